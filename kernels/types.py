"""What the kernels work on: the device arrays (shapes in named dimensions, units) and the structs of
per-member parameters, solver settings, output settings and integrator state.

Parameters and times are float64 whatever the working precision ``ft``: a float32 time has only
~2 us resolution at t = 20 s, coarser than the steps the detachment needs.

Device arrays of one launch (allocated by :func:`allocate`; dims named as in mujoco_warp's
``types.py``; "member" is the fastest index, so neighbouring GPU threads read neighbouring
addresses):

=================  ==================================  =====  ===============================================
name               shape                               dtype  content (units)
=================  ==================================  =====  ===============================================
params             (member,)                           struct MemberParams (SI)
states             (member,)                           struct IntegratorState (persists between launches)
state              (component, node, member)           ft     y = (u m, u_t m/s, tau_el Pa, phi s) at time t
stages             (stage_slot, component, node, mbr)  ft     stage derivatives K = f(Y) (per s); FSAL slot
work               (work_slot, node, member)           ft     stage constants, Newton iterate, Thomas rows
step_end           (step_end_slot, node, member)       ft     Jacobian diagonal (Pa s/m), contact (1) at a step's end
gates              (gate_slot, node, member)           ft     stress gate: gate (1), margin (Pa), sliding (1), ...;
                                                              (gate_slot, 1, 1) for the other laws
yield_time         (node, member)                      f64    first gate opening after the disc starts (s); (1, 1) unless stress gate
arrival            (front_event, node, member)         f64    front arrival time t_a of each event (FRONT_EVENTS)
                                                              (s), NaN: none; (N_EVENTS, 1, 1) without fronts
arrival_error      (front_event, node, member)         f64    its error estimate (s)
strength           (strength_slot, node, member)       f64    strength event: tau_f/sigma_n at the last two
                                                              accepted points and its running maximum (1);
                                                              (N_STRENGTH, 1, 1) without that event
record_times       (time,)                             f64    recording grid (s)
record_previous    (record_field, node, recorded)      ft     recorded fields at the last accepted point
record             (record_field, time, node, recorded) ft    sampled fields (RECORD_FIELDS; NaN: not reached)
=================  ==================================  =====  ===============================================
"""

import dataclasses

import numpy as np
import warp as wp

# state components (first index of ``state``, second of ``stages``)
C_U, C_V, C_TAU, C_PHI = 0, 1, 2, 3
N_COMPONENTS = 4
# work slots (first index of ``work``: the scratch of one attempted step, which the blocked GPU
# kernel keeps in shared memory, kernels/integrator.py team_layout): the stage constants z (in the
# order of the components; after the last stage, TR-BDF2's error norm leaves the step's solution
# there for advance_state), the Newton iterate of the pad velocity, the Thomas sweep's rows (cp,
# three right-hand sides) and the two border rows of the plate balance; last, the cooperative
# kernel's two coupling columns of a lane's interior rows (kernels/team.py)
W_ZU, W_ZV, W_ZT, W_ZP, W_V, W_CP, W_R0, W_R1, W_R2, W_C1, W_C2 = range(11)
W_RL, W_RR = 11, 12
N_WORK = 13
# step-end slots (first index of ``step_end``): what an attempted step leaves for its error norm and
# its acceptance, read once per node (kept out of ``work`` so that the shared work array is
# smaller): the Jacobian diagonal of the last Newton iteration (Pa s/m; the velocity error filter)
# and the contact at the end of the step (1 in contact, 0 lifted off; the velocity front)
E_DIAG, E_CONTACT = 0, 1
N_STEP_END = 2
# gate slots (stress gate, first index of ``gates``): the gate held over the next step (0 closed,
# 1 open; for a sliding node the start of its implicit solve), the yield margin |tau_f| - tau_c*A
# (Pa) at the last accepted point, the sliding flag (1: solved on the yield surface each stage), the
# margin at the accepted point before (Pa; the contact front's quadratic crossing); then what an
# attempted step leaves for its acceptance: the margin at its end (Pa), that margin's slope with
# respect to the gate (Pa per unit gate) and the last stage's solved gate (kept out of ``work`` so
# that the shared work array is smaller)
G_GATE, G_MARGIN, G_SLIDE, G_MARGIN_OLD, G_MARGIN_END, G_DMARGIN, G_GATE_END = range(7)
N_GATE = 7
# front events (first index of ``arrival``; docs/model.md, "Fronts"): each node's stick-to-slip
# transition (its first gate opening after the disc starts; stress gate only), its peak of
# tau_f/sigma_n (its own static friction), and the threshold crossing of the pad velocity
EV_CONTACT, EV_STRENGTH, EV_VELOCITY = 0, 1, 2
FRONT_EVENTS = ("contact", "strength", "velocity")
N_EVENTS = 3
# strength slots (first index of ``strength``): tau_f/sigma_n at the last accepted point and at the
# one before, and its running maximum over the window
S_RATIO1, S_RATIO2, S_MAX = 0, 1, 2
N_STRENGTH = 3
STAGE_SLOTS = {"tr_bdf2": 3, "esdirk4": 6}


def stage_slots(method: str) -> int:
    """Slots of the stages array K for an integrator method (its number of stages, FSAL included)."""
    return STAGE_SLOTS[method]

# status codes of a member (netCDF flag_values / flag_meanings)
STATUS_MAX_STEPS = 1
STATUS_NON_FINITE = 2
STATUS_STEP_UNDERFLOW = 3
STATUS_NO_PEAK = 4  # set on the host (warpfric/simulate.py _member_status): no peak of mu inside the run
STATUS_STALLED = 5  # far more steps than its peers (Solver.stall_factor; the limit comes from the host)
STATUS_MEANINGS = ("ok", "max_steps_reached", "non_finite_state", "step_size_underflow", "no_peak", "stalled")


@wp.struct
class MemberParams:
    """One member's physical parameters (SI), as resolved by warpfric.parameters."""

    shear_modulus: wp.float64
    poisson_ratio: wp.float64
    density: wp.float64
    memory_length: wp.float64
    shear_strength: wp.float64
    hardness: wp.float64
    viscous_coefficient: wp.float64
    reference_velocity: wp.float64
    aging_coefficient: wp.float64
    aging_time: wp.float64
    interface_stiffness: wp.float64
    gate_velocity: wp.float64
    height: wp.float64
    length: wp.float64
    depth: wp.float64
    damping: wp.float64
    normal_force: wp.float64
    eccentricity: wp.float64
    disc_velocity: wp.float64
    force_ramp_time: wp.float64
    rest_until: wp.float64
    velocity_ramp_time: wp.float64
    stop_time: wp.float64
    end_time: wp.float64  # s, min(end_time, max_end_time)
    auto_end: wp.float64  # 1: end_time was None, the run ends when the detachment is over
    interface_velocity_factor: wp.float64
    torque_arm: wp.float64
    initial_age: wp.float64


@wp.struct
class SolverSettings:
    """warpfric.Solver's settings as the kernels see them (see its docstring)."""

    rtol: wp.float64
    initial_step: wp.float64
    min_step: wp.float64
    max_step: wp.float64
    newton_tol: wp.float64
    switch_rtol: wp.float64  # relative tolerance of the gate-switch location (rtol * switch_tol)
    sliding_width: wp.float64  # relative width of the regularised gate of nodes sliding on the yield surface
    max_steps: wp.int32
    newton_max_iter: wp.int32
    step_safety: wp.float64  # step-size controller (kernels/controller.py)
    step_min_factor: wp.float64
    step_max_factor: wp.float64
    failure_factor: wp.float64
    predict_switches: wp.int32  # stress gate: 1: end a step just past the next gate switch predicted from the margins
    error_filter_nodes: wp.float64  # the velocity error filter's elastic stiffness is at least that of a grid of this many nodes (0: the grid's own)
    viscous_velocity_cap: wp.float64  # the velocity's error scale at nodes in contact is at most this times hardness/viscous_coefficient (inf: off)

# how the detachment velocity w is read from the pad velocity u_t (docs/model.md, "Fronts")
FRONT_AGAINST_DISC = 0  # w = -sign(v_max) * u_t: the pad springing back as the interface lets go
FRONT_WITH_DISC = 1  # w = sign(v_max) * u_t
FRONT_ABSOLUTE = 2  # w = |u_t|
FRONT_DIRECTIONS = ("against_disc", "with_disc", "absolute")

# fields that Record can sample (first index of the record array)
RECORD_FIELDS = ("velocity", "slip_rate", "normal_stress", "friction_stress")


@wp.struct
class OutputSettings:
    """What the integrator records besides mu_s."""

    front_direction: wp.int32  # FRONT_* code
    velocity_front: wp.int32  # 1: track the detachment velocity (event maximum and arrival times)
    front_threshold: wp.float64  # arrival level as a fraction of the event maximum
    contact_front: wp.int32  # 1: record each node's first gate opening after the disc starts (stress gate)
    strength_front: wp.int32  # 1: track each node's peak of tau_f/sigma_n


@wp.struct
class IntegratorState:
    """Per-member integrator state that persists between launches, and the in-kernel reductions."""

    t: wp.float64  # s, time of the state
    h: wp.float64  # s, next step size
    delta0: wp.float64  # m, mean compression of the pad
    tilt: wp.float64  # rad, tilt a of the backing plate
    mu_s: wp.float64  # static friction coefficient (running maximum, refined)
    mu_s_time: wp.float64  # s
    t1: wp.float64  # last two accepted (t, mu) points, for the parabolic refinement
    mu1: wp.float64
    t2: wp.float64
    mu2: wp.float64
    t3: wp.float64  # the accepted point before (t2, mu2), for ESDIRK4's cubic refinement
    mu3: wp.float64
    mu_final: wp.float64  # friction coefficient at the last accepted step
    npts: wp.int32
    steps_accepted: wp.int32
    steps_rejected: wp.int32
    newton_iterations: wp.int32
    status: wp.int32
    lift_off: wp.int32
    fsal: wp.int32  # slot of K holding f(y_n)
    restart: wp.int32  # 1: next step is a backward-Euler (re)start
    done: wp.int32
    front_max: wp.float64  # m/s, running maximum of the detachment velocity w over nodes and the window
    front_level: wp.float64  # m/s, arrival level (threshold * event maximum of a first pass); inf: none
    front_last: wp.float64  # s, last accepted time with max_x w >= threshold * running maximum (pass 1)
    front_now: wp.float64  # m/s, max over nodes of w at the last accepted step (pass 1)
    front_until: wp.float64  # s, the arrival pass stops here (front_last of pass 1); inf in pass 1
    switch_limit: wp.float64  # s, steps end at or before this time (a gate switch located in a rejected step, or predicted)
    switch_predicted: wp.int32  # 1: switch_limit is a predicted switch (kernels/gates.py, after_accept)
    prediction_misses: wp.int32  # consecutive steps clipped at a predicted switch that did not happen
    gate_switches: wp.int32  # accepted gate switches (stress gate)
    switch_retries: wp.int32  # consecutive steps rejected to locate a gate switch
    unlocated_switches: wp.int32  # steps accepted with a switch error > 1 after MAX_SWITCH_RETRIES
    record_slot: wp.int32  # index among the recorded members, -1: not recorded
    record_next: wp.int32  # next index of the recording time grid
    strength_rising: wp.int32  # nodes in contact whose tau_f/sigma_n is within STRENGTH_PEAK_DROP of its maximum (strength front)
    stuck_nodes: wp.int32  # nodes in contact whose gate has not opened since the disc started (stress gate; 0 otherwise)
    # why steps were rejected (the three add up to steps_rejected), and wasted predictions
    rejected_error_test: wp.int32  # rejected by the error test (error norm > 1)
    rejected_newton: wp.int32  # rejected because a stage's Newton solve failed (no convergence or a non-finite value)
    rejected_switch: wp.int32  # rejected to locate a gate switch (retried up to just past it; stress gate)
    missed_predictions: wp.int32  # accepted steps that ended at a predicted gate switch that did not happen
    newton_curvature: wp.float64  # the last TR-BDF2 step's Newton curvature (kernels/newton.py newton_solve; 0: not known)
    detachment_end: wp.float64  # s, the first state time at which the detachment was over (observers.py detachment_over); inf: not yet


@dataclasses.dataclass
class DeviceArrays:
    """The arrays of one launch (see the module docstring for shapes and units)."""

    params: wp.array
    state: wp.array
    stages: wp.array
    work: wp.array
    step_end: wp.array
    gates: wp.array
    yield_time: wp.array
    arrival: wp.array
    arrival_error: wp.array
    strength: wp.array
    record_times: wp.array
    record_previous: wp.array
    record: wp.array


def _member_first(ndim: int):
    """Axes that move the last (member) axis first, and those that move it back."""
    return (ndim - 1,) + tuple(range(ndim - 1)), tuple(range(1, ndim)) + (0,)


def member_zeros(shape, ft, member_major: bool):
    """Zeros of ``shape`` (.., node, member) on the device. With member_major the memory holds each
    member's block contiguously, member slowest (the cooperative kernel: a member's lanes read
    neighbouring nodes); the array is a transposed view, indexed the same way as the member-fastest
    one."""
    if not member_major:
        return wp.zeros(shape, dtype=ft)
    order, back = _member_first(len(shape))
    return wp.zeros(tuple(shape[k] for k in order), dtype=ft).transpose(back)


def allocate(ft, params, n_nodes: int, stress_gate: bool, fronts: bool,
             record_times, n_recorded: int, member_major: bool = False, method: str = "tr_bdf2",
             strength: bool = False, global_work: bool = True) -> DeviceArrays:
    """Allocate the arrays of a launch on the current Warp device. ``params``: the members' MemberParams
    (member,), a Warp array there (warpfric/engine.py device_member_params); arrays a scene does not
    need get a (.., 1, 1) placeholder; member_major: the state, stages, work and gates arrays hold
    each member contiguously (:func:`member_zeros`); method: the integrator, which sets the stage
    slots of K (:func:`stage_slots`); strength: the strength front's per-node reductions;
    global_work: the work array in global memory (False: a (N_WORK, 1, 1) placeholder, the kernel
    keeps it in shared memory: kernels/integrator.py team_layout)."""
    n_members = params.shape[0]
    times = np.asarray(record_times if n_recorded else [0.0], dtype=np.float64)
    per_node = (n_nodes, n_members)
    return DeviceArrays(
        params=params,
        state=member_zeros((N_COMPONENTS, n_nodes, n_members), ft, member_major),
        stages=member_zeros((stage_slots(method), N_COMPONENTS, n_nodes, n_members), ft, member_major),
        work=member_zeros((N_WORK, n_nodes, n_members), ft, member_major) if global_work
        else wp.zeros((N_WORK, 1, 1), dtype=ft),
        step_end=member_zeros((N_STEP_END, n_nodes, n_members), ft, member_major),
        gates=member_zeros((N_GATE, n_nodes, n_members), ft, member_major) if stress_gate
        else wp.zeros((N_GATE, 1, 1), dtype=ft),
        # NaN: not set yet (the kernels test isfinite)
        yield_time=wp.full(per_node if stress_gate else (1, 1), np.nan, dtype=wp.float64),
        arrival=wp.full((N_EVENTS,) + (per_node if fronts else (1, 1)), np.nan, dtype=wp.float64),
        arrival_error=wp.full((N_EVENTS,) + (per_node if fronts else (1, 1)), np.nan, dtype=wp.float64),
        strength=wp.full((N_STRENGTH,) + (per_node if strength else (1, 1)), np.nan, dtype=wp.float64),
        record_times=wp.array(times, dtype=wp.float64),
        record_previous=wp.zeros((len(RECORD_FIELDS), n_nodes, max(n_recorded, 1)), dtype=ft),
        # NaN: a time after the end of the run is never sampled
        record=wp.full((len(RECORD_FIELDS), times.shape[0] if n_recorded else 1, n_nodes, max(n_recorded, 1)),
                       np.nan, dtype=ft),
    )
