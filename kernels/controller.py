"""Step-size control (docs/model.md, "Time integration"): where the next step ends, and what an
accepted or rejected step does to the step size. Pure functions of the member's state and the
solver settings; the constants are fields of ``warpfric.Solver`` (step_safety, step_min_factor,
step_max_factor, failure_factor).

- Steps land exactly on the protocol's breakpoints (ramp ends, disc start, sudden stop, end): a
  step that would pass one ends on it (clipped); a step longer than half the distance to it is cut
  to that half, so that the breakpoint is reached by two equal steps rather than a long one and a
  sliver.
- With the stress gate, a step also ends at ``switch_limit``: just past a gate switch located by a
  rejected step (kernels/gates.py).
- After a step with error norm err (1 = the tolerance): h_next = h * clamp(safety * err^(-1/3),
  min_factor, max_factor) (elementary controller, local error O(h^3) of the order-2 solution);
  max_factor when err = 0. ESDIRK4 (Solver.method): err^(-1/4), its estimate being O(h^4). A step clipped at a breakpoint does not shrink the size for the next
  one. A rejected step shrinks by at least the safety factor; a failed Newton solve by
  failure_factor. Below min_step the member stops (step_size_underflow, or non_finite_state when
  the failure was a non-finite state).
"""

import warp as wp

from .model_terms import next_breakpoint
from .types import STATUS_MAX_STEPS, STATUS_NON_FINITE, STATUS_STALLED, STATUS_STEP_UNDERFLOW, IntegratorState, MemberParams, SolverSettings

# the local error of the order-2 solution is O(h^3): h_next ~ err^(-1/3). The exponent is -1/3
# rounded to float32 (-0.3333333432674408): the kernel has used that value from its first version (Warp
# folded the literal division -1.0/3.0 in float32); kept so that outputs stay equal (it changes a
# step size by at most ~3e-8 relative, far inside the controller's own slack)
ERROR_EXPONENT = -0.3333333432674408
# ESDIRK4 (Solver.method = 'esdirk4'): the embedded order-3 estimate is O(h^4): h_next ~ err^(-1/4)
ERROR_EXPONENT_ESDIRK4 = -0.25
# clipping codes of a proposed step
STEP_FREE, STEP_AT_BREAKPOINT, STEP_AT_SWITCH = 0, 1, 2


@wp.struct
class Step:
    """A proposed step: its size h (s), end time t_new (s) and clipping code (STEP_*)."""

    h: wp.float64
    t_new: wp.float64
    clipped: wp.int32


@wp.func
def propose_step(p: MemberParams, st: IntegratorState, settings: SolverSettings, t: wp.float64):
    """The next step from t: st.h bounded by max_step, the next breakpoint and st.switch_limit."""
    bp = next_breakpoint(p, t)
    h = wp.min(st.h, settings.max_step)
    clipped = STEP_FREE
    if h >= bp - t:
        h = bp - t
        clipped = STEP_AT_BREAKPOINT
    elif h > wp.float64(0.5) * (bp - t):
        h = wp.float64(0.5) * (bp - t)  # two equal steps, not a long one and a sliver
    if st.switch_limit < t + h and st.switch_limit > t:
        # a gate switch located by a rejected step (or predicted) lies before: end the step there
        # (1e300 unless the stress gate located or predicted one; a limit at or before t is stale
        # and never makes a step of zero length)
        h = st.switch_limit - t
        clipped = STEP_AT_SWITCH
    step = Step()
    step.h = h
    step.t_new = t + h
    if clipped == STEP_AT_BREAKPOINT:
        step.t_new = bp
    if clipped == STEP_AT_SWITCH:
        step.t_new = st.switch_limit
    step.clipped = clipped
    return step


@wp.func
def size_factor(error: wp.float64, settings: SolverSettings, exponent: wp.float64):
    """Size factor for the next step after an error norm ``error`` (1 = at the tolerance), for a local
    error estimate O(h^q): h_next = h * clamp(safety * error^exponent), exponent = -1/q."""
    if error > wp.float64(0.0):
        return wp.min(
            settings.step_max_factor,
            wp.max(settings.step_min_factor, settings.step_safety * wp.pow(error, exponent)),
        )
    return settings.step_max_factor


@wp.func
def step_factor(error: wp.float64, settings: SolverSettings):
    """size_factor for TR-BDF2 (local error estimate O(h^3))."""
    return size_factor(error, settings, wp.float64(ERROR_EXPONENT))


@wp.func
def step_factor_esdirk4(error: wp.float64, settings: SolverSettings):
    """size_factor for ESDIRK4 (local error estimate O(h^4): exponent -1/4)."""
    return size_factor(error, settings, wp.float64(ERROR_EXPONENT_ESDIRK4))


def step_factor_for(method: str):
    """The controller's step_factor function of an integrator method."""
    return step_factor_esdirk4 if method == "esdirk4" else step_factor


@wp.func
def accepted_step_size(st: IntegratorState, step: Step, factor: wp.float64):
    """h for the step after an accepted one: h*factor, but no smaller than before a clipped step."""
    h_next = step.h * factor
    if step.clipped != STEP_FREE:
        h_next = wp.max(h_next, st.h)
    return h_next


@wp.func
def reject(st: IntegratorState, settings: SolverSettings, h_next: wp.float64, non_finite: int):
    """Count a rejected step and retry with h_next; stop the member below min_step."""
    st.steps_rejected = st.steps_rejected + 1
    st.h = h_next
    if h_next < settings.min_step:
        st.done = 1
        if non_finite == 1:
            st.status = STATUS_NON_FINITE
        else:
            st.status = STATUS_STEP_UNDERFLOW
    return st


@wp.func
def out_of_steps(st: IntegratorState, settings: SolverSettings):
    """Stop the member (status max_steps_reached) once its attempted steps reach max_steps."""
    if st.steps_accepted + st.steps_rejected >= settings.max_steps:
        st.status = STATUS_MAX_STEPS
        st.done = 1
    return st


@wp.func
def stalled(st: IntegratorState, attempt_limit: int):
    """Stop the member (status stalled) once its attempted steps exceed attempt_limit: the straggler
    limit that the host derives from its peers (warpfric.engine.straggler_limit; 2**31 - 1: none)."""
    if st.done == 0 and st.steps_accepted + st.steps_rejected > attempt_limit:
        st.status = STATUS_STALLED
        st.done = 1
    return st
