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

``make_esdirk(ft, model, terms, newton, gates)`` builds the functions for one working precision and model.
"""

import math

import warp as wp

from .types import C_PHI, C_TAU, C_U, C_V, N_COMPONENTS, W_DIAG, W_V, MemberParams, SolverSettings

GAMMA = 1.0 - math.sqrt(2.0) / 2.0
W_TRB = math.sqrt(2.0) / 4.0
C2 = 2.0 * GAMMA
B_HAT = ((1.0 - W_TRB) / 3.0, (3.0 * W_TRB + 1.0) / 3.0, GAMMA / 3.0)
ERR1, ERR2, ERR3 = W_TRB - B_HAT[0], W_TRB - B_HAT[1], GAMMA - B_HAT[2]
EXTRAPOLATE_STAGE3 = 1.0 / C2  # linear extrapolation of V from t_n and t_n + c2*h to t_n + h
ORDER = 2  # of the solution; the error estimate is O(h^3)


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


def make_esdirk(ft, model, terms, newton, gates, team):
    inertia = bool(model.inertia)
    team_max = team["team_max"]
    barrier = team["barrier"]
    Coeffs = terms["Coeffs"]
    StageSums = newton["StageSums"]
    SwitchTest = gates["SwitchTest"]
    newton_solve = newton["newton_solve"]
    stage_derivatives = newton["stage_derivatives"]
    tableau = make_tableau(ft)
    stage_constant = tableau["stage_constant"]
    solution_increment = tableau["solution_increment"]
    error_increment = tableau["error_increment"]
    array3 = wp.array3d(dtype=ft)
    array4 = wp.array4d(dtype=ft)

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
        sums: StageSums
        switch_test: SwitchTest

    @wp.func
    def prepare_stage(
        c: Coeffs, m: int, n: int, state: array3, K: array4, work: array3,
        h: ft, a1: ft, s1: int, a2: ft, s2: int, n_terms: int, extrapolate: ft,
    ):
        """Stage constants z = y_n + h*(a1*K[s1] + a2*K[s2]) (first n_terms terms) into work[0..3] and
        the Newton start for V into work[W_V]: v_n + extrapolate*(V(stage s2) - v_n). (The lane's
        nodes; the Newton solve that follows reads its neighbours' halo nodes: a barrier.)"""
        for i in range(c.first_node, c.end_node):
            for comp in range(N_COMPONENTS):
                work[comp, i, m] = stage_constant(state[comp, i, m], h, a1, K[s1, comp, i, m], a2, K[s2, comp, i, m], n_terms)
            v = state[C_V, i, m]
            guess = v
            if n_terms >= 2:
                guess = v + extrapolate * (K[s2, C_U, i, m] - v)
            work[W_V, i, m] = guess
        barrier()

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
        for i in range(c.first_node, c.end_node):
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
                    y_new = y + solution_increment(h, k1, k2, k3)
                    e = error_increment(h, k1, k2, k3)
                    if comp == C_V:
                        e = e * wp.min(ft(1.0), wp.abs(c.rhoH / (g * work[W_DIAG, i, m])))
                    wgt = rtol * (scale + wp.max(wp.abs(y), wp.abs(y_new)))
                    err = wp.max(err, wp.abs(e) / wgt)
                    if not wp.isfinite(e):
                        err = ft(1.0e30)
        return team_max(err)

    @wp.func
    def advance_state(c: Coeffs, m: int, n: int, state: array3, K: array4, s1: int, s2: int, s3: int, h: ft,
                      backward_euler: int):
        """y_{n+1} = y_n + h * sum_j b_j K_j (backward Euler: y_n + h*K[s3]); the velocity is the last
        stage's (stiffly accurate, and algebraic without inertia). The lane's nodes."""
        for i in range(c.first_node, c.end_node):
            for comp in range(N_COMPONENTS):
                if comp == C_V:
                    state[comp, i, m] = K[s3, C_U, i, m]
                else:
                    k3 = K[s3, comp, i, m]
                    if backward_euler == 1:
                        state[comp, i, m] = state[comp, i, m] + h * k3
                    else:
                        state[comp, i, m] = state[comp, i, m] + solution_increment(h, K[s1, comp, i, m], K[s2, comp, i, m], k3)

    @wp.func
    def backward_euler_step(
        c: Coeffs, p: MemberParams, settings: SolverSettings, m: int, n: int, state: array3, K: array4,
        work: array3, gates: array3, s1: int, s3: int, t: wp.float64, h: wp.float64, t_new: wp.float64,
        delta0: ft, tilt: ft,
    ):
        """One backward-Euler stage of size h from t (ending at t_new; its derivatives into K[s3]); no
        error estimate."""
        res = StepResult()
        res.error = wp.float64(0.0)
        g = ft(h)
        prepare_stage(c, m, n, state, K, work, ft(h), ft(0.0), s1, ft(0.0), s1, 0, ft(0.0))
        ok, d0, a, iters, bad = newton_solve(c, p, settings, m, n, work, gates, g, t_new, t, delta0, tilt)
        res.ok = ok
        res.iterations = iters
        res.non_finite = bad
        res.delta0 = d0
        res.tilt = a
        if ok == 1:
            sums, test = stage_derivatives(c, p, settings, m, n, work, gates, K, s3, g, t_new, t, d0, a, ft(h), 1)
            res.sums = sums
            res.switch_test = test
        return res

    @wp.func
    def tr_bdf2_step(
        c: Coeffs, p: MemberParams, settings: SolverSettings, m: int, n: int, state: array3, K: array4,
        work: array3, gates: array3, s1: int, s2: int, s3: int, t: wp.float64, h: wp.float64,
        t_new: wp.float64, delta0: ft, tilt: ft,
    ):
        """One TR-BDF2 step of size h from t (ending at t_new): stage 2 (trapezoidal, at t + 2 gamma h)
        into K[s2], stage 3 (BDF2, at t_new) into K[s3], and the error norm."""
        res = StepResult()
        res.error = wp.float64(0.0)
        g = ft(wp.float64(GAMMA) * h)
        prepare_stage(c, m, n, state, K, work, ft(h), ft(GAMMA), s1, ft(0.0), s1, 1, ft(0.0))
        ok, d0, a, iters, bad = newton_solve(c, p, settings, m, n, work, gates, g, t + wp.float64(C2) * h, t, delta0, tilt)
        iterations = iters
        if ok == 1:
            stage_derivatives(c, p, settings, m, n, work, gates, K, s2, g, t + wp.float64(C2) * h, t, d0, a, ft(h), 0)
            prepare_stage(c, m, n, state, K, work, ft(h), ft(W_TRB), s1, ft(W_TRB), s2, 2, ft(EXTRAPOLATE_STAGE3))
            ok, d0, a, iters, bad = newton_solve(c, p, settings, m, n, work, gates, g, t_new, t, d0, a)
            iterations = iterations + iters
            if ok == 1:
                sums, test = stage_derivatives(c, p, settings, m, n, work, gates, K, s3, g, t_new, t, d0, a, ft(h), 1)
                res.sums = sums
                res.switch_test = test
                res.error = wp.float64(error_norm(c, settings, m, n, state, K, work, s1, s2, s3, ft(h)))
        res.ok = ok
        res.iterations = iterations
        res.non_finite = bad
        res.delta0 = d0
        res.tilt = a
        return res

    return dict(StepResult=StepResult, prepare_stage=prepare_stage, error_norm=error_norm, advance_state=advance_state,
                backward_euler_step=backward_euler_step, tr_bdf2_step=tr_bdf2_step, **tableau)
