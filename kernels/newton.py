"""One implicit stage of the pad model, solved by Newton's method (docs/model.md, "Time integration").

The unknowns are the pad velocity at every node, V_0..V_{N-1}, and the plate's compression delta0
and tilt a. At a given V the stage equations of the contact age and of the elastic friction stress
are linear and are solved in closed form per node (model_terms.interface_friction), so the Newton
matrix is tridiagonal in V, bordered by two columns (delta0, a) and two dense rows (force and moment
balance of the plate):

    [ J  B ] [dV     ]   [-R]        J: tridiagonal (N x N), B: columns B0 (delta0), B1 (a)
    [ C  D ] [dd0, da] = [-E]        C: rows C1 (force), C2 (moment), D: 2 x 2

It is solved with the Thomas algorithm on three right-hand sides, y0 = J^-1 (-R), y1 = J^-1 B0,
y2 = J^-1 B1, and the 2 x 2 Schur complement (D - C y1|y2) (dd0, da) = -E - C y0; then
dV = y0 - y1 dd0 - y2 da: O(N) work and memory per member. ``forward_row``, ``back_substitution``,
``schur_solve`` and ``solution_row`` are that solver alone (tests/test_kernels.py checks them against
numpy.linalg.solve); ``assemble_system`` evaluates each node's row of the system from the model
terms (``node_row``) and eliminates it at once, so that nothing but the Thomas rows is stored;
``newton_solve`` iterates that, the Schur complement and the update. ``stage_derivatives``
evaluates f(Y) of a converged stage.

``make_newton(ft, model, terms, gates, team, method)`` builds the functions for one working precision
and model from one factory per stage: ``make_bordered_solver`` (or ``make_team_solver``, the team's
partitioned solve), ``make_stage_equations`` (the load and each node's row), ``make_newton_system``
(passes 1 and 2 of an iteration), ``make_newton_solve`` (the iteration) and
``make_stage_derivatives`` (the converged stage).
"""

import warp as wp

from .model_terms import (disc_velocity_at, disc_velocity_piece, make_over_den, make_ratio_max, normal_force_in_step,
                          normal_force_piece, quotient)
from .team import vec3d, vec4d, vec5d, vec6d, vec12d
from .types import (
    C_PHI,
    C_TAU,
    C_U,
    C_V,
    E_CONTACT,
    E_DIAG,
    G_GATE_END,
    W_C1,
    W_C2,
    W_CP,
    W_R0,
    W_R1,
    W_R2,
    W_RL,
    W_RR,
    W_V,
    W_ZP,
    W_ZT,
    W_ZU,
    W_ZV,
    MemberParams,
    SolverSettings,
)


def make_bordered_solver(ft, tilt_on: bool):
    """The bordered tridiagonal solve for scalar type ``ft``; without tilt the system has one border
    (delta0) and the third right-hand side is skipped."""
    array3 = wp.array3d(dtype=ft)
    over_den = make_over_den(ft)

    @wp.func
    def forward_row(
        work: array3, i: int, m: int, lower: ft, diagonal: ft, upper: ft, rhs: ft, border_d0: ft, border_tilt: ft,
        cp_prev: ft, r0_prev: ft, r1_prev: ft, r2_prev: ft,
    ):
        """Thomas forward elimination of row i (lower, diagonal, upper of J; rhs = -R_i; the border
        columns B0_i, B1_i): stores the modified upper diagonal and right-hand sides in work[W_CP],
        work[W_R0..R2] and returns them for the next row."""
        den = diagonal - lower * cp_prev
        inv_den = ft(1.0) / den  # float64: one division for the row's quotients (over_den)
        cp = over_den(upper, den, inv_den)
        r0 = over_den(rhs - lower * r0_prev, den, inv_den)
        r1 = over_den(border_d0 - lower * r1_prev, den, inv_den)
        work[W_CP, i, m] = cp
        work[W_R0, i, m] = r0
        work[W_R1, i, m] = r1
        r2 = ft(0.0)
        if wp.static(tilt_on):
            r2 = over_den(border_tilt - lower * r2_prev, den, inv_den)
            work[W_R2, i, m] = r2
        return cp, r0, r1, r2

    @wp.func
    def back_substitution(work: array3, n: int, m: int):
        """Back substitution of the three right-hand sides (y0, y1, y2 overwrite work[W_R0..R2]) and
        the border products C1.y0, C1.y1, C1.y2, C2.y0, C2.y1, C2.y2 (C rows in work[W_C1], work[W_C2])."""
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
        return s10, s11, s12, s20, s21, s22

    @wp.func
    def schur_solve(
        d11: ft, d12: ft, d21: ft, d22: ft, e1: ft, e2: ft, s10: ft, s11: ft, s12: ft, s20: ft, s21: ft, s22: ft,
    ):
        """(dd0, da) from the 2 x 2 Schur complement (D - C y1|y2) (dd0, da) = -E - C y0 (without tilt:
        the 1 x 1 one, da = 0)."""
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
        return d_delta0, d_tilt

    @wp.func
    def solution_row(work: array3, i: int, m: int, d_delta0: ft, d_tilt: ft):
        """dV_i = y0_i - y1_i dd0 - y2_i da."""
        dv = work[W_R0, i, m] - work[W_R1, i, m] * d_delta0
        if wp.static(tilt_on):
            dv -= work[W_R2, i, m] * d_tilt
        return dv

    return dict(forward_row=forward_row, back_substitution=back_substitution, schur_solve=schur_solve,
                solution_row=solution_row)


def make_team_solver(ft, team):
    """The bordered tridiagonal solve split over a member's team (kernels/team.py): lane k's nodes
    [lo, hi) are its interior rows lo..hi-2 and its separator row s = hi-1. Each lane eliminates its
    interior rows with the Thomas algorithm on five right-hand sides: the three of the bordered
    solve and the two coupling columns -a_lo e_lo (to the previous lane's separator E_{k-1}) and
    -c_{hi-2} e_{hi-2} (to its own separator E_k), so that an interior unknown is
    x_i = xP_i + E_{k-1} xL_i + E_k xR_i. Substituted into the separator rows this leaves a P x P
    tridiagonal system in the separators (team.reduced_solve). Every lane owns >= 2 nodes."""
    elimination = make_lane_elimination(ft)
    solve = make_lane_solve(ft, team, elimination["LaneRows"])
    return dict(LaneRows=elimination["LaneRows"], start_rows=elimination["start_rows"], lane_row=elimination["lane_row"],
                team_solve=solve["team_solve"])


def make_lane_elimination(ft):
    """A lane's forward sweep of the team's bordered solve (make_team_solver): its interior rows
    eliminated, its separator row kept (LaneRows, start_rows, lane_row)."""
    array3 = wp.array3d(dtype=ft)

    @wp.struct
    class LaneRows:
        """A lane's forward sweep in progress: the last interior row's modified upper diagonal cp
        and right-hand sides (the three of the bordered solve, r, and the coupling columns, rl and
        rr), and its separator row (lower, diagonal, upper, right-hand sides), kept for the reduced
        system."""

        cp: ft
        r: vec3d
        rl: ft
        rr: ft
        sep_lower: ft
        sep_diagonal: ft
        sep_upper: ft
        sep_rhs: vec3d

    @wp.func
    def start_rows():
        rows = LaneRows()
        rows.cp = ft(0.0)
        rows.rl = ft(0.0)
        rows.rr = ft(0.0)
        rows.sep_lower = ft(0.0)
        rows.sep_diagonal = ft(1.0)
        rows.sep_upper = ft(0.0)
        return rows

    @wp.func
    def interior_forward_row(
        work: array3, i: int, m: int, lower: ft, diagonal: ft, upper: ft, rhs: vec3d, couple_left: ft,
        couple_right: ft, cp_prev: ft, r_prev: vec3d, rl_prev: ft, rr_prev: ft,
    ):
        """Thomas forward elimination of interior row i (rhs: -R_i, B0_i, B1_i; couple_left/right:
        the coupling columns' entries of the row, 0 but at the lane's first and last interior row);
        stores cp and the five modified right-hand sides in work[W_CP, W_R0..R2, W_RL, W_RR]."""
        den = diagonal - lower * cp_prev
        # one reciprocal for the row's six quotients (a team is float64: over_den's float64 form);
        # a zero numerator (cp at the lane's last interior row, rl on lane 0, rr before the lane's
        # last interior row) costs no division at all
        inv_den = ft(1.0) / den
        cp = upper * inv_den
        r = (rhs - lower * r_prev) * inv_den
        rl = (couple_left - lower * rl_prev) * inv_den
        rr = (couple_right - lower * rr_prev) * inv_den
        work[W_CP, i, m] = cp
        work[W_R0, i, m] = r[0]
        work[W_R1, i, m] = r[1]
        work[W_R2, i, m] = r[2]
        work[W_RL, i, m] = rl
        work[W_RR, i, m] = rr
        return cp, r, rl, rr

    @wp.func
    def lane_row(
        rows: LaneRows, work: array3, i: int, m: int, lo: int, hi: int, n: int, lower: ft, diagonal: ft, upper: ft,
        rhs: vec3d,
    ):
        """Row i of the lane's nodes [lo, hi) (lower, diagonal, upper of J; rhs = (-R_i, B0_i, B1_i)):
        the separator row hi-1 is kept (its upper entry dropped at the last node), an interior row
        is eliminated, its couplings to the previous lane's separator (the lane's first row, but in
        lane 0) and to its own separator (row hi-2) moved to the coupling columns."""
        out = rows
        if i == hi - 1:
            out.sep_lower = lower
            out.sep_diagonal = diagonal
            if hi < n:
                out.sep_upper = upper
            out.sep_rhs = rhs
        else:
            couple_left = ft(0.0)
            couple_right = ft(0.0)
            upper_kept = upper
            if i == lo and lo > 0:
                couple_left = -lower
            if i == hi - 2:
                couple_right = -upper
                upper_kept = ft(0.0)
            cp, r, rl, rr = interior_forward_row(work, i, m, lower, diagonal, upper_kept, rhs, couple_left, couple_right,
                                                 rows.cp, rows.r, rows.rl, rows.rr)
            out.cp = cp
            out.r = r
            out.rl = rl
            out.rr = rr
        return out

    return dict(LaneRows=LaneRows, start_rows=start_rows, lane_row=lane_row)


def make_lane_solve(ft, team, LaneRows):
    """A lane's back substitution and the separators' reduced system (make_team_solver): team_solve."""
    array3 = wp.array3d(dtype=ft)
    from_next_lane = team["from_next_lane"]
    reduced_solve = team["reduced_solve"]

    @wp.func
    def interior_back_substitution(work: array3, lo: int, hi: int, m: int):
        """Back substitution of the interior rows lo..hi-2 (five right-hand sides, in place). Returns
        x_lo and x_{hi-2} as (xP0, xP1, xP2, xL, xR); with no interior row (a lane of one node) the
        neighbours of its separator are the separators themselves: x_lo = E_k, x_{s-1} = E_{k-1}."""
        first = vec5d(0.0, 0.0, 0.0, 0.0, 1.0)
        last = vec5d(0.0, 0.0, 0.0, 1.0, 0.0)
        nxt = vec5d()
        for k in range(hi - 1 - lo):
            i = hi - 2 - k
            cp = work[W_CP, i, m]
            y = vec5d(work[W_R0, i, m], work[W_R1, i, m], work[W_R2, i, m], work[W_RL, i, m], work[W_RR, i, m]) - cp * nxt
            work[W_R0, i, m] = y[0]
            work[W_R1, i, m] = y[1]
            work[W_R2, i, m] = y[2]
            work[W_RL, i, m] = y[3]
            work[W_RR, i, m] = y[4]
            if k == 0:
                last = y
            first = y
            nxt = y
        return first, last

    @wp.func
    def team_solve(work: array3, lo: int, hi: int, m: int, lane: int, rows: LaneRows):
        """The lane's part of the bordered solve after its rows went through lane_row: exchange
        x_lo with the previous lane, solve for the separators, write y0, y1, y2 of the lane's nodes
        into work[W_R0..R2] and return the border products (C1.y0, C1.y1, C1.y2, C2.y0, C2.y1, C2.y2)
        over the lane's nodes."""
        first, last = interior_back_substitution(work, lo, hi, m)
        nxt = from_next_lane(first, lane)  # x_{s+1} of the next lane's first node (0 for the last)
        a = rows.sep_lower
        c = rows.sep_upper
        row = vec6d(
            a * last[3],
            rows.sep_diagonal + a * last[4] + c * nxt[3],
            c * nxt[4],
            rows.sep_rhs[0] - a * last[0] - c * nxt[0],
            rows.sep_rhs[1] - a * last[1] - c * nxt[1],
            rows.sep_rhs[2] - a * last[2] - c * nxt[2],
        )
        e_prev, e_self = reduced_solve(row, lane)
        sums = vec6d()
        for i in range(lo, hi):
            y = e_self
            if i < hi - 1:
                y = vec3d(work[W_R0, i, m], work[W_R1, i, m], work[W_R2, i, m])
                y = y + work[W_RL, i, m] * e_prev + work[W_RR, i, m] * e_self
            work[W_R0, i, m] = y[0]
            work[W_R1, i, m] = y[1]
            work[W_R2, i, m] = y[2]
            c1 = work[W_C1, i, m]
            c2 = work[W_C2, i, m]
            sums = sums + vec6d(c1 * y[0], c1 * y[1], c1 * y[2], c2 * y[0], c2 * y[1], c2 * y[2])
        return sums

    return dict(team_solve=team_solve)


def make_stage_equations(ft, model, terms, gates, method="tr_bdf2"):
    """The stage equations at one node, for the Newton solve and the converged stage: the load at a
    stage time, the stage displacement and each node's row of the Newton system (node_row)."""
    # the load at a stage time: ESDIRK4 has a stage past the step's end (c = 26/25), evaluated on the
    # smooth continuation of the step's protocol piece; TR-BDF2's stages lie inside the step
    continued = method != "tr_bdf2"
    disc_velocity_stage = disc_velocity_piece if continued else disc_velocity_at
    normal_force_stage = normal_force_piece if continued else normal_force_in_step
    inertia = bool(model.inertia)
    Coeffs = terms["Coeffs"]
    node_weight = terms["node_weight"]
    node_moment_weight = terms["node_moment_weight"]
    elastic_force = terms["elastic_force"]
    contact_terms = terms["contact_terms"]
    node_gate = gates["node_gate"]
    node_sliding = gates["node_sliding"]
    array3 = wp.array3d(dtype=ft)

    @wp.struct
    class NodeRow:
        """Node i's part of the Newton system of a stage: the pad's residual R_i (Pa) and its row of
        J (d R_i/d V_{i-1}, V_i, V_{i+1}, Pa s/m) and of the border columns B0 (d R_i/d delta0, Pa/m)
        and B1 (d R_i/d a, Pa), and what the node adds to the plate's balance rows (per unit
        depth): to the force and moment residuals E1 (N/m), E2 (N), to the D block (d11 =
        dE1/d delta0, d12 = dE1/da, d21 = dE2/d delta0, d22 = dE2/da) and to the C rows' entries
        at V_{i-1}, V_i, V_{i+1}."""

        residual: ft
        jac_left: ft
        jac_center: ft
        jac_right: ft
        col_delta0: ft
        col_tilt: ft
        e1: ft
        e2: ft
        d11: ft
        d12: ft
        d21: ft
        d22: ft
        c1_left: ft
        c1_center: ft
        c1_right: ft
        c2_left: ft
        c2_center: ft
        c2_right: ft
        kink: ft  # 1: the node sits at a kink of the stage equations (lifted off, sliding on the yield surface, or its slip changed sign in the stage), else 0

    @wp.func
    def stage_displacement(work: array3, i: int, n: int, m: int, g: ft):
        """u_i of the stage: z_u + g*V_i (0 beyond the last node)."""
        if i >= n:
            return ft(0.0)
        return work[W_ZU, i, m] + g * work[W_V, i, m]

    @wp.func
    def node_row(
        c: Coeffs, settings: SolverSettings, m: int, n: int, work: array3, gates: array3, i: int, u_l: ft,
        u_c: ft, u_r: ft, delta0: ft, tilt: ft, v_disc: ft, g: ft,
    ):
        """Node i's NodeRow at the stage's current V (work[W_V]), displacements u_{i-1}, u_i, u_{i+1}
        (m) and plate state delta0 (m), tilt (rad); g = gamma*h (s)."""
        vel = work[W_V, i, m]
        ns, fr = contact_terms(c, i, n, u_l, u_c, u_r, delta0, tilt, vel, v_disc, work[W_ZT, i, m],
                               work[W_ZP, i, m], g, node_gate(gates, i, m), node_sliding(gates, i, m),
                               ft(settings.sliding_width))
        sigma = ns.value
        ef = elastic_force(c, i, n, u_l, u_c, u_r, delta0, tilt)
        row = NodeRow()
        residual = -(ef.value + fr.stress - c.damping * vel)
        jac_c = -g * (ef.d_u_center + fr.d_normal * ns.d_u_center) + c.kif * fr.d_slip + c.damping
        if wp.static(inertia):
            if wp.static(ft == wp.float64):  # one quotient, the same for every node (the compiler may hoist it)
                rhoH_over_g = c.rhoH / g
                residual += rhoH_over_g * (vel - work[W_ZV, i, m])
                jac_c += rhoH_over_g
            else:
                residual += c.rhoH * (vel - work[W_ZV, i, m]) / g
                jac_c += c.rhoH / g
        row.residual = residual
        row.jac_center = jac_c
        row.jac_left = -g * (ef.d_u_left + fr.d_normal * ns.d_u_left)
        row.jac_right = -g * (ef.d_u_right + fr.d_normal * ns.d_u_right)
        row.col_delta0 = -(ef.d_delta0 + fr.d_normal * ns.d_delta0)
        row.col_tilt = -(ef.d_tilt + fr.d_normal * ns.d_tilt)
        # plate balance rows: force (1) and moment (2), per unit depth
        wgt = node_weight(c, i, n)
        wmom = node_moment_weight(c, i, n)
        row.e1 = wgt * fr.contact * sigma
        row.e2 = wmom * fr.contact * sigma + c.h_arm * wgt * fr.stress
        row.d11 = wgt * fr.contact * ns.d_delta0
        row.d12 = wgt * fr.contact * ns.d_tilt
        row.d21 = (wmom * fr.contact + c.h_arm * wgt * fr.d_normal) * ns.d_delta0
        row.d22 = (wmom * fr.contact + c.h_arm * wgt * fr.d_normal) * ns.d_tilt
        q1 = wgt * fr.contact * g
        q2 = (wmom * fr.contact + c.h_arm * wgt * fr.d_normal) * g
        row.c1_left = q1 * ns.d_u_left
        row.c1_center = q1 * ns.d_u_center
        row.c1_right = q1 * ns.d_u_right
        row.c2_left = q2 * ns.d_u_left
        row.c2_center = q2 * ns.d_u_center - c.h_arm * wgt * c.kif * fr.d_slip
        row.c2_right = q2 * ns.d_u_right
        # where Newton's contraction is no guide (kernels/newton.py newton_solve): a kink of the
        # equations, i.e. a lifted-off node, a node sliding on the yield surface, or a slip that
        # changed sign against the stage constant's (|s| in the relaxation, sign(s) in the viscous term)
        slip = v_disc - c.kif * vel
        slip_start = v_disc - c.kif * work[W_ZV, i, m]
        row.kink = ft(0.0)
        if sigma <= ft(0.0) or node_sliding(gates, i, m) > ft(0.0) or slip * slip_start <= ft(0.0):
            row.kink = ft(1.0)
        return row

    return dict(NodeRow=NodeRow, disc_velocity_stage=disc_velocity_stage, normal_force_stage=normal_force_stage,
                stage_displacement=stage_displacement, node_row=node_row)


def make_bordered_system(ft):
    """BorderedSystem: what the Schur complement of a Newton iteration needs."""

    @wp.struct
    class BorderedSystem:
        """The plate rows of a Newton iteration after the elimination of J, summed over the pad:
        the force and moment residuals E1 (N/m), E2 (N), the D block d11 = dE1/d delta0,
        d12 = dE1/da, d21 = dE2/d delta0, d22 = dE2/da, and the border products
        s10, s11, s12 = C1.y0, C1.y1, C1.y2 and s20, s21, s22 = C2.y0, C2.y1, C2.y2."""

        e1: ft
        e2: ft
        d11: ft
        d12: ft
        d21: ft
        d22: ft
        s10: ft
        s11: ft
        s12: ft
        s20: ft
        s21: ft
        s22: ft
        kink: ft  # 1: a node of this thread sits at a kink (NodeRow.kink); not summed over a team

    @wp.func
    def bordered_system(e1: ft, e2: ft, d11: ft, d12: ft, d21: ft, d22: ft, s10: ft, s11: ft, s12: ft, s20: ft,
                        s21: ft, s22: ft, kink: ft):
        out = BorderedSystem()
        out.kink = kink
        out.e1 = e1
        out.e2 = e2
        out.d11 = d11
        out.d12 = d12
        out.d21 = d21
        out.d22 = d22
        out.s10 = s10
        out.s11 = s11
        out.s12 = s12
        out.s20 = s20
        out.s21 = s21
        out.s22 = s22
        return out

    return dict(BorderedSystem=BorderedSystem, bordered_system=bordered_system)


def make_newton_system(ft, model, terms, team, equations, solver, team_solver):
    """assemble_system: the first two passes of a Newton iteration (one thread's Thomas solve, or a
    lane's part of the team's partitioned solve)."""
    inertia = bool(model.inertia)
    Coeffs = terms["Coeffs"]
    team_on = team["lanes"] > 1
    team_sum_vec12 = team.get("team_sum_vec12", None)
    from_neighbour_lanes = team.get("from_neighbour_lanes", None)
    start_rows = team_solver.get("start_rows", None)
    lane_row = team_solver.get("lane_row", None)
    team_solve = team_solver.get("team_solve", None)
    forward_row = solver["forward_row"]
    back_substitution = solver["back_substitution"]
    stage_displacement = equations["stage_displacement"]
    node_row = equations["node_row"]
    bordered_system = make_bordered_system(ft)["bordered_system"]
    array3 = wp.array3d(dtype=ft)

    @wp.func
    def assemble_system(
        c: Coeffs, settings: SolverSettings, m: int, n: int, work: array3, gates: array3, step_end: array3, g: ft,
        delta0: ft, tilt: ft, v_disc: ft, force_per_depth: ft, moment_per_depth: ft,
    ):
        """Pass 1 (the residuals and Jacobian rows of the nodes, node_row, and the forward elimination
        of J on three right-hand sides: -R, B0, B1) and pass 2 (back substitution and the border
        products) of a Newton iteration at the stage's current V, delta0 (m) and tilt
        (rad), under the load force_per_depth (N/m) and moment_per_depth (N). Returns the
        BorderedSystem; y0, y1, y2 are left in work[W_R0..R2]."""
        e1 = -force_per_depth  # force balance residual E1 (N/m)
        e2 = -moment_per_depth  # moment balance residual E2 (N)
        if wp.static(team_on):  # a lane sums its nodes; the load enters once, after the team sum
            e1 = ft(0.0)
            e2 = ft(0.0)
        d11 = ft(0.0)
        d12 = ft(0.0)
        d21 = ft(0.0)
        d22 = ft(0.0)
        kink = ft(0.0)
        # the border rows C1, C2 get three contributions per node (i-1, i, i+1): a row entry is
        # complete one node later
        c1_prev = ft(0.0)
        c1_cur = ft(0.0)
        c2_prev = ft(0.0)
        c2_cur = ft(0.0)
        cp_prev = ft(0.0)
        r0_prev = ft(0.0)
        r1_prev = ft(0.0)
        r2_prev = ft(0.0)
        # a lane of a team evaluates its own nodes [lo, hi) only: the entries its first and last
        # node give the border rows C1, C2 of the neighbouring lanes' nodes lo-1 and hi are
        # exchanged after the sweep (from_neighbour_lanes)
        lo = c.first_node
        hi = c.end_node
        to_previous_c1 = ft(0.0)
        to_previous_c2 = ft(0.0)
        if wp.static(team_on):
            rows = start_rows()
        u_l = ft(0.0)
        if lo > 0:
            u_l = stage_displacement(work, lo - 1, n, m, g)
        u_c = stage_displacement(work, lo, n, m, g)
        for i in range(lo, hi):
            u_r = stage_displacement(work, i + 1, n, m, g)
            row = node_row(c, settings, m, n, work, gates, i, u_l, u_c, u_r, delta0, tilt, v_disc, g)
            if wp.static(inertia):
                step_end[E_DIAG, i, m] = row.jac_center
            kink = wp.max(kink, row.kink)
            e1 += row.e1
            e2 += row.e2
            d11 += row.d11
            d12 += row.d12
            d21 += row.d21
            d22 += row.d22
            c1_prev += row.c1_left
            c1_cur += row.c1_center
            c2_prev += row.c2_left
            c2_cur += row.c2_center
            if i > lo:
                work[W_C1, i - 1, m] = c1_prev
                work[W_C2, i - 1, m] = c2_prev
            else:
                to_previous_c1 = row.c1_left
                to_previous_c2 = row.c2_left
            c1_prev = c1_cur
            c1_cur = row.c1_right
            c2_prev = c2_cur
            c2_cur = row.c2_right
            if wp.static(team_on):
                rows = lane_row(rows, work, i, m, lo, hi, n, row.jac_left, row.jac_center, row.jac_right,
                                vec3d(-row.residual, row.col_delta0, row.col_tilt))
            else:
                cp_prev, r0_prev, r1_prev, r2_prev = forward_row(
                    work, i, m, row.jac_left, row.jac_center, row.jac_right, -row.residual, row.col_delta0,
                    row.col_tilt, cp_prev, r0_prev, r1_prev, r2_prev
                )
            u_l = u_c
            u_c = u_r
        work[W_C1, hi - 1, m] = c1_prev
        work[W_C2, hi - 1, m] = c2_prev
        # ---- pass 2 ----
        if wp.static(team_on):  # a lane's y0, y1, y2 and products; the team's sums
            # the border-row entries of the lane's end nodes from its neighbours' end nodes
            from_prev, from_next = from_neighbour_lanes(
                vec4d(to_previous_c1, to_previous_c2, c1_cur, c2_cur), c.lane)
            work[W_C1, lo, m] = work[W_C1, lo, m] + from_prev[2]
            work[W_C2, lo, m] = work[W_C2, lo, m] + from_prev[3]
            work[W_C1, hi - 1, m] = work[W_C1, hi - 1, m] + from_next[0]
            work[W_C2, hi - 1, m] = work[W_C2, hi - 1, m] + from_next[1]
            products = team_solve(work, lo, hi, m, c.lane, rows)
            total = team_sum_vec12(vec12d(e1, e2, d11, d12, d21, d22, products[0], products[1], products[2],
                                          products[3], products[4], products[5]))
            return bordered_system(total[0] - force_per_depth, total[1] - moment_per_depth, total[2], total[3],
                                   total[4], total[5], total[6], total[7], total[8], total[9], total[10], total[11],
                                   kink)
        else:
            s10, s11, s12, s20, s21, s22 = back_substitution(work, n, m)
            return bordered_system(e1, e2, d11, d12, d21, d22, s10, s11, s12, s20, s21, s22, kink)

    return dict(assemble_system=assemble_system)


# the error a Newton iteration may leave, estimated from its contraction, as a fraction of
# Solver.newton_tol: the update test (norm <= newton_tol) leaves about a tenth of it with Newton's
# usual contraction; as loose as the test itself, the velocity's noise made the velocity front's
# time-error estimate 4x larger (docs/performance.md, "Newton iterations")
NEWTON_ERROR_FRACTION = 0.1
# without inertia: the largest error-weighted velocity update that newton_solve accepts as the force
# balance's round-off level (its stall test; seen at 1.0-4.7 in steps of ~1e-10 s at rtol 1e-8)
STALLED_VELOCITY_ERROR = 100.0


def make_newton_solve(ft, model, terms, team, equations, solver, system):
    """newton_solve: one implicit stage by Newton's method on the bordered system."""
    inertia = bool(model.inertia)
    Coeffs = terms["Coeffs"]
    team_on = team["lanes"] > 1
    team_max = team["team_max"]
    schur_solve = solver["schur_solve"]
    solution_row = solver["solution_row"]
    disc_velocity_stage = equations["disc_velocity_stage"]
    normal_force_stage = equations["normal_force_stage"]
    assemble_system = system["assemble_system"]
    array3 = wp.array3d(dtype=ft)
    ratio_max = make_ratio_max(ft)

    @wp.func
    def update_velocity(c: Coeffs, work: array3, lo: int, hi: int, m: int, g: ft, rtol: ft, d_delta0: ft, d_tilt: ft):
        """Apply the Newton update dV of nodes [lo, hi) to work[W_V]; returns the error-weighted norm
        of dV and of the displacement's g*dV, the norm of what dV moves in the stage's states
        (without inertia: the displacement's g*dV and, bounded with a contact area of 1, the elastic
        stress's g*Kh*dV; with inertia, where V is a state, the norm itself), and whether every
        update (with d_delta0, d_tilt) is finite."""
        top = ft(0.0)  # the norm so far, top/bottom (ratio_max: one division for the sweep)
        bottom = ft(1.0)
        state_top = ft(0.0)
        state_bottom = ft(1.0)
        finite = wp.isfinite(d_delta0) and wp.isfinite(d_tilt)  # the maximum drops NaN: test each
        for i in range(lo, hi):
            dv = solution_row(work, i, m, d_delta0, d_tilt)
            vel = work[W_V, i, m] + dv
            work[W_V, i, m] = vel
            u = work[W_ZU, i, m] + g * vel
            if not wp.isfinite(dv):
                finite = False
            du = g * wp.abs(dv)  # the displacement's update (m) and its tolerance
            du_tol = rtol * (c.u_scale + wp.abs(u))
            top, bottom = ratio_max(top, bottom, wp.abs(dv), rtol * (c.v_scale_contact + wp.abs(vel)))
            top, bottom = ratio_max(top, bottom, du, du_tol)
            if wp.static(not inertia):
                state_top, state_bottom = ratio_max(state_top, state_bottom, du, du_tol)
                state_top, state_bottom = ratio_max(state_top, state_bottom, c.Kh * du, rtol * c.tau_scale)
        norm = quotient(top, bottom)
        state_norm = norm
        if wp.static(not inertia):
            state_norm = quotient(state_top, state_bottom)
        return norm, state_norm, finite

    @wp.func
    def newton_solve(
        c: Coeffs, p: MemberParams, settings: SolverSettings, m: int, n: int, work: array3, gates: array3,
        step_end: array3, g: ft, t_stage: wp.float64, t_step: wp.float64, delta0_in: ft, tilt_in: ft, curvature_in: ft,
    ):
        """Solve one implicit stage (stage constants z in work[W_ZU..W_ZP], start V in work[W_V], the
        stage coefficient g = gamma*h). Returns (converged, delta0, tilt, iterations, non_finite,
        curvature); the solved V is left in work[W_V].

        Converged when an update's error-weighted norm is at most settings.newton_tol, or when the
        error left after it, estimated from its contraction theta as theta/(1 - theta) times its
        norm, is at most NEWTON_ERROR_FRACTION x newton_tol (Hairer and Wanner II, IV.8). theta
        is measured from the second iteration on; for the first it is predicted as K times the
        norm, from the curvature K = theta/(previous norm) of the last measured contraction (Newton's quadratic convergence, ||dV_k|| ~ K
        ||dV_{k-1}||^2; the affine-invariant estimate of Deuflhard's Newton codes), which
        curvature_in carries from the previous stage or step (0: not known, no prediction). The
        stage equations are nearly linear in V at a fixed gate, so K is small and one iteration
        often suffices (docs/model.md, "Time integration"). Neither is used in float32, nor in a
        solve where an iteration met a kink (NodeRow.kink, at the iterate before the update: an
        update that crosses a kink in the one iteration it is accepted after goes unseen), which
        also returns curvature 0."""
        v_disc = ft(disc_velocity_stage(p, t_stage, t_step))
        force = normal_force_stage(p, t_stage, t_step)
        force_per_depth = ft(force / p.depth)
        moment_per_depth = ft(force * p.eccentricity * wp.float64(0.5) * p.length / p.depth)
        rtol = ft(settings.rtol)
        delta0 = delta0_in
        tilt = tilt_in
        converged = int(0)
        non_finite = int(0)
        iters = int(0)
        prev_norm = ft(1.0e30)
        curvature = curvature_in
        kinked = ft(0.0)  # whether an iteration of this solve met a kink (this thread's nodes)
        kink_free = int(0)  # 1: the team's reduction of kinked said none (the contraction or the stall test ended the solve)
        for it in range(settings.newton_max_iter):
            iters = it + 1
            # ---- pass 1: residuals, Jacobian rows, forward elimination (3 right-hand sides) ----
            # ---- pass 2: back substitution and the border products ----
            bs = assemble_system(c, settings, m, n, work, gates, step_end, g, delta0, tilt, v_disc, force_per_depth,
                                 moment_per_depth)
            kinked = wp.max(kinked, bs.kink)
            # ---- the Schur complement ----
            d_delta0, d_tilt = schur_solve(bs.d11, bs.d12, bs.d21, bs.d22, bs.e1, bs.e2, bs.s10, bs.s11, bs.s12,
                                           bs.s20, bs.s21, bs.s22)
            # ---- pass 3: update and error-weighted norm of the update ----
            norm, state_norm, finite = update_velocity(c, work, c.first_node, c.end_node, m, g, rtol, d_delta0, d_tilt)
            if wp.static(team_on):
                # every lane must take the same branch, so every decision below reads the one
                # reduced value: a lane's non-finite update reaches the others as an infinite norm
                # (the team maximum drops NaN)
                if not finite or not wp.isfinite(norm):
                    norm = ft(wp.inf)
                norm = team_max(norm)
                finite = wp.isfinite(norm)
                if wp.static(not inertia):
                    state_norm = team_max(state_norm)
            delta0 = delta0 + d_delta0
            tilt = tilt + d_tilt
            plate_norm = wp.max(wp.abs(d_delta0) / (rtol * (c.delta_scale + wp.abs(delta0))),
                                wp.abs(d_tilt) / (rtol * (c.tilt_scale + wp.abs(tilt))))
            norm = wp.max(norm, plate_norm)
            if wp.static(not inertia):
                state_norm = wp.max(state_norm, plate_norm)
            if not finite or not wp.isfinite(norm):
                non_finite = 1
                break
            if norm <= ft(settings.newton_tol):
                converged = 1
                break
            theta = ft(1.0)  # the update's contraction: measured, or predicted from the curvature
            if it > 0:
                theta = norm / prev_norm
                curvature = theta / prev_norm
            elif curvature > ft(0.0):
                theta = curvature * norm
            if wp.static(ft == wp.float64):
                error_left = theta / (ft(1.0) - theta) * norm
                if theta < ft(1.0) and error_left <= ft(NEWTON_ERROR_FRACTION) * ft(settings.newton_tol):
                    # not at a kink of the equations, where the contraction says nothing of the
                    # error (a lane's kink reaches the team through the maximum): else the solve
                    # goes on as without the estimate
                    if team_max(kinked) == ft(0.0):
                        converged = 1
                        kink_free = 1
                        break
            # stagnation inside the error tolerance: an update within the step's tolerance (norm <= 1)
            # that no longer halves has reached the round-off level of the working precision (the
            # case it is meant for is float32; it applies to float64 too, where it is rare)
            if it > 0 and norm <= ft(1.0) and norm > ft(0.5) * prev_norm:
                converged = 1
                break
            if wp.static(not inertia):
                # without inertia V is not a state but the force balance's solution, whose Jacobian
                # scales with g: its round-off level (the residual's, over g) exceeds the velocity's
                # tolerance once a step is short enough (after a located gate switch at rtol 1e-8).
                # An update that no longer halves and moves the stage's states (g*dV) by at most
                # their tolerance has reached that level: not at a kink, where a cycling iteration
                # stalls too, and not with V's own error above STALLED_VELOCITY_ERROR tolerances
                if it > 0 and state_norm <= ft(1.0) and norm > ft(0.5) * prev_norm and norm <= ft(STALLED_VELOCITY_ERROR):
                    if team_max(kinked) == ft(0.0):
                        converged = 1
                        kink_free = 1
                        break
            prev_norm = norm
        if wp.static(ft == wp.float64):
            # a curvature measured where an iteration met a kink is no guide for the next stage
            if kink_free == 0:
                if team_max(kinked) != ft(0.0):
                    curvature = ft(0.0)
        return converged, delta0, tilt, iters, non_finite, curvature

    return dict(newton_solve=newton_solve)


def make_stage_derivatives(ft, model, terms, gates, team, equations):
    """The derivatives f(Y) of a converged stage, its StageSums and (end of a step) its gate-switch
    test."""
    inertia = bool(model.inertia)
    stress_gate = model.relaxation_gate == "stress"
    team_on = team["lanes"] > 1
    Coeffs = terms["Coeffs"]
    node_weight = terms["node_weight"]
    contact_terms = terms["contact_terms"]
    node_gate = gates["node_gate"]
    node_sliding = gates["node_sliding"]
    test_switch = gates["test_switch"]
    no_switch = gates["no_switch"]
    team_switch_test = gates["team_switch_test"]
    team_min = team["team_min"]
    team_sum = team["team_sum"]
    disc_velocity_stage = equations["disc_velocity_stage"]
    stage_displacement = equations["stage_displacement"]
    over_den = make_over_den(ft)
    array3 = wp.array3d(dtype=ft)
    array4 = wp.array4d(dtype=ft)

    @wp.struct
    class StageSums:
        """Integrals over the pad of a converged stage, per unit depth: int tau_f dx (N/m),
        int sigma_n^+ dx (N/m), and min sigma_n (Pa)."""

        friction: wp.float64
        normal: wp.float64
        min_normal: wp.float64

    @wp.func
    def stage_derivatives(
        c: Coeffs, p: MemberParams, settings: SolverSettings, m: int, n: int, work: array3, gates: array3,
        step_end: array3, K: array4, slot: int, g: ft, t_stage: wp.float64, t_step: wp.float64, delta0: ft, tilt: ft,
        h: ft, end_of_step: int,
    ):
        """Stage derivatives K[slot] = f(Y) of a converged stage; returns its StageSums and, at the end
        of a step (end_of_step = 1: the last stage of a step of size h), the gate-switch test of the
        step (kernels/gates.py; the stress gate only), and stores each node's contact and gate for
        the fronts and the gate update."""
        v_disc = ft(disc_velocity_stage(p, t_stage, t_step))
        sums = StageSums()
        sums.friction = wp.float64(0.0)
        sums.normal = wp.float64(0.0)
        sums.min_normal = wp.float64(1.0e300)
        test = no_switch()
        inv_g = ft(1.0) / g  # float64: K_V = (V - z_V) * (1/g), one division for every node (over_den)
        u_l = ft(0.0)
        if c.first_node > 0:
            u_l = stage_displacement(work, c.first_node - 1, n, m, g)
        u_c = stage_displacement(work, c.first_node, n, m, g)
        for i in range(c.first_node, c.end_node):
            u_r = stage_displacement(work, i + 1, n, m, g)
            vel = work[W_V, i, m]
            ns, fr = contact_terms(c, i, n, u_l, u_c, u_r, delta0, tilt, vel, v_disc, work[W_ZT, i, m], work[W_ZP, i, m],
                                   g, node_gate(gates, i, m), node_sliding(gates, i, m), ft(settings.sliding_width))
            sigma = ns.value
            if end_of_step == 1:
                step_end[E_CONTACT, i, m] = fr.contact  # at the end of the step: the velocity and strength fronts skip lifted-off nodes
                if wp.static(stress_gate):
                    gates[G_GATE_END, i, m] = fr.gate
                    test = test_switch(c, settings, gates, i, m, fr, sigma, vel, v_disc, h, test)
            K[slot, C_U, i, m] = vel
            if wp.static(inertia):
                K[slot, C_V, i, m] = over_den(vel - work[W_ZV, i, m], g, inv_g)
            else:
                K[slot, C_V, i, m] = ft(0.0)
            K[slot, C_TAU, i, m] = fr.elastic_stress_rate
            K[slot, C_PHI, i, m] = fr.contact_age_rate
            wgt = wp.float64(node_weight(c, i, n))
            sums.friction += wgt * wp.float64(fr.stress)
            sums.normal += wgt * wp.float64(fr.contact * sigma)
            sums.min_normal = wp.min(sums.min_normal, wp.float64(sigma))
            u_l = u_c
            u_c = u_r
        if wp.static(team_on):
            sums.friction = team_sum(sums.friction)
            sums.normal = team_sum(sums.normal)
            sums.min_normal = team_min(sums.min_normal)
            if end_of_step == 1 and wp.static(stress_gate):
                test = team_switch_test(test)
        return sums, test

    return dict(StageSums=StageSums, stage_derivatives=stage_derivatives)


def make_newton(ft, model, terms, gates, team, method="tr_bdf2"):
    """The implicit stage for one working precision, model, team and method: the stage equations,
    the bordered solve (one thread's, or the team's), the Newton iteration and the converged
    stage's derivatives."""
    solver = make_bordered_solver(ft, bool(model.tilt))
    team_solver = make_team_solver(ft, team) if team["lanes"] > 1 else {}
    equations = make_stage_equations(ft, model, terms, gates, method)
    system = make_newton_system(ft, model, terms, team, equations, solver, team_solver)
    solve = make_newton_solve(ft, model, terms, team, equations, solver, system)
    derivatives = make_stage_derivatives(ft, model, terms, gates, team, equations)
    return dict(StageSums=derivatives["StageSums"], newton_solve=solve["newton_solve"],
                stage_derivatives=derivatives["stage_derivatives"], **solver)
