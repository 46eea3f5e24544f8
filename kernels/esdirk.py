"""TR-BDF2 as a stiffly accurate ESDIRK (docs/model.md, "Time integration").

Tableau (Hosea & Shampine 1996, "Analysis and implementation of TR-BDF2", Appl. Numer. Math. 20),
gamma = 1 - sqrt(2)/2, w = sqrt(2)/4:

    c = (0, 2 gamma, 1)     A = [[0, 0, 0], [gamma, gamma, 0], [w, w, gamma]]     b = (w, w, gamma)
    b_hat = ((1 - w)/3, (3w + 1)/3, gamma/3)   (embedded order 3)

L-stable, order 2, stiffly accurate (b = last row of A: y_{n+1} is the last stage). The explicit
first stage reuses f(y_n) of the previous step (FSAL); the local error estimate is
h * sum (b - b_hat) K, O(h^3). A backward-Euler step (one implicit stage, no estimate) starts the
run and restarts it after a jump of the disc velocity (the sudden stop), which invalidates the FSAL
stage and the algebraic plate state.

The stage derivatives live in three slots of ``stages`` (K); s1 holds f(y_n), and the slot of the
last stage becomes the next step's s1. ``stage_constant``, ``solution_increment`` and
``error_increment`` are the tableau alone (tests/test_kernels.py measures with them the order 2 of
the solution on a linear stiff system, the order 3 of the error estimate on a non-stiff one, and
L-stability); the array functions apply them to every node and component.

``make_esdirk(ft, model, terms, newton, gates, team, method)`` builds the functions for one working
precision and model, by part: the tableau (``make_tableau``), its application to the arrays
(``make_tr_bdf2_arrays``), the StepResult (``make_step_result``) and the attempted step
(``make_tr_bdf2_steps``: ``implicit_step``, TR-BDF2 or a backward-Euler restart, its stages one
loop so that their code is compiled once); ESDIRK4 likewise (``make_esdirk4_arrays``, ``make_esdirk4``).
"""

import math

import warp as wp

from .model_terms import make_ratio_max, quotient
from .types import C_PHI, C_TAU, C_U, C_V, E_CONTACT, E_DIAG, N_COMPONENTS, W_V, MemberParams, SolverSettings

GAMMA = 1.0 - math.sqrt(2.0) / 2.0
W_TRB = math.sqrt(2.0) / 4.0
C2 = 2.0 * GAMMA
B_HAT = ((1.0 - W_TRB) / 3.0, (3.0 * W_TRB + 1.0) / 3.0, GAMMA / 3.0)
ERR1, ERR2, ERR3 = W_TRB - B_HAT[0], W_TRB - B_HAT[1], GAMMA - B_HAT[2]
EXTRAPOLATE_STAGE3 = 1.0 / C2  # linear extrapolation of V from t_n and t_n + c2*h to t_n + h
ORDER = 2  # of the solution; the error estimate is O(h^3)


# ESDIRK4(3)6L[2]SA (Kennedy & Carpenter 2016, NASA/TM-2016-219173; the coefficients as in SUNDIALS
# ARKODE_ESDIRK436L2SA_6_3_4; studies/esdirk_order.py): 6 stages, the first explicit (FSAL), gamma =
# 1/4, L-stable, stiffly accurate, order 4, embedded order 3 (estimate O(h^4)), stage order 2;
# c5 = 26/25 > 1 (kernels/model_terms.py disc_velocity_piece)
_SQ2 = math.sqrt(2.0)
E4_GAMMA = 0.25
E4_C = (0.0, 0.5, (2.0 - _SQ2) / 4.0, 5.0 / 8.0, 26.0 / 25.0, 1.0)
E4_B = ((1181.0 - 987.0 * _SQ2) / 13782.0, (1181.0 - 987.0 * _SQ2) / 13782.0, 47.0 * (-267.0 + 1783.0 * _SQ2) / 273343.0,
        -16.0 * (-22922.0 + 3525.0 * _SQ2) / 571953.0, -15625.0 * (97.0 + 376.0 * _SQ2) / 90749876.0, 0.25)
E4_B_HAT = (-480923228411.0 / 4982971448372.0, -480923228411.0 / 4982971448372.0, 6709447293961.0 / 12833189095359.0,
            3513175791894.0 / 6748737351361.0, -498863281070.0 / 6042575550617.0, 2077005547802.0 / 8945017530137.0)


def _e4_matrix():
    a = [[0.0] * 6 for _ in range(6)]
    for i in range(1, 6):
        a[i][i] = E4_GAMMA
    a[2][1] = (1.0 - _SQ2) / 8.0
    a[3][1] = (5.0 - 7.0 * _SQ2) / 64.0
    a[3][2] = 7.0 * (1.0 + _SQ2) / 32.0
    a[4][1] = -(13796.0 + 54539.0 * _SQ2) / 125000.0
    a[4][2] = (506605.0 + 132109.0 * _SQ2) / 437500.0
    a[4][3] = 166.0 * (-97.0 + 376.0 * _SQ2) / 109375.0
    a[5] = list(E4_B)
    for i in range(1, 5):
        a[i][0] = E4_C[i] - sum(a[i][1:])
    return a


E4_A = _e4_matrix()
E4_ERR = tuple(b - bh for b, bh in zip(E4_B, E4_B_HAT))
# flat names for the kernels (Warp reads module constants by name)
(E4_A10, E4_A20, E4_A21, E4_A30, E4_A31, E4_A32, E4_A40, E4_A41, E4_A42, E4_A43,
 E4_B0, E4_B1, E4_B2, E4_B3, E4_B4, E4_B5) = (E4_A[1][0], E4_A[2][0], E4_A[2][1], E4_A[3][0], E4_A[3][1], E4_A[3][2],
                                              E4_A[4][0], E4_A[4][1], E4_A[4][2], E4_A[4][3], *E4_B)
E4_D0, E4_D1, E4_D2, E4_D3, E4_D4, E4_D5 = E4_ERR
E4_C1, E4_C2, E4_C3, E4_C4 = E4_C[1:5]


def make_tableau(ft):
    """The tableau's scalar operations for type ``ft``."""

    @wp.func
    def stage_constant(y: ft, h: ft, a1: ft, k1: ft, a2: ft, k2: ft, n_terms: int):
        """z = y + h*(a1*k1 + a2*k2), first n_terms terms (0, 1 or 2)."""
        z = y
        if n_terms >= 1:
            z += h * a1 * k1
        if n_terms >= 2:
            z += h * a2 * k2
        return z

    @wp.func
    def solution_increment(h: ft, k1: ft, k2: ft, k3: ft):
        """h * sum b K."""
        return h * (ft(W_TRB) * (k1 + k2) + ft(GAMMA) * k3)

    @wp.func
    def error_increment(h: ft, k1: ft, k2: ft, k3: ft):
        """h * sum (b - b_hat) K: the local error estimate of the order-2 solution."""
        return h * (ft(ERR1) * k1 + ft(ERR2) * k2 + ft(ERR3) * k3)

    return dict(stage_constant=stage_constant, solution_increment=solution_increment, error_increment=error_increment)


def make_tr_bdf2_arrays(ft, model, terms, team, tableau):
    """The tableau applied to every node and component of a member: the stage constants and Newton
    start (prepare_stage), the error norm (fold_error, error_norm) and the solution update
    (advance_state)."""
    inertia = bool(model.inertia)
    team_max = team["team_max"]
    barrier = team["barrier"]
    Coeffs = terms["Coeffs"]
    stage_constant = tableau["stage_constant"]
    solution_increment = tableau["solution_increment"]
    error_increment = tableau["error_increment"]
    array3 = wp.array3d(dtype=ft)
    array4 = wp.array4d(dtype=ft)
    vec4 = wp.types.vector(length=N_COMPONENTS, dtype=ft)
    ratio_max = make_ratio_max(ft)

    @wp.func
    def prepare_stage(
        c: Coeffs, m: int, n: int, state: array3, K: array4, work: array3,
        h: ft, a1: ft, s1: int, a2: ft, s2: int, n_terms: int, extrapolate: ft,
    ):
        """Stage constants z = y_n + h*(a1*K[s1] + a2*K[s2]) (first n_terms terms) into work[0..3] and
        the Newton start for V into work[W_V]: v_n + extrapolate*(V(stage s2) - v_n). (The lane's
        nodes; the Newton solve that follows reads the stage displacement of the neighbouring lanes'
        end nodes: a barrier.) A node's values are all read before its constants are written: for
        the compiler a write may alias a later read, so reads after a write wait for it in turn."""
        for i in range(c.first_node, c.end_node):
            y = vec4()
            k1 = vec4()
            k2 = vec4()
            for comp in range(N_COMPONENTS):
                y[comp] = state[comp, i, m]
                if n_terms >= 1:
                    k1[comp] = K[s1, comp, i, m]
                if n_terms >= 2:
                    k2[comp] = K[s2, comp, i, m]
            for comp in range(N_COMPONENTS):
                work[comp, i, m] = stage_constant(y[comp], h, a1, k1[comp], a2, k2[comp], n_terms)
            guess = y[C_V]
            if n_terms >= 2:
                guess = y[C_V] + extrapolate * (k2[C_U] - y[C_V])
            work[W_V, i, m] = guess
        barrier()

    @wp.func
    def filter_stiffening(c: Coeffs, s: SolverSettings, n: int, g: ft):
        """What the velocity error filter's g * diag (kg/m^2) gains so that its elastic part is that
        of a grid of s.error_filter_nodes nodes where that grid is finer than the member's n nodes:
        g^2 * 2 M H (1/dx_f^2 - 1/dx^2), dx_f = L / (error_filter_nodes - 1) (m), g = gamma*h (s);
        0 where the member's grid is as fine or finer, or error_filter_nodes is 0 (docs/model.md,
        "Time integration": the elastic diagonal 2 M H / dx^2 grows as N^2, and with it how much of
        the pad's low-mode ringing the filter hides)."""
        extra = ft(0.0)
        if s.error_filter_nodes > wp.float64(n):
            inv_dx_filter = ft((s.error_filter_nodes - wp.float64(1.0)) / wp.float64(c.L))
            extra = g * g * ft(2.0) * c.MH * (inv_dx_filter * inv_dx_filter - c.inv_dx * c.inv_dx)
        return extra

    @wp.func
    def fold_error(c: Coeffs, step_end: array3, comp: int, i: int, m: int, e: ft, y: ft, y_new: ft, g: ft, rtol: ft,
                   filter_extra: ft, top: ft, bottom: ft):
        """Fold the local error estimate e of component comp at node i (from y to y_new; g = gamma*h)
        into the running maximum top/bottom (ratio_max) of |e| / (rtol*(scale + max(|y|, |y_new|))),
        scale the component's natural scale; the velocity's e filtered by min(1, |rho H / (g *
        diag + filter_extra)|) (diag: step_end[E_DIAG]; filter_extra: filter_stiffening; in float64
        as |e| rho H / (weight |g diag + filter_extra|) where the filter is below 1, without a
        quotient); 1e30 where e is not finite. Returns (top, bottom): the sweep's norm is
        quotient(top, bottom)."""
        scale = c.u_scale
        num = wp.abs(e)
        den_factor = ft(1.0)
        if comp == C_V:
            scale = c.v_scale
            if c.v_scale_contact != c.v_scale:  # capped (contact_velocity_scale): at nodes in contact at the step's end
                if step_end[E_CONTACT, i, m] != ft(0.0):
                    scale = c.v_scale_contact
            if wp.static(ft == wp.float64):
                diag = wp.abs(g * step_end[E_DIAG, i, m] + filter_extra)
                if diag > c.rhoH:
                    num = num * c.rhoH
                    den_factor = diag
            else:
                num = wp.abs(e * wp.min(ft(1.0), wp.abs(c.rhoH / (g * step_end[E_DIAG, i, m] + filter_extra))))
        if comp == C_TAU:
            scale = c.tau_scale
        if comp == C_PHI:
            scale = c.phi_scale
        wgt = rtol * (scale + wp.max(wp.abs(y), wp.abs(y_new)))
        top, bottom = ratio_max(top, bottom, num, wgt * den_factor)
        if not wp.isfinite(e):
            top = ft(1.0e30)
            bottom = ft(1.0)
        return top, bottom

    @wp.func
    def error_norm(
        c: Coeffs, s: SolverSettings, m: int, n: int, state: array3, K: array4, step_end: array3, work: array3,
        s1: int, s2: int, s3: int, h: ft,
    ):
        """Max over nodes and differential components of |h*sum (b - b_hat) K| / (rtol*(scale + |y|)).
        Leaves the step's solution y_new of every component but the velocity in work[comp] (the
        stage constants' slots, free once the last stage converged), where advance_state takes it
        if the step is accepted: it reads the state and three stage derivatives once, not twice.

        The velocity's estimate is filtered by the diagonal of (I - gamma*h*J)^-1 (Hairer & Wanner,
        IV.8; Shampine): the pad velocity is stiff and overdamped, and its raw estimate does not
        vanish for modes that the L-stable scheme damps correctly."""
        g = ft(GAMMA) * h
        rtol = ft(s.rtol)
        filter_extra = filter_stiffening(c, s, n, g)
        top = ft(0.0)  # the norm so far, top/bottom (fold_error)
        bottom = ft(1.0)
        for i in range(c.first_node, c.end_node):
            # a node's values all read before its writes (as in prepare_stage)
            y = vec4()
            k1 = vec4()
            k2 = vec4()
            k3 = vec4()
            for comp in range(N_COMPONENTS):
                if comp != C_V or wp.static(inertia):
                    y[comp] = state[comp, i, m]
                    k1[comp] = K[s1, comp, i, m]
                    k2[comp] = K[s2, comp, i, m]
                    k3[comp] = K[s3, comp, i, m]
            for comp in range(N_COMPONENTS):
                if comp != C_V or wp.static(inertia):
                    y_new = y[comp] + solution_increment(h, k1[comp], k2[comp], k3[comp])
                    if comp != C_V:
                        work[comp, i, m] = y_new
                    top, bottom = fold_error(c, step_end, comp, i, m, error_increment(h, k1[comp], k2[comp], k3[comp]),
                                             y[comp], y_new, g, rtol, filter_extra, top, bottom)
        return team_max(quotient(top, bottom))

    @wp.func
    def advance_state(c: Coeffs, m: int, n: int, state: array3, K: array4, work: array3, s3: int, h: ft,
                      backward_euler: int):
        """y_{n+1} = y_n + h * sum_j b_j K_j, which error_norm left in work[comp] (backward Euler: y_n +
        h*K[s3]); the velocity is the last stage's (stiffly accurate, and algebraic without inertia).
        The lane's nodes."""
        for i in range(c.first_node, c.end_node):
            y_new = vec4()  # a node's values all read before its writes (as in prepare_stage)
            for comp in range(N_COMPONENTS):
                if comp == C_V:
                    y_new[comp] = K[s3, C_U, i, m]
                elif backward_euler == 1:
                    y_new[comp] = state[comp, i, m] + h * K[s3, comp, i, m]
                else:
                    y_new[comp] = work[comp, i, m]
            for comp in range(N_COMPONENTS):
                state[comp, i, m] = y_new[comp]

    return dict(prepare_stage=prepare_stage, filter_stiffening=filter_stiffening, fold_error=fold_error,
                error_norm=error_norm, advance_state=advance_state)


def make_step_result(ft, newton, gates):
    """The StepResult struct of an attempted step (any method)."""
    StageSums = newton["StageSums"]
    SwitchTest = gates["SwitchTest"]

    @wp.struct
    class StepResult:
        """An attempted step: converged (1) or not, its error norm (1 = the tolerance; 0 for a
        backward-Euler step), Newton iterations, non-finite (1), the plate's delta0 (m) and tilt
        (rad) at its end, the integrals of its last stage and its gate-switch test."""

        ok: wp.int32
        error: wp.float64
        iterations: wp.int32
        non_finite: wp.int32
        delta0: ft
        tilt: ft
        newton_curvature: ft  # the Newton curvature its last stage ended with (0: not known)
        sums: StageSums
        switch_test: SwitchTest

    return StepResult


def make_tr_bdf2_steps(ft, terms, newton, StepResult, arrays):
    """The attempted steps: backward Euler (a (re)start) and TR-BDF2, each stage solved by Newton
    (kernels/newton.py)."""
    Coeffs = terms["Coeffs"]
    newton_solve = newton["newton_solve"]
    stage_derivatives = newton["stage_derivatives"]
    prepare_stage = arrays["prepare_stage"]
    error_norm = arrays["error_norm"]
    array3 = wp.array3d(dtype=ft)
    array4 = wp.array4d(dtype=ft)

    @wp.func
    def implicit_step(
        c: Coeffs, p: MemberParams, settings: SolverSettings, m: int, n: int, state: array3, K: array4,
        work: array3, gates: array3, step_end: array3, s1: int, s2: int, s3: int, t: wp.float64, h: wp.float64,
        t_new: wp.float64, delta0: ft, tilt: ft, backward_euler: int, newton_curvature: ft,
    ):
        """One step of size h from t (ending at t_new). TR-BDF2 (backward_euler = 0): stage 2
        (trapezoidal, at t + 2 gamma h) into K[s2], stage 3 (BDF2, at t_new) into K[s3], and the
        error norm; backward Euler (non-zero, a (re)start): one stage at t_new into K[s3], no error
        estimate. newton_curvature: the Newton curvature of the step before (kernels/newton.py
        newton_solve; 0: not known), carried from stage to stage and returned in the result. The
        stages are one loop with a bound known only at run time, so that the code of
        a stage (the Newton solve above all) is compiled once, not once per stage: on a GPU several
        inlined copies overflow the instruction cache when the warps of an SM are in different
        stages (docs/performance.md, "GPU: where the time goes")."""
        res = StepResult()
        res.error = wp.float64(0.0)
        g = ft(wp.float64(GAMMA) * h)
        n_stages = 2
        if backward_euler != 0:
            g = ft(h)
            n_stages = 1
        ok = int(1)
        bad = int(0)
        iterations = int(0)
        d0 = delta0
        a = tilt
        curvature = newton_curvature
        if backward_euler != 0:
            curvature = ft(0.0)  # another stage matrix (g = h): not carried
        for stage in range(n_stages):
            last = stage == n_stages - 1
            t_stage = t_new
            slot = s3
            if backward_euler != 0:
                prepare_stage(c, m, n, state, K, work, ft(h), ft(0.0), s1, ft(0.0), s1, 0, ft(0.0))
            elif stage == 0:
                t_stage = t + wp.float64(C2) * h
                slot = s2
                prepare_stage(c, m, n, state, K, work, ft(h), ft(GAMMA), s1, ft(0.0), s1, 1, ft(0.0))
            else:
                prepare_stage(c, m, n, state, K, work, ft(h), ft(W_TRB), s1, ft(W_TRB), s2, 2, ft(EXTRAPOLATE_STAGE3))
            ok, d0, a, iters, bad, curvature = newton_solve(c, p, settings, m, n, work, gates, step_end, g, t_stage, t,
                                                            d0, a, curvature)
            iterations = iterations + iters
            if ok != 1:
                break
            end_of_step = int(0)
            if last:
                end_of_step = 1
            sums, test = stage_derivatives(c, p, settings, m, n, work, gates, step_end, K, slot, g, t_stage, t, d0, a, ft(h),
                                           end_of_step)
            if last:
                res.sums = sums
                res.switch_test = test
        if ok == 1 and backward_euler == 0:  # TR-BDF2 only: backward Euler has no error estimate
            res.error = wp.float64(error_norm(c, settings, m, n, state, K, step_end, work, s1, s2, s3, ft(h)))
        res.ok = ok
        res.iterations = iterations
        res.non_finite = bad
        res.delta0 = d0
        res.tilt = a
        res.newton_curvature = curvature
        return res

    return dict(implicit_step=implicit_step)


def make_esdirk(ft, model, terms, newton, gates, team, method="tr_bdf2"):
    """The steppers for one working precision and model: TR-BDF2 and backward Euler, and with
    method = 'esdirk4' ESDIRK4's step (make_esdirk4)."""
    tableau = make_tableau(ft)
    arrays = make_tr_bdf2_arrays(ft, model, terms, team, tableau)
    StepResult = make_step_result(ft, newton, gates)
    steps = make_tr_bdf2_steps(ft, terms, newton, StepResult, arrays)
    out = dict(StepResult=StepResult, prepare_stage=arrays["prepare_stage"], error_norm=arrays["error_norm"],
               advance_state=arrays["advance_state"], implicit_step=steps["implicit_step"], **tableau)
    if method == "esdirk4":
        out.update(make_esdirk4(ft, model, terms, newton, gates, team, StepResult, arrays["filter_stiffening"],
                                arrays["fold_error"]))
    return out


def make_esdirk4_arrays(ft, model, terms, team, filter_stiffening, fold_error):
    """ESDIRK4's tableau applied to every node and component of a member: the stage constants and
    Newton start (prepare_stage4), the error norm (error_norm4) and the solution update
    (advance_state4); e4_row and e4_abscissa read the tableau."""
    inertia = bool(model.inertia)
    team_max = team["team_max"]
    barrier = team["barrier"]
    Coeffs = terms["Coeffs"]
    array3 = wp.array3d(dtype=ft)
    array4 = wp.array4d(dtype=ft)
    vec6 = wp.types.vector(length=6, dtype=ft)

    @wp.func
    def e4_row(i: int):
        """Row i (1..5) of A, the explicit part (columns 0..i-1; 0 beyond)."""
        if i == 1:
            return vec6(ft(E4_A10), ft(0.0), ft(0.0), ft(0.0), ft(0.0), ft(0.0))
        if i == 2:
            return vec6(ft(E4_A20), ft(E4_A21), ft(0.0), ft(0.0), ft(0.0), ft(0.0))
        if i == 3:
            return vec6(ft(E4_A30), ft(E4_A31), ft(E4_A32), ft(0.0), ft(0.0), ft(0.0))
        if i == 4:
            return vec6(ft(E4_A40), ft(E4_A41), ft(E4_A42), ft(E4_A43), ft(0.0), ft(0.0))
        return vec6(ft(E4_B0), ft(E4_B1), ft(E4_B2), ft(E4_B3), ft(E4_B4), ft(0.0))

    @wp.func
    def e4_abscissa(i: int):
        """c_i of stages 1..4 (stage 5 ends the step: t_new itself)."""
        if i == 1:
            return wp.float64(E4_C1)
        if i == 2:
            return wp.float64(E4_C2)
        if i == 3:
            return wp.float64(E4_C3)
        return wp.float64(E4_C4)

    @wp.func
    def prepare_stage4(c: Coeffs, m: int, n: int, state: array3, K: array4, work: array3, h: ft, s1: int, i: int):
        """Stage constants z = y_n + h*sum_{j<i} a_ij K_j into work[0..3]; Newton start for V: the
        previous stage's velocity (Y0 = z + gamma*h*K_{i-1})."""
        row = e4_row(i)
        for node in range(c.first_node, c.end_node):
            for comp in range(N_COMPONENTS):
                z = state[comp, node, m]
                for j in range(i):
                    z += h * row[j] * K[(s1 + j) % 6, comp, node, m]
                work[comp, node, m] = z
            work[W_V, node, m] = K[(s1 + i - 1) % 6, C_U, node, m]
        barrier()

    @wp.func
    def error_norm4(c: Coeffs, s: SolverSettings, m: int, n: int, state: array3, K: array4, step_end: array3, s1: int,
                    h: ft):
        """As error_norm (max norm, natural scales, the velocity's estimate filtered by the diagonal of
        (I - gamma*h*J)^-1) with h*sum (b - b_hat) K over the six stages."""
        g = ft(E4_GAMMA) * h
        rtol = ft(s.rtol)
        filter_extra = filter_stiffening(c, s, n, g)
        b = vec6(ft(E4_B0), ft(E4_B1), ft(E4_B2), ft(E4_B3), ft(E4_B4), ft(E4_B5))
        d = vec6(ft(E4_D0), ft(E4_D1), ft(E4_D2), ft(E4_D3), ft(E4_D4), ft(E4_D5))
        top = ft(0.0)  # the norm so far, top/bottom (fold_error)
        bottom = ft(1.0)
        for i in range(c.first_node, c.end_node):
            for comp in range(N_COMPONENTS):
                if comp != C_V or wp.static(inertia):
                    inc = ft(0.0)
                    e = ft(0.0)
                    for j in range(6):
                        k = K[(s1 + j) % 6, comp, i, m]
                        inc += b[j] * k
                        e += d[j] * k
                    y = state[comp, i, m]
                    top, bottom = fold_error(c, step_end, comp, i, m, h * e, y, y + h * inc, g, rtol, filter_extra, top, bottom)
        return team_max(quotient(top, bottom))

    @wp.func
    def advance_state4(c: Coeffs, m: int, n: int, state: array3, K: array4, s1: int, h: ft):
        """y_{n+1} = y_n + h * sum_j b_j K_j; the velocity is the last stage's (stiffly accurate)."""
        b = vec6(ft(E4_B0), ft(E4_B1), ft(E4_B2), ft(E4_B3), ft(E4_B4), ft(E4_B5))
        for i in range(c.first_node, c.end_node):
            for comp in range(N_COMPONENTS):
                if comp == C_V:
                    state[comp, i, m] = K[(s1 + 5) % 6, C_U, i, m]
                else:
                    inc = ft(0.0)
                    for j in range(6):
                        inc += b[j] * K[(s1 + j) % 6, comp, i, m]
                    state[comp, i, m] = state[comp, i, m] + h * inc

    return dict(e4_abscissa=e4_abscissa, prepare_stage4=prepare_stage4, error_norm4=error_norm4,
                advance_state4=advance_state4)


def make_esdirk4(ft, model, terms, newton, gates, team, StepResult, filter_stiffening, fold_error):
    """ESDIRK4(3)6L[2]SA's step (Solver.method = 'esdirk4'): the stages in six slots of K, the slot
    of stage j being (s1 + j) % 6 (s1 = FSAL slot: f(y_n)); the last stage's slot becomes the next
    step's s1."""
    Coeffs = terms["Coeffs"]
    newton_solve = newton["newton_solve"]
    stage_derivatives = newton["stage_derivatives"]
    arrays = make_esdirk4_arrays(ft, model, terms, team, filter_stiffening, fold_error)
    e4_abscissa = arrays["e4_abscissa"]
    prepare_stage4 = arrays["prepare_stage4"]
    error_norm4 = arrays["error_norm4"]
    array3 = wp.array3d(dtype=ft)
    array4 = wp.array4d(dtype=ft)

    @wp.func
    def esdirk4_step(
        c: Coeffs, p: MemberParams, settings: SolverSettings, m: int, n: int, state: array3, K: array4,
        work: array3, gates: array3, step_end: array3, s1: int, t: wp.float64, h: wp.float64, t_new: wp.float64,
        delta0: ft, tilt: ft,
    ):
        """One ESDIRK4 step of size h from t (ending at t_new): stages 1..5 (implicit, gamma = 1/4)
        into K[(s1 + i) % 6], the gate-switch test at the end of the last one, and the error norm."""
        res = StepResult()
        res.error = wp.float64(0.0)
        g = ft(wp.float64(E4_GAMMA) * h)
        hf = ft(h)
        d0 = delta0
        a = tilt
        ok = int(1)
        bad = int(0)
        iterations = int(0)
        for i in range(1, 6):
            t_stage = t_new
            end = int(1)
            if i < 5:
                t_stage = t + e4_abscissa(i) * h
                end = 0
            prepare_stage4(c, m, n, state, K, work, hf, s1, i)
            ok, d0, a, iters, bad, _curvature = newton_solve(c, p, settings, m, n, work, gates, step_end, g, t_stage, t,
                                                             d0, a, ft(0.0))
            iterations = iterations + iters
            if ok != 1:
                break
            sums, test = stage_derivatives(c, p, settings, m, n, work, gates, step_end, K, (s1 + i) % 6, g, t_stage, t, d0,
                                           a, hf, end)
            if end == 1:
                res.sums = sums
                res.switch_test = test
        if ok == 1:
            res.error = wp.float64(error_norm4(c, settings, m, n, state, K, step_end, s1, hf))
        res.ok = ok
        res.iterations = iterations
        res.non_finite = bad
        res.delta0 = d0
        res.tilt = a
        return res

    return dict(esdirk4_step=esdirk4_step, advance_state4=arrays["advance_state4"], error_norm4=error_norm4,
                prepare_stage4=prepare_stage4)
