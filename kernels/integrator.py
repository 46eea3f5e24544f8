"""Batched implicit adaptive time integration of the pad model (one Warp thread per member).

Scheme (docs/model.md, "Time integration"):
- TR-BDF2 written as a stiffly accurate ESDIRK (Hosea & Shampine 1996): L-stable, order 2, with
  an embedded order-3 solution for the local error estimate; the explicit first stage reuses
  f(y_n) from the previous step (FSAL). Each member has its own step size.
- A backward-Euler step of ``initial_step`` starts the run and restarts it after the sudden disc
  stop (a jump of the disc velocity makes the FSAL stage and the algebraic plate state invalid).
- Steps land exactly on the protocol's breakpoints (ramp ends, disc start, stop, end).
- Each implicit stage is solved by Newton's method on the unknowns (V_0..V_{N-1}, delta0, a):
  the pad velocity at every node and the plate's compression and tilt. At a given V the stage
  equations of the contact age and of the elastic friction stress are linear and are solved in
  closed form per node (model_terms.interface_friction), so the Newton matrix is tridiagonal
  in V, bordered by two columns (delta0, a) and two dense rows (force and moment balance of the
  plate). It is solved by the Thomas algorithm with three right-hand sides and a 2x2 Schur
  complement: O(N) work and memory per member.
- Layout: every field array is (component, node, member) with the member index fastest, so that
  neighbouring GPU threads read neighbouring addresses.
"""


import math

import warp as wp

from .model_terms import disc_travel_at, disc_velocity_at, make_model_terms, next_breakpoint, normal_force_at
from .params import (
    STATUS_MAX_STEPS,
    STATUS_NON_FINITE,
    STATUS_STEP_UNDERFLOW,
    IntegratorState,
    MemberParams,
    OutputSettings,
    SolverSettings,
)
from .reductions import crossing_time, crossing_time_quadratic, detachment_velocity, record_friction_point

# state components (first index of the state array and second index of the stage-derivative array)
C_U, C_V, C_TAU, C_PHI = 0, 1, 2, 3
N_COMPONENTS = 4
# work slots: stage constants z (same order as the components), Newton iterate, Thomas and border rows
W_ZU, W_ZV, W_ZT, W_ZP, W_V, W_CP, W_R0, W_R1, W_R2, W_C1, W_C2, W_DIAG, W_MARGIN, W_DMARGIN, W_CONTACT, W_GATE_END = range(16)
N_WORK = 16
# yield-gate state (stress gate), first index of the gate array: the gate (0 closed, 1 open, held over
# the next step; for a sliding node the start of its implicit solve), the yield margin
# |tau_f| - tau_c*A (Pa) at the last accepted point, and the sliding flag (1: the node slides on the
# yield surface, its gate solved in every stage from |tau_f| = tau_c*A)
G_GATE, G_MARGIN, G_SLIDE = 0, 1, 2
N_GATE = 3
N_STAGE_SLOTS = 3
# a gate switch that MAX_SWITCH_RETRIES retries could not place within its tolerance (a strongly
# curved margin makes the linear crossing estimate creep towards it, like regula falsi) is accepted
# at the end of the step and counted in unlocated_switches: the cost of one is bounded
MAX_SWITCH_RETRIES = 8

# automatic end (end_time None, docs/model.md "End of a run"): mu has fallen this fraction below its
# maximum, and (front metrics on) every node's detachment velocity is below this fraction of the
# arrival level
AUTO_END_PEAK_DROP = 0.01
AUTO_END_FRONT_FRACTION = 0.5
# ... and the maximum came after the disc had slid this many memory lengths D: a detachment needs
# slip of order D (the measured peaks: 2.7-3.6 D from 1e-6 to 1e-4 m/s); earlier wiggles of mu(t)
# (the start of the disc, 1e-8 in mu) are not the peak
AUTO_END_MIN_TRAVEL = 0.5

# TR-BDF2 as an ESDIRK: c = (0, 2g, 1); A = [[0,0,0],[g,g,0],[w,w,g]]; b = (w, w, g)
GAMMA = 1.0 - math.sqrt(2.0) / 2.0
W_TRB = math.sqrt(2.0) / 4.0
C2 = 2.0 * GAMMA
B_HAT = ((1.0 - W_TRB) / 3.0, (3.0 * W_TRB + 1.0) / 3.0, GAMMA / 3.0)
ERR1, ERR2, ERR3 = W_TRB - B_HAT[0], W_TRB - B_HAT[1], GAMMA - B_HAT[2]
EXTRAPOLATE_STAGE3 = 1.0 / C2  # linear extrapolation of V from t_n and t_n + c2*h to t_n + h
ORDER_ESTIMATE = 3.0  # the local error of the order-2 solution is O(h^3)

_CACHE: dict = {}


def get_integrator(dtype: str, model) -> dict:
    """Compiled kernels for one working precision and one set of model switches (cached)."""
    key = (dtype, model)
    if key not in _CACHE:
        _CACHE[key] = _make_integrator(dtype, model)
    return _CACHE[key]


def _make_integrator(dtype: str, model):
    ft = wp.float64 if dtype == "float64" else wp.float32
    terms = make_model_terms(ft, model)
    Coeffs = terms["Coeffs"]
    make_coeffs = terms["make_coeffs"]
    node_weight = terms["node_weight"]
    node_moment_weight = terms["node_moment_weight"]
    normal_stress = terms["normal_stress"]
    elastic_force = terms["elastic_force"]
    interface_friction = terms["interface_friction"]
    yield_margin = terms["yield_margin"]
    inertia = bool(model.inertia)
    stress_gate = model.relaxation_gate == "stress"
    viscous = bool(model.viscous_friction)
    tilt_on = bool(model.tilt)

    array3 = wp.array3d(dtype=ft)
    array4 = wp.array4d(dtype=ft)

    @wp.func
    def is_finite(x: ft):
        return wp.isfinite(x)

    @wp.func
    def node_gate(gates: array3, i: int, m: int):
        """The yield gate of node i over the current step (1 for the gate-less and velocity laws)."""
        if wp.static(stress_gate):
            return gates[G_GATE, i, m]
        return ft(1.0)

    @wp.func
    def node_sliding(gates: array3, i: int, m: int):
        """1 where node i slides on the yield surface (stress gate), else 0."""
        if wp.static(stress_gate):
            return gates[G_SLIDE, i, m]
        return ft(0.0)

    @wp.func
    def prepare_stage(
        m: int, n: int, state: array3, K: array4, work: array3,
        h: ft, a1: ft, s1: int, a2: ft, s2: int, n_terms: int, extrapolate: ft,
    ):
        """z = y_n + h*(a1*K[s1] + a2*K[s2]) (first n_terms terms) and the Newton start for V:
        v_n + extrapolate*(V(stage s2) - v_n)."""
        for i in range(n):
            for comp in range(N_COMPONENTS):
                z = state[comp, i, m]
                if n_terms >= 1:
                    z += h * a1 * K[s1, comp, i, m]
                if n_terms >= 2:
                    z += h * a2 * K[s2, comp, i, m]
                work[comp, i, m] = z
            v = state[C_V, i, m]
            guess = v
            if n_terms >= 2:
                guess = v + extrapolate * (K[s2, C_U, i, m] - v)
            work[W_V, i, m] = guess

    @wp.func
    def newton_solve(
        c: Coeffs, p: MemberParams, s: SolverSettings, m: int, n: int, work: array3, gates: array3,
        g: ft, t_stage: wp.float64, t_step: wp.float64, delta0_in: ft, tilt_in: ft,
    ):
        """Solve one implicit stage. Returns (converged, delta0, tilt, iterations, non_finite)."""
        v_disc = ft(disc_velocity_at(p, t_stage, t_step))
        force = normal_force_at(p, t_stage)
        force_per_depth = ft(force / p.depth)
        moment_per_depth = ft(force * p.eccentricity * wp.float64(0.5) * p.length / p.depth)
        rtol = ft(s.rtol)
        delta0 = delta0_in
        tilt = tilt_in
        converged = int(0)
        non_finite = int(0)
        iters = int(0)
        prev_norm = ft(1.0e30)
        for it in range(s.newton_max_iter):
            iters = it + 1
            # ---- pass 1: residuals, Jacobian rows, forward elimination (3 right-hand sides) ----
            e1 = -force_per_depth
            e2 = -moment_per_depth
            d11 = ft(0.0)
            d12 = ft(0.0)
            d21 = ft(0.0)
            d22 = ft(0.0)
            c1_prev = ft(0.0)
            c1_cur = ft(0.0)
            c2_prev = ft(0.0)
            c2_cur = ft(0.0)
            cp_prev = ft(0.0)
            r0_prev = ft(0.0)
            r1_prev = ft(0.0)
            r2_prev = ft(0.0)
            u_l = ft(0.0)
            u_c = work[W_ZU, 0, m] + g * work[W_V, 0, m]
            for i in range(n):
                u_r = ft(0.0)
                if i < n - 1:
                    u_r = work[W_ZU, i + 1, m] + g * work[W_V, i + 1, m]
                vel = work[W_V, i, m]
                ns = normal_stress(c, i, n, u_l, u_c, u_r, delta0, tilt)
                sigma = ns.value
                fr = interface_friction(
                    c, sigma, vel, v_disc, work[W_ZT, i, m], work[W_ZP, i, m], g, node_gate(gates, i, m),
                    node_sliding(gates, i, m), ft(s.sliding_width),
                )
                ef = elastic_force(c, i, n, u_l, u_c, u_r, delta0, tilt)
                residual = -(ef.value + fr.stress - c.damping * vel)
                jac_c = -g * (ef.d_u_center + fr.d_normal * ns.d_u_center) + c.kif * fr.d_slip + c.damping
                if wp.static(inertia):
                    residual += c.rhoH * (vel - work[W_ZV, i, m]) / g
                    jac_c += c.rhoH / g
                    work[W_DIAG, i, m] = jac_c
                jac_l = -g * (ef.d_u_left + fr.d_normal * ns.d_u_left)
                jac_r = -g * (ef.d_u_right + fr.d_normal * ns.d_u_right)
                col_d0 = -(ef.d_delta0 + fr.d_normal * ns.d_delta0)
                col_a = -(ef.d_tilt + fr.d_normal * ns.d_tilt)
                # plate balance rows: force (1) and moment (2), per unit depth
                wgt = node_weight(c, i, n)
                wmom = node_moment_weight(c, i, n)
                e1 += wgt * fr.contact * sigma
                e2 += wmom * fr.contact * sigma + c.h_arm * wgt * fr.stress
                d11 += wgt * fr.contact * ns.d_delta0
                d12 += wgt * fr.contact * ns.d_tilt
                d21 += (wmom * fr.contact + c.h_arm * wgt * fr.d_normal) * ns.d_delta0
                d22 += (wmom * fr.contact + c.h_arm * wgt * fr.d_normal) * ns.d_tilt
                q1 = wgt * fr.contact * g
                q2 = (wmom * fr.contact + c.h_arm * wgt * fr.d_normal) * g
                c1_prev += q1 * ns.d_u_left
                c1_cur += q1 * ns.d_u_center
                c1_next = q1 * ns.d_u_right
                c2_prev += q2 * ns.d_u_left
                c2_cur += q2 * ns.d_u_center - c.h_arm * wgt * c.kif * fr.d_slip
                c2_next = q2 * ns.d_u_right
                if i > 0:
                    work[W_C1, i - 1, m] = c1_prev
                    work[W_C2, i - 1, m] = c2_prev
                c1_prev = c1_cur
                c1_cur = c1_next
                c2_prev = c2_cur
                c2_cur = c2_next
                # Thomas forward sweep
                den = jac_c - jac_l * cp_prev
                cp = jac_r / den
                r0 = (-residual - jac_l * r0_prev) / den
                r1 = (col_d0 - jac_l * r1_prev) / den
                work[W_CP, i, m] = cp
                work[W_R0, i, m] = r0
                work[W_R1, i, m] = r1
                if wp.static(tilt_on):
                    r2 = (col_a - jac_l * r2_prev) / den
                    work[W_R2, i, m] = r2
                    r2_prev = r2
                cp_prev = cp
                r0_prev = r0
                r1_prev = r1
                u_l = u_c
                u_c = u_r
            work[W_C1, n - 1, m] = c1_prev
            work[W_C2, n - 1, m] = c2_prev
            # ---- pass 2: back substitution, and the border products C*y ----
            y0_next = ft(0.0)
            y1_next = ft(0.0)
            y2_next = ft(0.0)
            s10 = ft(0.0)
            s11 = ft(0.0)
            s12 = ft(0.0)
            s20 = ft(0.0)
            s21 = ft(0.0)
            s22 = ft(0.0)
            for k in range(n):
                i = n - 1 - k
                cp = work[W_CP, i, m]
                y0 = work[W_R0, i, m] - cp * y0_next
                y1 = work[W_R1, i, m] - cp * y1_next
                work[W_R0, i, m] = y0
                work[W_R1, i, m] = y1
                c1 = work[W_C1, i, m]
                s10 += c1 * y0
                s11 += c1 * y1
                y0_next = y0
                y1_next = y1
                if wp.static(tilt_on):
                    y2 = work[W_R2, i, m] - cp * y2_next
                    work[W_R2, i, m] = y2
                    c2 = work[W_C2, i, m]
                    s12 += c1 * y2
                    s20 += c2 * y0
                    s21 += c2 * y1
                    s22 += c2 * y2
                    y2_next = y2
            # ---- Schur complement for (d delta0, d tilt) ----
            d_delta0 = ft(0.0)
            d_tilt = ft(0.0)
            if wp.static(tilt_on):
                a11 = d11 - s11
                a12 = d12 - s12
                a21 = d21 - s21
                a22 = d22 - s22
                b1 = -e1 - s10
                b2 = -e2 - s20
                det = a11 * a22 - a12 * a21
                d_delta0 = (b1 * a22 - a12 * b2) / det
                d_tilt = (a11 * b2 - a21 * b1) / det
            else:
                d_delta0 = (-e1 - s10) / (d11 - s11)
            # ---- pass 3: update and error-weighted norm of the update ----
            norm = ft(0.0)
            for i in range(n):
                dv = work[W_R0, i, m] - work[W_R1, i, m] * d_delta0
                if wp.static(tilt_on):
                    dv -= work[W_R2, i, m] * d_tilt
                vel = work[W_V, i, m] + dv
                work[W_V, i, m] = vel
                u = work[W_ZU, i, m] + g * vel
                norm = wp.max(norm, wp.abs(dv) / (rtol * (c.v_scale + wp.abs(vel))))
                norm = wp.max(norm, g * wp.abs(dv) / (rtol * (c.u_scale + wp.abs(u))))
            delta0 = delta0 + d_delta0
            tilt = tilt + d_tilt
            norm = wp.max(norm, wp.abs(d_delta0) / (rtol * (c.delta_scale + wp.abs(delta0))))
            norm = wp.max(norm, wp.abs(d_tilt) / (rtol * (c.tilt_scale + wp.abs(tilt))))
            if not is_finite(norm):
                non_finite = 1
                break
            if norm <= ft(s.newton_tol):
                converged = 1
                break
            # stagnation inside the error tolerance: the update has reached the round-off level of
            # the working precision (float32), further iterations cannot improve it
            if it > 0 and norm <= ft(1.0) and norm > ft(0.5) * prev_norm:
                converged = 1
                break
            prev_norm = norm
        return converged, delta0, tilt, iters, non_finite

    @wp.func
    def finalize_stage(
        c: Coeffs, p: MemberParams, s: SolverSettings, m: int, n: int, work: array3, gates: array3,
        K: array4, slot: int, g: ft, t_stage: wp.float64, t_step: wp.float64, delta0: ft, tilt: ft,
        h: ft, check_gates: int,
    ):
        """Stage derivatives K[slot] = f(Y) of the converged stage; returns
        (int tau_f dx, int sigma_n^+ dx, min sigma_n) per unit depth, and (check_gates = 1, stress
        gate, last stage of a step of size h) the gate-switch test of the step: (switch error,
        fraction of h to retry with).

        Gate switches (docs/model.md, "Gate switches"): the gate of each node is held over a step.
        Where the end-of-step yield margin z1 (stored in work[W_MARGIN]) has the other sign, the
        switch happened inside the step, at the fraction theta = z0/(z0 - z1) (linear in time); the
        relaxation then ran with the wrong gate over (1 - theta)*h, a local error of
        (1 - theta)*h*(|tau_el|, phi)*|s|/D. Its error-weighted size (like the step's error norm)
        is the switch error; > 1 rejects the step, and the retry ends where that error is 0.5."""
        v_disc = ft(disc_velocity_at(p, t_stage, t_step))
        sum_tau = wp.float64(0.0)
        sum_sigma = wp.float64(0.0)
        min_sigma = wp.float64(1.0e300)
        switch_error = ft(0.0)
        retry_fraction = ft(1.0)
        rtol = ft(wp.min(s.switch_rtol, wp.float64(1.0e30)))
        u_l = ft(0.0)
        u_c = work[W_ZU, 0, m] + g * work[W_V, 0, m]
        for i in range(n):
            u_r = ft(0.0)
            if i < n - 1:
                u_r = work[W_ZU, i + 1, m] + g * work[W_V, i + 1, m]
            vel = work[W_V, i, m]
            ns = normal_stress(c, i, n, u_l, u_c, u_r, delta0, tilt)
            sigma = ns.value
            sliding = node_sliding(gates, i, m)
            fr = interface_friction(
                c, sigma, vel, v_disc, work[W_ZT, i, m], work[W_ZP, i, m], g, node_gate(gates, i, m), sliding,
                ft(s.sliding_width),
            )
            if check_gates == 1:
                work[W_CONTACT, i, m] = fr.contact  # at the end of the step: fronts skip lifted-off nodes
                work[W_GATE_END, i, m] = fr.gate
            if wp.static(stress_gate):
                if check_gates == 1:
                    z1 = yield_margin(c, fr.stress, fr.area)
                    work[W_MARGIN, i, m] = z1
                    # d(dz/dt)/d(gate) at the end of the step: the gate enters the rates of tau_el
                    # and phi (and A through phi); the pad's rates do not depend on it
                    slip = v_disc - c.kif * vel
                    relax = wp.abs(slip) * c.inv_D
                    darea_dgate = fr.contact * sigma * c.inv_hardness * c.b / (c.phi0 + fr.contact_age) * (-fr.contact_age * relax)
                    dtau_dgate = -fr.elastic_stress * relax
                    if wp.static(viscous):
                        dtau_dgate += c.eta_vstar * wp.sign(slip) * wp.log(ft(1.0) + wp.abs(slip) / c.vstar) * darea_dgate
                    work[W_DMARGIN, i, m] = wp.sign(fr.stress) * dtau_dgate - c.tau_c * darea_dgate
                    open_now = ft(0.0)
                    if z1 > ft(0.0):
                        open_now = ft(1.0)
                    if sliding == ft(0.0) and open_now != fr.gate:
                        z0 = gates[G_MARGIN, i, m]
                        theta = ft(0.0)
                        if z0 != z1:
                            theta = wp.clamp(z0 / (z0 - z1), ft(0.0), ft(1.0))
                        rate = wp.max(
                            wp.abs(fr.elastic_stress) * relax / (rtol * (c.tau_scale + wp.abs(fr.elastic_stress))),
                            fr.contact_age * relax / (rtol * (c.phi_scale + wp.abs(fr.contact_age))),
                        )
                        e = (ft(1.0) - theta) * h * rate
                        switch_error = wp.max(switch_error, e)
                        if e > ft(1.0):
                            retry_fraction = wp.min(retry_fraction, theta + ft(0.5) * (ft(1.0) - theta) / e)
            K[slot, C_U, i, m] = vel
            if wp.static(inertia):
                K[slot, C_V, i, m] = (vel - work[W_ZV, i, m]) / g
            else:
                K[slot, C_V, i, m] = ft(0.0)
            K[slot, C_TAU, i, m] = fr.elastic_stress_rate
            K[slot, C_PHI, i, m] = fr.contact_age_rate
            wgt = wp.float64(node_weight(c, i, n))
            sum_tau += wgt * wp.float64(fr.stress)
            sum_sigma += wgt * wp.float64(fr.contact * sigma)
            min_sigma = wp.min(min_sigma, wp.float64(sigma))
            u_l = u_c
            u_c = u_r
        return sum_tau, sum_sigma, min_sigma, switch_error, retry_fraction

    @wp.func
    def gate_regime(gate: ft, sliding: ft):
        """0: closed, 1: sliding on the yield surface, 2: open."""
        if sliding > ft(0.0):
            return 1
        if gate >= ft(1.0):
            return 2
        return 0

    @wp.func
    def switch_gates(
        c: Coeffs, p: MemberParams, st: IntegratorState, m: int, n: int, state: array3, K: array4,
        slot: int, gates: array3, work: array3, t_old: wp.float64, t_new: wp.float64,
        yield_time: wp.array2d(dtype=wp.float64),
    ):
        """After an accepted step (state advanced): choose each node's gate regime for the next step
        from its end-of-step yield margin z1, store the margin, correct the FSAL derivatives K[slot] of
        the nodes whose gate changed (the gate enters only the relaxation rates of tau_el and phi,
        closed-form in the state) and record the first opening time (linear in the margin).

        A closed or open node takes the Heaviside theta(z1), unless it crossed the yield surface
        z = 0 into a side whose field points back (Filippov sliding): the margin's rate is affine in
        the gate, dz/dt(g) = r_obs + (g - g_old)*dr, r_obs seen over the step and dr = d(dz/dt)/dg
        at its end (work[W_DMARGIN]); with dr < 0 and the far side's rate of opposite sign the node
        slides. A sliding node's gate is solved in every stage from |tau_f| = tau_c*A
        (interface_friction), pinned at 1 or 0 where that cannot hold; the node keeps that implicit
        regime for the rest of the run."""
        v_disc = ft(disc_velocity_at(p, t_new, t_old))
        h = ft(t_new - t_old)
        for i in range(n):
            z1 = work[W_MARGIN, i, m]
            z0 = gates[G_MARGIN, i, m]
            sliding = gates[G_SLIDE, i, m]
            gate = gates[G_GATE, i, m]
            new_sliding = ft(0.0)
            new_gate = ft(0.0)
            if sliding > ft(0.0):
                # a sliding node stays in the implicit regime: where |tau_f| = tau_c*A cannot hold, its
                # solved gate is pinned at 1 (open) or 0 (closed), which is the Heaviside value; leaving
                # the regime would only trade the implicit gate for repeated located switches
                gate = work[W_GATE_END, i, m]  # the last stage's solved gate: K[slot] is consistent with it
                new_gate = gate
                new_sliding = ft(1.0)
            else:
                if z1 > ft(0.0):
                    new_gate = ft(1.0)
                dr = work[W_DMARGIN, i, m]
                if dr < ft(0.0) and h > ft(0.0) and new_gate != gate:
                    r_obs = (z1 - z0) / h
                    rate_far = r_obs + (ft(1.0) - ft(2.0) * gate) * dr  # the rate with the other gate value
                    if (gate == ft(0.0) and rate_far < ft(0.0)) or (gate == ft(1.0) and rate_far > ft(0.0)):
                        new_sliding = ft(1.0)
                        new_gate = wp.clamp(gate + (-z1 / h - r_obs) / dr, ft(0.0), ft(1.0))  # start value
            if new_gate != gate:
                relax = (new_gate - gate) * wp.abs(v_disc - c.kif * state[C_V, i, m]) * c.inv_D
                K[slot, C_TAU, i, m] = K[slot, C_TAU, i, m] - state[C_TAU, i, m] * relax
                K[slot, C_PHI, i, m] = K[slot, C_PHI, i, m] - state[C_PHI, i, m] * relax
            if gate_regime(new_gate, new_sliding) != gate_regime(gate, sliding):
                st.gate_switches = st.gate_switches + 1
            if new_gate > ft(0.0) and not wp.isfinite(yield_time[i, m]):
                theta = wp.float64(0.0)
                if z0 != z1 and z1 > ft(0.0):
                    theta = wp.clamp(wp.float64(z0) / wp.float64(z0 - z1), wp.float64(0.0), wp.float64(1.0))
                yield_time[i, m] = t_old + theta * (t_new - t_old)
            gates[G_GATE, i, m] = new_gate
            gates[G_SLIDE, i, m] = new_sliding
            gates[G_MARGIN, i, m] = z1
        return st

    @wp.func
    def error_norm(
        c: Coeffs, s: SolverSettings, m: int, n: int, state: array3, K: array4, work: array3,
        s1: int, s2: int, s3: int, h: ft,
    ):
        """Max over nodes and differential components of |h*sum (b - b_hat) K| / (rtol*(scale + |y|)).

        The velocity's estimate is filtered by the diagonal of (I - gamma*h*J)^-1 (Hairer & Wanner,
        IV.8; Shampine): the pad velocity is stiff and overdamped, and its raw estimate does not
        vanish for modes that the L-stable scheme damps correctly."""
        g = ft(GAMMA) * h
        rtol = ft(s.rtol)
        err = ft(0.0)
        for i in range(n):
            for comp in range(N_COMPONENTS):
                use = True
                scale = c.u_scale
                if comp == C_V:
                    scale = c.v_scale
                    use = wp.static(inertia)
                if comp == C_TAU:
                    scale = c.tau_scale
                if comp == C_PHI:
                    scale = c.phi_scale
                if use:
                    k1 = K[s1, comp, i, m]
                    k2 = K[s2, comp, i, m]
                    k3 = K[s3, comp, i, m]
                    y = state[comp, i, m]
                    y_new = y + h * (ft(W_TRB) * (k1 + k2) + ft(GAMMA) * k3)
                    e = h * (ft(ERR1) * k1 + ft(ERR2) * k2 + ft(ERR3) * k3)
                    if comp == C_V:
                        e = e * wp.min(ft(1.0), wp.abs(c.rhoH / (g * work[W_DIAG, i, m])))
                    wgt = rtol * (scale + wp.max(wp.abs(y), wp.abs(y_new)))
                    err = wp.max(err, wp.abs(e) / wgt)
                    if not is_finite(e):
                        err = ft(1.0e30)
        return err

    @wp.func
    def advance_state(m: int, n: int, state: array3, K: array4, s1: int, s2: int, s3: int, h: ft, be: int):
        """y_{n+1} = y_n + h * sum_j b_j K_j (backward Euler when be = 1: y_n + h*K[s3]);
        the velocity is the last stage's (stiffly accurate, and algebraic without inertia)."""
        for i in range(n):
            for comp in range(N_COMPONENTS):
                if comp == C_V:
                    state[comp, i, m] = K[s3, C_U, i, m]
                else:
                    k3 = K[s3, comp, i, m]
                    if be == 1:
                        state[comp, i, m] = state[comp, i, m] + h * k3
                    else:
                        k = ft(W_TRB) * (K[s1, comp, i, m] + K[s2, comp, i, m]) + ft(GAMMA) * k3
                        state[comp, i, m] = state[comp, i, m] + h * k

    @wp.func
    def track_fronts(
        p: MemberParams, st: IntegratorState, m: int, n: int, state: array3, K: array4, work: array3, s2: int, s3: int,
        t_old: wp.float64, t_new: wp.float64, arrival: wp.array2d(dtype=wp.float64),
        arrival_error: wp.array2d(dtype=wp.float64), direction: int,
        threshold: wp.float64, use_stage2: int,
    ):
        """Fold an accepted step (before the state is advanced) into the front tracking: the running
        maximum of the detachment velocity w, each node's first crossing of st.front_level (on the
        quadratic through the step's ends and its second stage, linear after a backward-Euler
        restart, with its error estimate in arrival_error), and front_last: the last step at which some node had
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
        for i in range(n):
            if work[W_CONTACT, i, m] == ft(0.0):
                continue
            w_old = detachment_velocity(wp.float64(state[C_V, i, m]), disc_sign, direction)
            w_new = detachment_velocity(wp.float64(K[s3, C_U, i, m]), disc_sign, direction)
            st.front_max = wp.max(st.front_max, w_new)
            w_step = wp.max(w_step, w_new)
            if not wp.isfinite(arrival[i, m]):
                if use_stage2 == 1:
                    # quadratic through the step's ends and its second stage (at c2*h): a sharper
                    # crossing time, and its distance to the linear one as the error estimate
                    w_mid = detachment_velocity(wp.float64(K[s2, C_U, i, m]), disc_sign, direction)
                    if w_new >= st.front_level or w_mid >= st.front_level:
                        t_cross, t_err = crossing_time_quadratic(
                            st.front_level, t_old, w_old, wp.float64(C2), w_mid, t_new, w_new
                        )
                        arrival[i, m] = t_cross
                        arrival_error[i, m] = t_err
                elif w_new >= st.front_level:
                    arrival[i, m] = crossing_time(st.front_level, t_old, w_old, t_new, w_new)
                    arrival_error[i, m] = t_new - t_old  # backward-Euler step: no inner point
        if w_step > wp.float64(0.0) and w_step >= threshold * st.front_max:
            st.front_last = t_new
        st.front_now = w_step
        return st

    @wp.func
    def record_fields(
        c: Coeffs, p: MemberParams, st: IntegratorState, m: int, n: int, state: array3,
        t_old: wp.float64, t_new: wp.float64, delta0: ft, tilt: ft, times: wp.array(dtype=wp.float64),
        previous: array3, record: array4,
    ):
        """Sample the fields (pad velocity, slip rate, contact pressure, friction stress) of a
        recorded member at the grid times in (t_old, t_new], by linear interpolation between the
        accepted points; ``previous`` holds the fields at t_old."""
        slot = st.record_slot
        n_times = times.shape[0]
        k_end = st.record_next
        while k_end < n_times:
            if times[k_end] > t_new:
                break
            k_end += 1
        v_disc = ft(disc_velocity_at(p, t_new, t_old))
        span = t_new - t_old
        u_l = ft(0.0)
        u_c = state[C_U, 0, m]
        for i in range(n):
            u_r = ft(0.0)
            if i < n - 1:
                u_r = state[C_U, i + 1, m]
            vel = state[C_V, i, m]
            ns = normal_stress(c, i, n, u_l, u_c, u_r, delta0, tilt)
            sigma = ns.value
            fr = interface_friction(
                c, sigma, vel, v_disc, state[C_TAU, i, m], state[C_PHI, i, m], ft(0.0), ft(1.0), ft(0.0), ft(1.0)
            )
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

    @wp.func
    def detachment_over(p: MemberParams, st: IntegratorState, outputs: OutputSettings):
        """The automatic end: mu has passed a maximum reached after the disc slid AUTO_END_MIN_TRAVEL*D
        and fallen AUTO_END_PEAK_DROP below it, and (fronts on) no node is above
        AUTO_END_FRONT_FRACTION of the arrival level."""
        if st.t <= p.rest_until or st.npts < 3 or st.mu_s <= wp.float64(0.0):
            return False
        if disc_travel_at(p, st.mu_s_time) < wp.float64(AUTO_END_MIN_TRAVEL) * p.memory_length:
            return False  # the maximum must come from the sliding disc
        if st.mu_final > (wp.float64(1.0) - wp.float64(AUTO_END_PEAK_DROP)) * st.mu_s:
            return False
        if outputs.fronts == 1 and st.front_max > wp.float64(0.0):
            if st.front_now >= wp.float64(AUTO_END_FRONT_FRACTION) * outputs.front_threshold * st.front_max:
                return False
        return True

    @wp.func
    def accept_point(
        st: IntegratorState, p: MemberParams, t_new: wp.float64, sum_tau: wp.float64,
        sum_sigma: wp.float64, min_sigma: wp.float64,
    ):
        st.t = t_new
        st.steps_accepted = st.steps_accepted + 1
        sign_v = wp.float64(1.0)
        if p.disc_velocity < wp.float64(0.0):
            sign_v = wp.float64(-1.0)
        mu = wp.float64(0.0)
        if sum_sigma > wp.float64(0.0):
            mu = sign_v * sum_tau / sum_sigma
        st = record_friction_point(st, t_new, mu)
        if min_sigma < wp.float64(0.0) and normal_force_at(p, t_new) > wp.float64(0.0):
            st.lift_off = 1
        if t_new == p.stop_time:
            st.restart = 1
        return st

    @wp.func
    def reject(st: IntegratorState, s: SolverSettings, h_next: wp.float64, newton_failed: int, non_finite: int):
        st.steps_rejected = st.steps_rejected + 1
        st.newton_failures = st.newton_failures + newton_failed
        st.last_failure_non_finite = non_finite
        st.h = h_next
        if h_next < s.min_step:
            st.done = 1
            if non_finite == 1:
                st.status = STATUS_NON_FINITE
            else:
                st.status = STATUS_STEP_UNDERFLOW
        return st

    @wp.kernel(module="unique")
    def integrate(
        params: wp.array(dtype=MemberParams),
        settings: SolverSettings,
        states: wp.array(dtype=IntegratorState),
        state: array3,
        K: array4,
        work: array3,
        launch_steps: int,
        outputs: OutputSettings,
        arrival: wp.array2d(dtype=wp.float64),
        arrival_error: wp.array2d(dtype=wp.float64),
        record_times: wp.array(dtype=wp.float64),
        record_previous: array3,
        record: array4,
        gates: array3,
        yield_time: wp.array2d(dtype=wp.float64),
    ):
        """Advance each member by at most ``launch_steps`` attempted steps (or to its end_time).

        gates: (N_GATE, node, member) yield-gate state (stress gate only; else a (N_GATE, 1, 1) dummy);
        yield_time: (node, member) first gate opening time, s (stress gate only)."""
        m = wp.tid()
        st = states[m]
        if st.done != 0:
            return
        p = params[m]
        n = state.shape[1]
        c = make_coeffs(p, n)
        delta0 = ft(st.delta0)
        tilt = ft(st.tilt)
        for _attempt in range(launch_steps):
            t = st.t
            if t >= p.end_time or t >= st.front_until:
                st.done = 1
                break
            if p.auto_end > wp.float64(0.0) and detachment_over(p, st, outputs):
                st.done = 1
                break
            if st.steps_accepted + st.steps_rejected >= settings.max_steps:
                st.status = STATUS_MAX_STEPS
                st.done = 1
                break
            bp = next_breakpoint(p, t)
            h = wp.min(st.h, settings.max_step)
            clipped = int(0)
            if h >= bp - t:
                h = bp - t
                clipped = 1
            elif h > wp.float64(0.5) * (bp - t):
                h = wp.float64(0.5) * (bp - t)  # two equal steps, not a long one and a sliver
            if wp.static(stress_gate):
                if st.switch_limit < t + h:
                    # a gate switch located by a rejected step lies before: end the step there
                    h = st.switch_limit - t
                    clipped = 2
            t_new = t + h
            if clipped == 1:
                t_new = bp
            if clipped == 2:
                t_new = st.switch_limit
            s1 = st.fsal
            s2 = (s1 + 1) % 3
            s3 = (s1 + 2) % 3
            if st.restart != 0:
                # backward Euler (re)start: one implicit stage, accepted without error estimate
                g = ft(h)
                prepare_stage(m, n, state, K, work, ft(h), ft(0.0), s1, ft(0.0), s1, 0, ft(0.0))
                ok, d0, a, iters, bad = newton_solve(c, p, settings, m, n, work, gates, g, t_new, t, delta0, tilt)
                st.newton_iterations = st.newton_iterations + iters
                if ok == 1:
                    sum_tau, sum_sigma, min_sigma, sw_err, sw_frac = finalize_stage(
                        c, p, settings, m, n, work, gates, K, s3, g, t_new, t, d0, a, ft(h), 1
                    )
                    if outputs.fronts == 1:
                        st = track_fronts(p, st, m, n, state, K, work, s2, s3, t, t_new, arrival, arrival_error, outputs.front_direction, outputs.front_threshold, 0)
                    advance_state(m, n, state, K, s1, s2, s3, ft(h), 1)
                    if wp.static(stress_gate):
                        st = switch_gates(c, p, st, m, n, state, K, s3, gates, work, t, t_new, yield_time)
                    delta0 = d0
                    tilt = a
                    if st.record_slot >= 0:
                        st = record_fields(c, p, st, m, n, state, t, t_new, d0, a, record_times, record_previous, record)
                    st.restart = 0
                    st.fsal = s3
                    st.h = settings.initial_step
                    st.npts = 0  # mu(t) may jump here: no parabola across the discontinuity
                    st = accept_point(st, p, t_new, sum_tau, sum_sigma, min_sigma)
                else:
                    st = reject(st, settings, h * wp.float64(0.25), 1, bad)
                    if st.done != 0:
                        break
                continue
            g = ft(wp.float64(GAMMA) * h)
            # stage 2 (trapezoidal stage, at t + 2*gamma*h)
            prepare_stage(m, n, state, K, work, ft(h), ft(GAMMA), s1, ft(0.0), s1, 1, ft(0.0))
            ok, d0, a, iters, bad = newton_solve(
                c, p, settings, m, n, work, gates, g, t + wp.float64(C2) * h, t, delta0, tilt
            )
            st.newton_iterations = st.newton_iterations + iters
            sum_tau = wp.float64(0.0)
            sum_sigma = wp.float64(0.0)
            min_sigma = wp.float64(0.0)
            sw_err = ft(0.0)
            sw_frac = ft(1.0)
            if ok == 1:
                finalize_stage(c, p, settings, m, n, work, gates, K, s2, g, t + wp.float64(C2) * h, t, d0, a, ft(h), 0)
                # stage 3 (BDF2 stage, at t + h)
                prepare_stage(m, n, state, K, work, ft(h), ft(W_TRB), s1, ft(W_TRB), s2, 2, ft(EXTRAPOLATE_STAGE3))
                ok, d0, a, iters, bad = newton_solve(c, p, settings, m, n, work, gates, g, t_new, t, d0, a)
                st.newton_iterations = st.newton_iterations + iters
                if ok == 1:
                    sum_tau, sum_sigma, min_sigma, sw_err, sw_frac = finalize_stage(
                        c, p, settings, m, n, work, gates, K, s3, g, t_new, t, d0, a, ft(h), 1
                    )
            if ok != 1:
                st = reject(st, settings, h * wp.float64(0.25), 1, bad)
                if st.done != 0:
                    break
                continue
            err = wp.float64(error_norm(c, settings, m, n, state, K, work, s1, s2, s3, ft(h)))
            factor = wp.float64(5.0)
            if err > wp.float64(0.0):
                factor = wp.min(wp.float64(5.0), wp.max(wp.float64(0.2), wp.float64(0.9) * wp.pow(err, wp.float64(-1.0 / ORDER_ESTIMATE))))
            if wp.static(stress_gate):
                if err <= wp.float64(1.0) and sw_err > ft(1.0):
                    if wp.float64(sw_frac) * h > settings.min_step and st.switch_retries < MAX_SWITCH_RETRIES:
                        # a gate switched inside the step, too early to be moved to its end: retry up
                        # to just past the switch (the error-controlled step size st.h is kept)
                        st.steps_rejected = st.steps_rejected + 1
                        st.switch_retries = st.switch_retries + 1
                        st.switch_limit = t + wp.float64(sw_frac) * h
                        continue
                    st.unlocated_switches = st.unlocated_switches + 1
            if err <= wp.float64(1.0):
                if outputs.fronts == 1:
                    st = track_fronts(p, st, m, n, state, K, work, s2, s3, t, t_new, arrival, arrival_error, outputs.front_direction, outputs.front_threshold, 1)
                advance_state(m, n, state, K, s1, s2, s3, ft(h), 0)
                if wp.static(stress_gate):
                    switches_before = st.gate_switches
                    st = switch_gates(c, p, st, m, n, state, K, s3, gates, work, t, t_new, yield_time)
                    if st.gate_switches != switches_before or sw_err > ft(1.0):
                        st.switch_retries = 0  # the located switch happened (or was given up)
                    if t_new >= st.switch_limit:
                        st.switch_limit = wp.float64(1.0e300)
                delta0 = d0
                tilt = a
                if st.record_slot >= 0:
                    st = record_fields(c, p, st, m, n, state, t, t_new, d0, a, record_times, record_previous, record)
                st.fsal = s3
                h_next = h * factor
                if clipped != 0:
                    h_next = wp.max(h_next, st.h)
                st.h = h_next
                st = accept_point(st, p, t_new, sum_tau, sum_sigma, min_sigma)
                if st.restart != 0:
                    st.h = settings.initial_step
            else:
                st = reject(st, settings, h * wp.min(factor, wp.float64(0.9)), 0, 0)
                if st.done != 0:
                    break
        st.delta0 = wp.float64(delta0)
        st.tilt = wp.float64(tilt)
        states[m] = st

    @wp.kernel(module="unique")
    def evaluate_fields(
        params: wp.array(dtype=MemberParams),
        states: wp.array(dtype=IntegratorState),
        state: array3,
        normal_stress_out: wp.array2d(dtype=ft),
        friction_stress_out: wp.array2d(dtype=ft),
    ):
        """Interface normal stress (Pa, contact part max(sigma_n, 0)) and friction stress (Pa) of
        the current state of each member, nodes x members."""
        m = wp.tid()
        st = states[m]
        p = params[m]
        n = state.shape[1]
        c = make_coeffs(p, n)
        delta0 = ft(st.delta0)
        tilt = ft(st.tilt)
        v_disc = ft(disc_velocity_at(p, st.t, st.t))
        u_l = ft(0.0)
        u_c = state[C_U, 0, m]
        for i in range(n):
            u_r = ft(0.0)
            if i < n - 1:
                u_r = state[C_U, i + 1, m]
            ns = normal_stress(c, i, n, u_l, u_c, u_r, delta0, tilt)
            sigma = ns.value
            fr = interface_friction(
                c, sigma, state[C_V, i, m], v_disc, state[C_TAU, i, m], state[C_PHI, i, m], ft(0.0), ft(1.0), ft(0.0), ft(1.0)
            )
            normal_stress_out[i, m] = fr.contact * sigma
            friction_stress_out[i, m] = fr.stress
            u_l = u_c
            u_c = u_r

    return dict(integrate=integrate, evaluate_fields=evaluate_fields, ft=ft, Coeffs=Coeffs)
