"""What the integrator records of an accepted step (docs/model.md, "Outputs", "Fronts", "End of a run"):
the friction coefficient and its maximum mu_s, lift-off, the detachment fronts (event maximum and
arrival times) and the recorded fields; and the automatic end of a run, which is decided from them.

``on_accept`` is the one hook the integrator calls after each accepted step (the state already
advanced); the velocity and strength fronts' observers are compiled in only where the run may
need them (``ObserverSet``: a run models only what its scene needs, and a smaller kernel leaves
the GPU's instruction cache and registers to the rest; the recording always, so that a sweep's
chunks share one kernel) and run only when the launch asks for them
(OutputSettings.velocity_front / strength_front, IntegratorState.record_slot); the contact front is
recorded with the gate switches (kernels/gates.py).

``make_observers(ft, model, terms, team, method, observed)`` builds the functions for one working
precision, model (the model's switches reach them through ``terms``) and ObserverSet, one factory
per observer:
``make_state_interface`` (the friction law at the state, shared by the next two),
``make_velocity_front``, ``make_strength_front`` and ``make_recording``.
"""

from typing import NamedTuple

import warp as wp

from .esdirk import C2
from .model_terms import disc_travel_at, disc_velocity_at, normal_force_at
from .reductions import (
    crossing_time,
    crossing_time_quadratic,
    detachment_velocity,
    peak_within_falls,
    record_friction_point,
    record_friction_point_cubic,
)
from .types import (
    C_PHI, C_TAU, C_U, C_V, E_CONTACT, EV_STRENGTH, EV_VELOCITY, S_MAX, S_RATIO1, S_RATIO2, IntegratorState, MemberParams,
    OutputSettings,
)

# automatic end (end_time None, docs/model.md "End of a run"): mu has fallen this fraction below its
# maximum, and (front metrics on) every node's detachment velocity is below this fraction of the
# arrival level
AUTO_END_PEAK_DROP = 0.01
AUTO_END_FRONT_FRACTION = 0.5
# ... and the maximum came after the disc had slid this many memory lengths D: a detachment needs
# slip of order D (the measured peaks: 2.7-3.6 D from 1e-6 to 1e-4 m/s); earlier wiggles of mu(t)
# (the start of the disc, 1e-8 in mu) are not the peak
AUTO_END_MIN_TRAVEL = 0.5
# strength front: a node's peak of tau_f/sigma_n counts once the ratio has fallen this fraction below
# it (the measured drop after the peak is ~20 %: N = 100, e = -0.2..0.2, stress gate); the automatic
# end waits for every node in contact to pass its peak
STRENGTH_PEAK_DROP = 0.01


@wp.func
def friction_point(st: IntegratorState, p: MemberParams, t_new: wp.float64, friction: wp.float64,
                   normal: wp.float64, min_normal: wp.float64, cubic: int):
    """Count the accepted point at t_new: mu = sign(v_d) * int tau_f dx / int sigma_n^+ dx into the
    running maximum (reductions.record_friction_point, refined by a parabola; with cubic = 1
    record_friction_point_cubic, by a cubic: ESDIRK4), lift-off (sigma_n < 0 somewhere while
    loaded), and a restart when the step ended on the sudden stop."""
    st.t = t_new
    st.steps_accepted = st.steps_accepted + 1
    sign_v = wp.float64(1.0)
    if p.disc_velocity < wp.float64(0.0):
        sign_v = wp.float64(-1.0)
    mu = wp.float64(0.0)
    if normal > wp.float64(0.0):
        mu = sign_v * friction / normal
    if cubic == 1:
        st = record_friction_point_cubic(st, t_new, mu)
    else:
        st = record_friction_point(st, t_new, mu)
    if min_normal < wp.float64(0.0) and normal_force_at(p, t_new) > wp.float64(0.0):
        st.lift_off = 1
    if t_new == p.stop_time:
        st.restart = 1
    return st


@wp.func
def detachment_over(p: MemberParams, st: IntegratorState, outputs: OutputSettings):
    """The automatic end: mu has passed a maximum reached after the disc slid AUTO_END_MIN_TRAVEL*D
    and fallen AUTO_END_PEAK_DROP below it, (stress gate) every node in contact has opened its gate
    since the disc started, while the disc moves (a partial slip that arrests drops mu too, and mu
    rises past it to the detachment's peak), (velocity front) no node is above
    AUTO_END_FRONT_FRACTION of the arrival level, and (strength front) every node in contact has
    passed its peak of tau_f/sigma_n by STRENGTH_PEAK_DROP. A disc that stopped before it slid
    AUTO_END_MIN_TRAVEL*D can give no such maximum (its travel stays where it stopped): the run ends
    at the stop."""
    min_travel = wp.float64(AUTO_END_MIN_TRAVEL) * p.memory_length
    if st.t >= p.stop_time and disc_travel_at(p, p.stop_time) < min_travel:
        return True
    if st.t <= p.rest_until or st.npts < 3 or st.mu_s <= wp.float64(0.0):
        return False
    if disc_travel_at(p, st.mu_s_time) < min_travel:
        return False  # the maximum must come from the sliding disc
    if st.mu_final > (wp.float64(1.0) - wp.float64(AUTO_END_PEAK_DROP)) * st.mu_s:
        return False
    if st.stuck_nodes > 0 and st.t < p.stop_time:
        return False
    if outputs.velocity_front == 1 and st.front_max > wp.float64(0.0):
        if st.front_now >= wp.float64(AUTO_END_FRONT_FRACTION) * outputs.front_threshold * st.front_max:
            return False
    if outputs.strength_front == 1 and st.strength_rising > 0:
        return False
    return True


@wp.func
def latch_detachment_end(p: MemberParams, st: IntegratorState, outputs: OutputSettings):
    """st with detachment_end set to the state's time where detachment_over holds for the first
    time (asked at every attempt until then, whatever the run's end): the time the automatic end
    would stop at, which tells a run cut off by an explicit end_time from one that saw its fronts
    through."""
    if st.detachment_end > st.t:  # not yet (inf), or set in a state ahead of this one: never
        if detachment_over(p, st, outputs):
            st.detachment_end = st.t
    return st


@wp.func
def run_finished(p: MemberParams, st: IntegratorState, outputs: OutputSettings):
    """True when the member has reached its end: end_time, the end of the arrival pass (front_until)
    or, with end_time None, the end of the detachment (st.detachment_end, latched by
    latch_detachment_end just before)."""
    if st.t >= p.end_time or st.t >= st.front_until:
        return True
    if p.auto_end > wp.float64(0.0) and st.detachment_end <= st.t:
        return True
    return False


def make_state_interface(ft, terms):
    """The interface of the state itself (the friction law at the state, g = 0), node by node along
    a lane's nodes: the displacement stencil's start and each node's normal stress and friction."""
    Coeffs = terms["Coeffs"]
    contact_terms = terms["contact_terms"]
    array3 = wp.array3d(dtype=ft)

    @wp.func
    def state_displacement(state: array3, i: int, n: int, m: int):
        """u_i of the state (0 beyond the last node)."""
        if i >= n:
            return ft(0.0)
        return state[C_U, i, m]

    @wp.func
    def lane_stencil_start(c: Coeffs, state: array3, n: int, m: int):
        """(u of the node left of the lane's first node (0 at the pad's left end), u of its first node)."""
        u_l = ft(0.0)
        if c.first_node > 0:
            u_l = state_displacement(state, c.first_node - 1, n, m)
        return u_l, state_displacement(state, c.first_node, n, m)

    @wp.func
    def state_contact(c: Coeffs, state: array3, i: int, n: int, m: int, u_l: ft, u_c: ft, u_r: ft, delta0: ft, tilt: ft,
                      v_disc: ft):
        """The interface at node i of the state itself (the friction law at the state: g = 0)."""
        return contact_terms(c, i, n, u_l, u_c, u_r, delta0, tilt, state[C_V, i, m], v_disc, state[C_TAU, i, m],
                             state[C_PHI, i, m], ft(0.0), ft(1.0), ft(0.0), ft(1.0))

    return dict(state_displacement=state_displacement, lane_stencil_start=lane_stencil_start,
                state_contact=state_contact)


def make_velocity_front(ft, terms, team):
    """The velocity front (OutputSettings.velocity_front): track_fronts."""
    Coeffs = terms["Coeffs"]
    team_max = team["team_max"]
    array3 = wp.array3d(dtype=ft)
    array4 = wp.array4d(dtype=ft)

    @wp.func
    def track_fronts(
        c: Coeffs, p: MemberParams, st: IntegratorState, m: int, n: int, K: array4, step_end: array3, s1: int, s2: int,
        s3: int, t_old: wp.float64, t_new: wp.float64, arrival: wp.array3d(dtype=wp.float64),
        arrival_error: wp.array3d(dtype=wp.float64), direction: int,
        threshold: wp.float64, use_stage2: int,
    ):
        """Fold an accepted step into the front tracking (the pad velocity at t_old is the FSAL
        slot's K[s1, C_U], at t_new the last stage's K[s3, C_U]): the running maximum of the
        detachment velocity w, each node's first crossing of st.front_level (on the quadratic through
        the step's ends and its second stage, linear after a backward-Euler restart, with its error
        estimate in arrival_error), and front_last: the last step at which some node had
        w >= threshold * (running maximum). Every first crossing of threshold * (final maximum)
        ends a step at or before front_last, so the arrival pass may stop there.
        Window: from the disc start to the sudden stop (or the end). A node without contact at the
        end of the step (lifted off) is skipped: it never arrives, nucleates or sets the maximum."""
        if t_new <= p.rest_until or t_old >= p.stop_time:
            return st
        disc_sign = wp.float64(1.0)
        if p.disc_velocity < wp.float64(0.0):
            disc_sign = wp.float64(-1.0)
        w_step = wp.float64(-1.0e300)
        for i in range(c.first_node, c.end_node):
            if step_end[E_CONTACT, i, m] == ft(0.0):
                continue
            w_old = detachment_velocity(wp.float64(K[s1, C_U, i, m]), disc_sign, direction)
            w_new = detachment_velocity(wp.float64(K[s3, C_U, i, m]), disc_sign, direction)
            w_step = wp.max(w_step, w_new)
            if not wp.isfinite(arrival[EV_VELOCITY, i, m]):
                if use_stage2 == 1:
                    # quadratic through the step's ends and its second stage (at c2*h): a sharper
                    # crossing time, and its distance to the linear one as the error estimate
                    w_mid = detachment_velocity(wp.float64(K[s2, C_U, i, m]), disc_sign, direction)
                    if w_new >= st.front_level or w_mid >= st.front_level:
                        t_cross, t_err = crossing_time_quadratic(
                            st.front_level, t_old, w_old, wp.float64(C2), w_mid, t_new, w_new
                        )
                        arrival[EV_VELOCITY, i, m] = t_cross
                        arrival_error[EV_VELOCITY, i, m] = t_err
                elif w_new >= st.front_level:
                    arrival[EV_VELOCITY, i, m] = crossing_time(st.front_level, t_old, w_old, t_new, w_new)
                    arrival_error[EV_VELOCITY, i, m] = t_new - t_old  # backward-Euler step: no inner point
        w_step = team_max(w_step)  # over the team's nodes (max is exact: the same in any order)
        if w_step > wp.float64(-1.0e300):  # some node in contact (front_max stays -inf before)
            st.front_max = wp.max(st.front_max, w_step)
        if w_step > wp.float64(0.0) and w_step >= threshold * st.front_max:
            st.front_last = t_new
        st.front_now = w_step
        return st

    return dict(track_fronts=track_fronts)


def make_strength_front(ft, terms, team, interface):
    """The strength front (OutputSettings.strength_front): track_strength."""
    Coeffs = terms["Coeffs"]
    team_count = team["team_count"]
    barrier = team["barrier"]
    state_displacement = interface["state_displacement"]
    lane_stencil_start = interface["lane_stencil_start"]
    state_contact = interface["state_contact"]
    array3 = wp.array3d(dtype=ft)

    @wp.func
    def track_strength(
        c: Coeffs, p: MemberParams, st: IntegratorState, m: int, n: int, state: array3, t_old: wp.float64,
        t_new: wp.float64, delta0: ft, tilt: ft, backward_euler: int, strength: wp.array3d(dtype=wp.float64),
        arrival: wp.array3d(dtype=wp.float64), arrival_error: wp.array3d(dtype=wp.float64),
    ):
        """The strength front: each node's running maximum of r = sign(v_max)*tau_f/sigma_n (its own
        static friction; nodes in contact, window from the disc start to the sudden stop) and its time
        in arrival[EV_STRENGTH], refined like mu_s by the parabola through the last three accepted
        points when the middle one is a discrete maximum (in float32 where its vertex passes
        peak_within_falls: a fast disc's start put every node's vertex there, 194 against 0.498;
        arrival_error: the refinement's shift, or the step for an unrefined maximum).
        st.strength_rising counts the team's nodes in contact whose r is still within
        STRENGTH_PEAK_DROP of its maximum. The lane's nodes (after a
        barrier: the stencil reads the halo's displacement, just advanced by the neighbour)."""
        barrier()
        v_disc = ft(disc_velocity_at(p, t_new, t_old))
        sign_v = wp.float64(1.0)
        if p.disc_velocity < wp.float64(0.0):
            sign_v = wp.float64(-1.0)
        in_window = t_new > p.rest_until and t_old < p.stop_time
        refine = backward_euler == 0 and st.npts >= 2 and t_old > st.t2 and st.t2 >= p.rest_until
        rising = int(0)
        u_l, u_c = lane_stencil_start(c, state, n, m)
        for i in range(c.first_node, c.end_node):
            u_r = state_displacement(state, i + 1, n, m)
            ns, fr = state_contact(c, state, i, n, m, u_l, u_c, u_r, delta0, tilt, v_disc)
            u_l = u_c
            u_c = u_r
            sigma = wp.float64(fr.contact * ns.value)
            r_new = wp.float64(wp.nan)
            if sigma > wp.float64(0.0):
                r_new = sign_v * wp.float64(fr.stress) / sigma
            r1 = strength[S_RATIO1, i, m]
            r2 = strength[S_RATIO2, i, m]
            strength[S_RATIO2, i, m] = r1
            strength[S_RATIO1, i, m] = r_new
            if not (in_window and wp.isfinite(r_new)):
                continue
            r_max = strength[S_MAX, i, m]
            if not wp.isfinite(r_max) or r_new > r_max:
                r_max = r_new
                arrival[EV_STRENGTH, i, m] = t_new
                arrival_error[EV_STRENGTH, i, m] = t_new - t_old
            if refine and wp.isfinite(r1) and wp.isfinite(r2) and r1 >= r2 and r1 >= r_new:
                d1 = (r1 - r2) / (t_old - st.t2)
                d2 = (r_new - r1) / (t_new - t_old)
                curv = (d2 - d1) / (t_new - st.t2)
                if curv < wp.float64(0.0):
                    t_peak = wp.float64(0.5) * (t_old + st.t2) - d1 / (wp.float64(2.0) * curv)
                    if t_peak >= st.t2 and t_peak <= t_new:
                        r_peak = r2 + d1 * (t_peak - st.t2) + curv * (t_peak - st.t2) * (t_peak - t_old)
                        # float32's round-off makes kinks where a fast disc starts, and the parabola
                        # through one reads any value (194 against 0.498): there the vertex passes
                        # mu_s's test (its fall to the two other points; mu_s's also reads the point
                        # before them); float64 keeps it unbounded (bounded, a node's discrete maximum
                        # a step from its peak moved a front by two nodes: docs/model.md, "Outputs")
                        kept = True
                        if wp.static(ft == wp.float32):
                            kept = peak_within_falls(r_peak, r1, wp.min(r2, r_new))
                        if r_peak >= r_max and kept:
                            r_max = r_peak
                            arrival[EV_STRENGTH, i, m] = t_peak
                            arrival_error[EV_STRENGTH, i, m] = wp.abs(t_peak - t_old)
            strength[S_MAX, i, m] = r_max
            if r_new > (wp.float64(1.0) - wp.float64(STRENGTH_PEAK_DROP)) * r_max:
                rising += 1
        st.strength_rising = team_count(rising)
        return st

    return dict(track_strength=track_strength)


def make_recording(ft, terms, team, interface):
    """The recorded fields of a recorded member (IntegratorState.record_slot): record_fields."""
    Coeffs = terms["Coeffs"]
    barrier = team["barrier"]
    state_displacement = interface["state_displacement"]
    lane_stencil_start = interface["lane_stencil_start"]
    state_contact = interface["state_contact"]
    array3 = wp.array3d(dtype=ft)
    array4 = wp.array4d(dtype=ft)

    @wp.func
    def record_fields(
        c: Coeffs, p: MemberParams, st: IntegratorState, m: int, n: int, state: array3,
        t_old: wp.float64, t_new: wp.float64, delta0: ft, tilt: ft, times: wp.array(dtype=wp.float64),
        previous: array3, record: array4,
    ):
        """Sample the fields (pad velocity, slip rate, contact pressure, friction stress) of a
        recorded member at the grid times in (t_old, t_new], by linear interpolation between the
        accepted points; ``previous`` holds the fields at t_old. The lane's nodes (after a barrier:
        the stencil reads the halo's displacement, just advanced by the neighbour)."""
        barrier()
        slot = st.record_slot
        n_times = times.shape[0]
        k_end = st.record_next
        while k_end < n_times:
            if times[k_end] > t_new:
                break
            k_end += 1
        v_disc = ft(disc_velocity_at(p, t_new, t_old))
        span = t_new - t_old
        u_l, u_c = lane_stencil_start(c, state, n, m)
        for i in range(c.first_node, c.end_node):
            u_r = state_displacement(state, i + 1, n, m)
            vel = state[C_V, i, m]
            ns, fr = state_contact(c, state, i, n, m, u_l, u_c, u_r, delta0, tilt, v_disc)
            sigma = ns.value
            current = wp.vector(vel, v_disc - c.kif * vel, fr.contact * sigma, fr.stress, length=4, dtype=ft)
            for k in range(st.record_next, k_end):
                frac = ft(1.0)
                if span > wp.float64(0.0):
                    frac = ft(wp.clamp((times[k] - t_old) / span, wp.float64(0.0), wp.float64(1.0)))
                for f in range(4):
                    record[f, k, i, slot] = previous[f, i, slot] + frac * (current[f] - previous[f, i, slot])
            for f in range(4):
                previous[f, i, slot] = current[f]
            u_l = u_c
            u_c = u_r
        st.record_next = k_end
        return st

    return dict(record_fields=record_fields)


class ObserverSet(NamedTuple):
    """The fronts' observers compiled into a kernel (the recording and the friction point always):
    both by default; a run compiles those its front events may use (warpfric/engine.py
    observer_set)."""

    velocity_front: bool = True
    strength_front: bool = True


def make_observers(ft, model, terms, team, method="tr_bdf2", observed=ObserverSet()):
    """The observers for one working precision, model and ObserverSet, composed into on_accept:
    the velocity front and the strength front (those of ``observed``), the recording and the
    friction point."""
    # mu_s: TR-BDF2 refines the maximum by a parabola through three accepted points, ESDIRK4 by a
    # cubic through four (its longer steps)
    cubic = 1 if method == "esdirk4" else 0
    Coeffs = terms["Coeffs"]
    interface = make_state_interface(ft, terms)
    track_fronts = make_velocity_front(ft, terms, team)["track_fronts"]
    track_strength = make_strength_front(ft, terms, team, interface)["track_strength"]
    record_fields = make_recording(ft, terms, team, interface)["record_fields"]
    array3 = wp.array3d(dtype=ft)
    array4 = wp.array4d(dtype=ft)

    @wp.func
    def on_accept(
        c: Coeffs, p: MemberParams, st: IntegratorState, outputs: OutputSettings, m: int, n: int, state: array3,
        K: array4, step_end: array3, s1: int, s2: int, s3: int, t_old: wp.float64, t_new: wp.float64, delta0: ft,
        tilt: ft, friction: wp.float64, normal: wp.float64, min_normal: wp.float64, backward_euler: int,
        arrival: wp.array3d(dtype=wp.float64), arrival_error: wp.array3d(dtype=wp.float64),
        strength: wp.array3d(dtype=wp.float64),
        record_times: wp.array(dtype=wp.float64), record_previous: array3, record: array4,
    ):
        """After an accepted step from t_old to t_new (state advanced, K[s1] still f(y_old)): fronts,
        recording, then the friction point (mu(t) may jump across a backward-Euler restart: no
        parabola through it)."""
        if wp.static(observed.velocity_front):
            if outputs.velocity_front == 1:
                st = track_fronts(c, p, st, m, n, K, step_end, s1, s2, s3, t_old, t_new, arrival, arrival_error,
                                  outputs.front_direction, outputs.front_threshold, 1 - backward_euler)
        if wp.static(observed.strength_front):
            if outputs.strength_front == 1:
                st = track_strength(c, p, st, m, n, state, t_old, t_new, delta0, tilt, backward_euler, strength,
                                    arrival, arrival_error)
        if st.record_slot >= 0:
            st = record_fields(c, p, st, m, n, state, t_old, t_new, delta0, tilt, record_times, record_previous, record)
        if backward_euler == 1:
            st.npts = 0
        return friction_point(st, p, t_new, friction, normal, min_normal, cubic)

    return dict(on_accept=on_accept, track_fronts=track_fronts, track_strength=track_strength, record_fields=record_fields,
                state_displacement=interface["state_displacement"], state_contact=interface["state_contact"])
