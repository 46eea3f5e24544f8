"""Each stage of the integrator alone (kernels/*.py), against an independent computation:
model-term derivatives against central differences, the bordered tridiagonal solve against
numpy.linalg.solve, the TR-BDF2 tableau's orders on a linear stiff system, the step-size controller
on scripted inputs, the observers on synthetic trajectories, and the kernel-visible structs against
the public parameter types."""

import dataclasses

import numpy as np
import pytest
import warp as wp
from conftest import DEVICE

import warpfric as wf
from warpfric.engine import cpu_blocks, member_params, solver_settings
from warpfric.kernels import controller, esdirk, types
from warpfric.kernels.integrator import make_stages
from warpfric.kernels.observers import friction_point
from warpfric.members import resolve_members

f64 = wp.float64


def _coeffs_params(**scene):
    values, _ = resolve_members(None, wf.Parameters(**scene))
    return wp.array(member_params(values), dtype=types.MemberParams, device=DEVICE)


# ------------------------------------------------------------------------------------------------
# model terms
# ------------------------------------------------------------------------------------------------

_TERM_INPUTS = ("u_l", "u_c", "u_r", "delta0", "tilt", "velocity", "v_disc", "z_tau", "z_phi", "g", "gate", "sliding")
_TERM_OUTPUTS = ("sigma", "sigma_ul", "sigma_uc", "sigma_ur", "sigma_d0", "sigma_a",
                 "force", "force_ul", "force_uc", "force_ur", "force_d0", "force_a",
                 "tau_f", "tau_f_sigma", "tau_f_slip", "gate_used")


def _terms_kernel(model):
    stages = make_stages(f64, model)
    terms = stages["terms"]
    make_coeffs, normal_stress = terms["make_coeffs"], terms["normal_stress"]
    elastic_force, interface_friction = terms["elastic_force"], terms["interface_friction"]

    @wp.kernel(module="unique")
    def evaluate(params: wp.array(dtype=types.MemberParams), nodes: int, node: wp.array(dtype=int),
                 x: wp.array2d(dtype=f64), out: wp.array2d(dtype=f64)):
        k = wp.tid()
        c = make_coeffs(params[0], nodes)
        i = node[k]
        ns = normal_stress(c, i, nodes, x[k, 0], x[k, 1], x[k, 2], x[k, 3], x[k, 4])
        ef = elastic_force(c, i, nodes, x[k, 0], x[k, 1], x[k, 2], x[k, 3], x[k, 4])
        # the friction law at this node's sigma_n
        fr = interface_friction(c, ns.value, x[k, 5], x[k, 6], x[k, 7], x[k, 8], x[k, 9], x[k, 10], x[k, 11], f64(1e-3))
        row = wp.vector(ns.value, ns.d_u_left, ns.d_u_center, ns.d_u_right, ns.d_delta0, ns.d_tilt,
                        ef.value, ef.d_u_left, ef.d_u_center, ef.d_u_right, ef.d_delta0, ef.d_tilt,
                        fr.stress, fr.d_normal, fr.d_slip, fr.gate, length=16, dtype=f64)
        for j in range(16):
            out[k, j] = row[j]

    return evaluate


def _evaluate_terms(kernel, params, nodes, node, x):
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    node = np.broadcast_to(np.asarray(node, dtype=np.int32), (x.shape[0],)).copy()
    out = wp.zeros((x.shape[0], len(_TERM_OUTPUTS)), dtype=f64, device=DEVICE)
    wp.launch(kernel, dim=x.shape[0], inputs=[params, nodes, wp.array(node, dtype=int, device=DEVICE),
                                               wp.array(x, dtype=f64, device=DEVICE), out], device=DEVICE)
    return dict(zip(_TERM_OUTPUTS, out.numpy().T))


def _random_state(rng, gate, sliding):
    """A loaded, sliding pad near the default scene: u ~ 1e-6 m, delta0 ~ 5e-6 m, slip ~ 1e-4 m/s."""
    return np.array([rng.normal(0, 1e-6), rng.normal(0, 1e-6), rng.normal(0, 1e-6), 6e-6 + rng.normal(0, 1e-7),
                     rng.normal(0, 1e-6), rng.normal(0, 5e-5), 1e-4, 4e4 + rng.normal(0, 1e3), 0.3 + rng.uniform(0, 0.1),
                     1e-5 * rng.uniform(0.5, 2.0), gate, sliding])


@pytest.mark.parametrize("gate_law", ["stress", "none", "velocity"])
def test_model_term_derivatives_match_central_differences(gate_law):
    """The exact partial derivatives that the Newton matrix uses, against central differences of the
    values (relative step 1e-6), at the two edge nodes and an interior node, random states."""
    model = wf.Model(relaxation_gate=gate_law)
    kernel = _terms_kernel(model)
    nodes = 11
    params = _coeffs_params()
    rng = np.random.default_rng(3)
    for node in (0, 5, nodes - 1):
        for gate, sliding in ((1.0, 0.0), (0.0, 0.0)) + (((0.5, 1.0),) if gate_law == "stress" else ()):
            x0 = _random_state(rng, gate, sliding)
            base = _evaluate_terms(kernel, params, nodes, node, x0)
            # normal stress and elastic force: derivatives with respect to u_l, u_c, u_r, delta0, tilt
            for j, name in enumerate(("ul", "uc", "ur", "d0", "a")):
                step = 1e-6 * max(abs(x0[j]), 1e-7)
                xp, xm = x0.copy(), x0.copy()
                xp[j] += step
                xm[j] -= step
                plus, minus = _evaluate_terms(kernel, params, nodes, node, xp), _evaluate_terms(kernel, params, nodes, node, xm)
                for term in ("sigma", "force"):
                    # both are linear in these variables: the central difference is exact but for
                    # round-off of the value over the step
                    fd = (plus[term][0] - minus[term][0]) / (2 * step)
                    exact = base[f"{term}_{name}"][0]
                    natural = abs(base[term][0]) / max(abs(x0[j]), 1e-7)
                    assert abs(fd - exact) <= 1e-6 * max(abs(exact), natural), (gate_law, node, gate, term, name, fd, exact)
            # friction: d tau_f/d sigma_n through delta0 (d sigma/d delta0 = M/H), d tau_f/d s through v_disc
            step = 1e-7 * abs(x0[3])
            xp, xm = x0.copy(), x0.copy()
            xp[3] += step
            xm[3] -= step
            plus, minus = _evaluate_terms(kernel, params, nodes, node, xp), _evaluate_terms(kernel, params, nodes, node, xm)
            fd = (plus["tau_f"][0] - minus["tau_f"][0]) / (plus["sigma"][0] - minus["sigma"][0])
            np.testing.assert_allclose(base["tau_f_sigma"][0], fd, rtol=1e-5, atol=1e-9 * abs(base["tau_f"][0]) / 1e6)
            step = 1e-6 * abs(x0[6])
            xp, xm = x0.copy(), x0.copy()
            xp[6] += step
            xm[6] -= step
            plus, minus = _evaluate_terms(kernel, params, nodes, node, xp), _evaluate_terms(kernel, params, nodes, node, xm)
            fd = (plus["tau_f"][0] - minus["tau_f"][0]) / (2 * step)
            np.testing.assert_allclose(base["tau_f_slip"][0], fd, rtol=1e-5)


_ROW_OUTPUTS = ("residual", "jac_left", "jac_center", "jac_right", "col_delta0", "col_tilt", "e1", "e2",
                "d11", "d12", "d21", "d22", "c1_left", "c1_center", "c1_right", "c2_left", "c2_center", "c2_right")
# each assembled entry: the value it differentiates and the variable (column of _row_variables)
_ROW_JACOBIAN = {"jac_left": ("residual", 0), "jac_center": ("residual", 1), "jac_right": ("residual", 2),
                 "col_delta0": ("residual", 3), "col_tilt": ("residual", 4),
                 "c1_left": ("e1", 0), "c1_center": ("e1", 1), "c1_right": ("e1", 2), "d11": ("e1", 3), "d12": ("e1", 4),
                 "c2_left": ("e2", 0), "c2_center": ("e2", 1), "c2_right": ("e2", 2), "d21": ("e2", 3), "d22": ("e2", 4)}


def _rows_kernel(model):
    from warpfric.kernels.newton import make_stage_equations

    stages = make_stages(f64, model)
    make_coeffs = stages["terms"]["make_coeffs"]
    equations = make_stage_equations(f64, model, stages["terms"], stages["gates"])
    node_row, stage_displacement = equations["node_row"], equations["stage_displacement"]

    @wp.kernel(module="unique")
    def rows(params: wp.array(dtype=types.MemberParams), settings: types.SolverSettings, nodes: int, node: int,
             g: f64, v_disc: f64, plate: wp.array2d(dtype=f64), work: wp.array3d(dtype=f64),
             gates: wp.array3d(dtype=f64), out: wp.array2d(dtype=f64)):
        m = wp.tid()  # one evaluation a member slot: work[:, :, m], gates[:, :, m], plate[m] = (delta0, tilt)
        c = make_coeffs(params[0], nodes)
        u_l = f64(0.0)
        if node > 0:
            u_l = stage_displacement(work, node - 1, nodes, m, g)
        u_c = stage_displacement(work, node, nodes, m, g)
        u_r = stage_displacement(work, node + 1, nodes, m, g)
        r = node_row(c, settings, m, nodes, work, gates, node, u_l, u_c, u_r, plate[m, 0], plate[m, 1], v_disc, g)
        row = wp.vector(r.residual, r.jac_left, r.jac_center, r.jac_right, r.col_delta0, r.col_tilt, r.e1, r.e2,
                        r.d11, r.d12, r.d21, r.d22, r.c1_left, r.c1_center, r.c1_right, r.c2_left, r.c2_center,
                        r.c2_right, length=18, dtype=f64)
        for j in range(18):
            out[m, j] = row[j]

    return rows


@pytest.mark.parametrize("gate_law", ["stress", "none", "velocity"])
def test_newton_system_rows_match_central_differences(gate_law):
    """Every entry of a node's row of the Newton system as kernels/newton.py assembles it (node_row:
    the pad's row J, the border columns, the plate balance rows' D block and C entries), against
    central differences of the residuals it differentiates, with respect to V_{i-1}, V_i, V_{i+1}
    (through the stage displacements u = z_u + g V), delta0 and tilt: a term dropped from the
    assembly (the normal stress's response in J's diagonal was, unseen by the iteration counts of
    the stress gate) fails here. Random stage states of a loaded pad, edge and interior nodes,
    open, closed and (stress gate) sliding gates."""
    model = wf.Model(relaxation_gate=gate_law)
    kernel = _rows_kernel(model)
    nodes, g, v_disc = 11, 2e-5, 1e-4
    params = _coeffs_params()
    settings = solver_settings(wf.Solver())
    rng = np.random.default_rng(5)
    steps = np.array([1e-9, 1e-9, 1e-9, 1e-12, 1e-12])  # V (m/s), delta0 (m), tilt (rad)
    for node in (0, 5, nodes - 1):
        for gate, sliding in ((1.0, 0.0), (0.0, 0.0)) + (((0.5, 1.0),) if gate_law == "stress" else ()):
            work = np.zeros((types.N_WORK, nodes, 11))
            work[types.W_ZU] = rng.normal(0, 1e-6, nodes)[:, None]
            work[types.W_V] = rng.normal(0, 5e-5, nodes)[:, None]
            work[types.W_ZV] = work[types.W_V] + rng.normal(0, 1e-6, nodes)[:, None]
            work[types.W_ZT] = (4e4 + rng.normal(0, 1e3, nodes))[:, None]
            work[types.W_ZP] = (0.3 + rng.uniform(0, 0.1, nodes))[:, None]
            gates = np.zeros((7, nodes, 11))
            gates[types.G_GATE], gates[types.G_SLIDE] = gate, sliding
            plate = np.tile([6e-6 + rng.normal(0, 1e-7), rng.normal(0, 1e-6)], (11, 1))
            # member slot 0: the state; 1 + 2j and 2 + 2j: variable j stepped up and down
            for j, step in enumerate(steps):
                for slot, sign in ((1 + 2 * j, 1.0), (2 + 2 * j, -1.0)):
                    if j < 3:
                        if 0 <= node - 1 + j < nodes:
                            work[types.W_V, node - 1 + j, slot] += sign * step
                    else:
                        plate[slot, j - 3] += sign * step
            out = wp.zeros((11, len(_ROW_OUTPUTS)), dtype=f64, device=DEVICE)
            wp.launch(kernel, dim=11, device=DEVICE, inputs=[
                params, settings, nodes, node, g, v_disc, wp.array(plate, dtype=f64, device=DEVICE),
                wp.array(work, dtype=f64, device=DEVICE), wp.array(gates, dtype=f64, device=DEVICE), out])
            rows = dict(zip(_ROW_OUTPUTS, out.numpy().T))
            for entry, (value, j) in _ROW_JACOBIAN.items():
                if (j == 0 and node == 0) or (j == 2 and node == nodes - 1):
                    continue  # no neighbour there
                fd = (rows[value][1 + 2 * j] - rows[value][2 + 2 * j]) / (2 * steps[j])
                exact = rows[entry][0]
                roundoff = 10 * np.finfo(float).eps * abs(rows[value][0]) / steps[j]  # the difference's own
                assert abs(fd - exact) <= 1e-6 * abs(exact) + roundoff, (gate_law, node, gate, sliding, entry, fd, exact)


# ------------------------------------------------------------------------------------------------
# bordered tridiagonal solve
# ------------------------------------------------------------------------------------------------

def _bordered_kernel(tilt_on):
    from warpfric.kernels.newton import make_bordered_solver

    solver = make_bordered_solver(f64, tilt_on)
    forward_row, back_substitution = solver["forward_row"], solver["back_substitution"]
    schur_solve, solution_row = solver["schur_solve"], solver["solution_row"]

    @wp.kernel(module="unique")
    def solve(bands: wp.array3d(dtype=f64), border: wp.array2d(dtype=f64), work: wp.array3d(dtype=f64),
              dv: wp.array2d(dtype=f64), dp: wp.array2d(dtype=f64)):
        """bands[m, i] = (lower, diagonal, upper, rhs, B0, B1, C1, C2); border[m] = (d11, d12, d21, d22, e1, e2)."""
        m = wp.tid()
        n = bands.shape[1]
        cp = f64(0.0)
        r0 = f64(0.0)
        r1 = f64(0.0)
        r2 = f64(0.0)
        for i in range(n):
            cp, r0, r1, r2 = forward_row(work, i, m, bands[m, i, 0], bands[m, i, 1], bands[m, i, 2], bands[m, i, 3],
                                         bands[m, i, 4], bands[m, i, 5], cp, r0, r1, r2)
            work[types.W_C1, i, m] = bands[m, i, 6]
            work[types.W_C2, i, m] = bands[m, i, 7]
        s10, s11, s12, s20, s21, s22 = back_substitution(work, n, m)
        d_delta0, d_tilt = schur_solve(border[m, 0], border[m, 1], border[m, 2], border[m, 3], border[m, 4], border[m, 5],
                                       s10, s11, s12, s20, s21, s22)
        for i in range(n):
            dv[m, i] = solution_row(work, i, m, d_delta0, d_tilt)
        dp[m, 0] = d_delta0
        dp[m, 1] = d_tilt

    return solve


def _team_bordered_kernel(tilt_on, lanes, exchange):
    from warpfric.kernels.newton import make_bordered_solver, make_team_solver
    from warpfric.kernels.team import make_team, node_range, vec3d

    team = make_team(f64, lanes, exchange)
    team_solver = make_team_solver(f64, team)
    start_rows, lane_row, team_solve = team_solver["start_rows"], team_solver["lane_row"], team_solver["team_solve"]
    team_sum_vec12 = team["team_sum_vec12"]
    bordered = make_bordered_solver(f64, tilt_on)
    schur_solve, solution_row = bordered["schur_solve"], bordered["solution_row"]
    vec12d = wp.types.vector(length=12, dtype=f64)

    @wp.kernel(module="unique")
    def solve(bands: wp.array3d(dtype=f64), border: wp.array2d(dtype=f64), work: wp.array3d(dtype=f64),
              dv: wp.array2d(dtype=f64), dp: wp.array2d(dtype=f64)):
        """As _bordered_kernel, by a team of ``lanes`` threads per system (each row through lane_row,
        as newton_solve hands them to the partitioned solve)."""
        m, lane = wp.tid()
        n = bands.shape[1]
        lo, hi = node_range(lane, lanes, n)
        rows = start_rows()
        for i in range(lo, hi):
            rows = lane_row(rows, work, i, m, lo, hi, n, bands[m, i, 0], bands[m, i, 1], bands[m, i, 2],
                            vec3d(bands[m, i, 3], bands[m, i, 4], bands[m, i, 5]))
            work[types.W_C1, i, m] = bands[m, i, 6]
            work[types.W_C2, i, m] = bands[m, i, 7]
        p = team_solve(work, lo, hi, m, lane, rows)
        total = team_sum_vec12(vec12d(f64(0.0), f64(0.0), f64(0.0), f64(0.0), f64(0.0), f64(0.0),
                                      p[0], p[1], p[2], p[3], p[4], p[5]))
        d_delta0, d_tilt = schur_solve(border[m, 0], border[m, 1], border[m, 2], border[m, 3], border[m, 4], border[m, 5],
                                       total[6], total[7], total[8], total[9], total[10], total[11])
        for i in range(lo, hi):
            dv[m, i] = solution_row(work, i, m, d_delta0, d_tilt)
        if lane == 0:
            dp[m, 0] = d_delta0
            dp[m, 1] = d_tilt

    return solve


def _quotient_kernel(dtype):
    from warpfric.kernels.model_terms import quotient

    @wp.kernel(module="unique")
    def divide(num: wp.array(dtype=dtype), den: wp.array(dtype=dtype), by_quotient: wp.array(dtype=dtype),
               by_division: wp.array(dtype=dtype)):
        i = wp.tid()
        by_quotient[i] = quotient(num[i], den[i])
        by_division[i] = num[i] / den[i]

    return divide


def _ratio_max_kernel(dtype):
    from warpfric.kernels.model_terms import make_ratio_max, quotient

    ratio_max = make_ratio_max(dtype)

    @wp.kernel(module="unique")
    def sweep(num: wp.array2d(dtype=dtype), den: wp.array2d(dtype=dtype), norm: wp.array(dtype=dtype)):
        row = wp.tid()
        top = dtype(0.0)
        bottom = dtype(1.0)
        for j in range(num.shape[1]):
            top, bottom = ratio_max(top, bottom, num[row, j], den[row, j])
        norm[row] = quotient(top, bottom)

    return sweep


@pytest.mark.parametrize("dtype", [wp.float64, wp.float32])
def test_ratio_max_is_the_largest_quotient(dtype):
    """kernels/model_terms.py ratio_max (the error norms' running maximum of num/den kept as a
    fraction, one division per sweep) gives the largest of the terms' quotients, as numpy's
    maximum of num / den, bit for bit: over random sweeps with dens spanning 12 decades, zero
    numerators, a sweep of zeros (norm 0), NaN terms and NaN dens (dropped, as wp.max drops
    them), an infinite numerator (norm inf), zero and infinite dens, the error norm's 1e30
    sentinel, and, in float64, terms whose cross products overflow or underflow (a diverged step:
    the largest quotient must not be lost)."""
    np_type = np.float64 if dtype == wp.float64 else np.float32
    rng = np.random.default_rng(7)
    rows, terms = 400, 24
    num = (rng.random((rows, terms)) * 10.0 ** rng.uniform(-8, 4, (rows, terms))).astype(np_type)
    den = (10.0 ** rng.uniform(-6, 6, (rows, terms))).astype(np_type)
    num[rng.random((rows, terms)) < 0.2] = 0.0
    num[0] = 0.0
    num[1, 5] = np.nan
    num[2, ::3] = np.nan
    num[3, 7] = np.inf
    den[4, 3] = 0.0  # num/0: inf
    den[5, 3] = np.inf  # num/inf: 0
    num[5, 0], den[5, 0] = 2.0, np.inf  # the first term 0 (taken), then the others
    den[6, 9] = np.nan
    num[7, 4], den[7, 4] = 1.0e30, 1.0  # the sentinel, then smaller terms
    if dtype == wp.float64:
        num[8, :2], den[8, :2] = [1e290, 1e300], [1e294, 1e294]  # products overflow: 1e6 wins
        num[9, :2], den[9, :2] = [1e-200, 2e-200], [1e-124, 1e-124]  # products underflow: 2e-76 wins
        num[9, 2:] = 0.0
        num[10, :3], den[10, :3] = [5e-320, 1e-300, 3.0], [1e-10, 1e10, 1e300]  # a subnormal num
    norm = wp.zeros(rows, dtype=dtype, device=DEVICE)
    wp.launch(_ratio_max_kernel(dtype), dim=rows, device=DEVICE,
              inputs=[wp.array(num, dtype=dtype, device=DEVICE), wp.array(den, dtype=dtype, device=DEVICE), norm])
    got = norm.numpy()
    with np.errstate(all="ignore"):
        expected = np.fmax.reduce(num / den, axis=1, initial=0.0).astype(np_type)
    assert got[0] == 0.0 and np.isinf(got[[3, 4]]).all() and np.isfinite(got[[1, 2, 5, 6]]).all() and got[7] == 1e30
    if dtype == wp.float64:
        assert got[8] == 1e300 / 1e294 and got[9] == 2e-200 / 1e-124
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("dtype", [wp.float64, wp.float32])
def test_quotient_has_the_bits_of_the_division(dtype):
    """kernels/model_terms.py quotient (a zero numerator's signed zero by a product, so that the GPU's
    division does not take its slow path) equals num / den bit for bit (NaN as NaN): the device's
    own division and numpy's, over every pair of signed zeros, infinities, NaN, subnormals (whose
    reciprocal overflows), a tiny, a huge and ordinary values."""
    np_type, bits = (np.float64, np.uint64) if dtype == wp.float64 else (np.float32, np.uint32)
    tiny, subnormal, huge = (1e-300, 5e-324, 3e300) if dtype == wp.float64 else (1e-30, 1e-45, 3e38)
    values = np.array([0.0, -0.0, 1.0, -2.5, 7.0, tiny, subnormal, -subnormal, -huge, np.inf, -np.inf, np.nan],
                      dtype=np_type)
    num, den = (a.ravel() for a in np.meshgrid(values, values, indexing="ij"))
    out = [wp.zeros(num.size, dtype=dtype, device=DEVICE) for _ in range(2)]
    wp.launch(_quotient_kernel(dtype), dim=num.size, device=DEVICE,
              inputs=[wp.array(num, dtype=dtype, device=DEVICE), wp.array(den, dtype=dtype, device=DEVICE)] + out)
    by_quotient, by_division = (a.numpy().view(bits) for a in out)
    with np.errstate(all="ignore"):
        expected = (num / den).astype(np_type)
    # NaN payloads may differ between operations and devices: NaN compared as NaN, the rest by bits
    nan = np.isnan(expected)
    np.testing.assert_array_equal(np.isnan(by_division.view(np_type)), nan)
    np.testing.assert_array_equal(by_quotient[~nan], by_division[~nan])
    np.testing.assert_array_equal(np.isnan(by_quotient.view(np_type)), nan)
    np.testing.assert_array_equal(by_quotient[~nan], expected.view(bits)[~nan])
    zero_over = (num == 0) & np.isfinite(den) & (den != 0)
    assert np.array_equal(np.signbit(by_quotient.view(np_type)[zero_over]), np.signbit(num[zero_over]) ^ np.signbit(den[zero_over]))


TEAM_EXCHANGES = ["tile", "emulated"] + (["shuffle"] if DEVICE.startswith("cuda") else [])


@pytest.mark.parametrize("tilt_on, lanes, exchange", [(True, 1, None), (False, 1, None)] + [
    (tilt_on, lanes, exchange) for exchange in TEAM_EXCHANGES
    for tilt_on, lanes in ((True, 4), (False, 3), (True, 8), (True, 64))])
def test_bordered_tridiagonal_solve_matches_numpy(tilt_on, lanes, exchange):
    """[[J, B], [C, D]] (dV, dd0, da) = (rhs, -e) for random diagonally dominant J and random borders,
    5 systems of 17 unknowns (131 for a team of 64 lanes, two warps: at least two per lane): the
    kernel's Thomas + Schur solve (lanes = 1) and the partitioned solve of a team (lanes > 1: 8
    lanes leave lanes of two nodes, one interior row; its separators by the tile team's twisted
    factorisation or by parallel cyclic reduction, kernels/team.py) equal numpy.linalg.solve to
    1e-11."""
    rng = np.random.default_rng(7)
    members, n = 5, 17 if lanes <= 8 else 2 * lanes + 3
    bands = rng.normal(size=(members, n, 8))
    bands[:, :, 1] = 4.0 + np.abs(bands[:, :, 1])  # diagonal dominance (the Newton matrix has it)
    bands[:, 0, 0] = 0.0
    bands[:, -1, 2] = 0.0
    border = rng.normal(size=(members, 6))
    border[:, 0] += 10.0
    border[:, 3] += 10.0
    work = wp.zeros((types.N_WORK, n, members), dtype=f64, device=DEVICE)
    dv = wp.zeros((members, n), dtype=f64, device=DEVICE)
    dp = wp.zeros((members, 2), dtype=f64, device=DEVICE)
    inputs = [wp.array(bands, dtype=f64, device=DEVICE), wp.array(border, dtype=f64, device=DEVICE), work, dv, dp]
    if lanes == 1:
        wp.launch(_bordered_kernel(tilt_on), dim=members, inputs=inputs, device=DEVICE)
    else:
        with cpu_blocks(True):
            wp.launch_tiled(_team_bordered_kernel(tilt_on, lanes, exchange), dim=[members], inputs=inputs, block_dim=lanes,
                            device=DEVICE)
    k = 2 if tilt_on else 1
    for m in range(members):
        a = np.zeros((n + k, n + k))
        for i in range(n):
            a[i, i] = bands[m, i, 1]
            if i > 0:
                a[i, i - 1] = bands[m, i, 0]
            if i < n - 1:
                a[i, i + 1] = bands[m, i, 2]
        a[:n, n] = bands[m, :, 4]
        a[n, :n] = bands[m, :, 6]
        a[n, n] = border[m, 0]
        if tilt_on:
            a[:n, n + 1] = bands[m, :, 5]
            a[n + 1, :n] = bands[m, :, 7]
            a[n, n + 1], a[n + 1, n], a[n + 1, n + 1] = border[m, 1], border[m, 2], border[m, 3]
        rhs = np.concatenate([bands[m, :, 3], -border[m, 4:4 + k]])
        x = np.linalg.solve(a, rhs)
        np.testing.assert_allclose(dv.numpy()[m], x[:n], rtol=1e-11, atol=1e-13)
        np.testing.assert_allclose(dp.numpy()[m, :k], x[n:], rtol=1e-11, atol=1e-13)
        if not tilt_on:
            assert dp.numpy()[m, 1] == 0.0


# ------------------------------------------------------------------------------------------------
# TR-BDF2 tableau
# ------------------------------------------------------------------------------------------------

def _tableau_kernel():
    tab = esdirk.make_tableau(f64)
    stage_constant, solution_increment, error_increment = tab["stage_constant"], tab["solution_increment"], tab["error_increment"]

    @wp.func
    def solve_stage(a: wp.mat22d, g: f64, z: wp.vec2d):
        """Y = (I - g A)^-1 z."""
        return wp.inverse(wp.identity(n=2, dtype=f64) - g * a) * z

    @wp.kernel(module="unique")
    def integrate(a: wp.mat22d, y0: wp.vec2d, h: wp.array(dtype=f64), steps: wp.array(dtype=int),
                  y_end: wp.array(dtype=wp.vec2d), first_error: wp.array(dtype=wp.vec2d)):
        """y' = A y at fixed step h[k] for steps[k] steps with the kernel's TR-BDF2 tableau."""
        k = wp.tid()
        hk = h[k]
        g = f64(esdirk.GAMMA) * hk
        y = y0
        k1 = a * y
        for s in range(steps[k]):
            z2 = wp.vec2d(stage_constant(y[0], hk, f64(esdirk.GAMMA), k1[0], f64(0.0), k1[0], 1),
                          stage_constant(y[1], hk, f64(esdirk.GAMMA), k1[1], f64(0.0), k1[1], 1))
            k2 = a * solve_stage(a, g, z2)
            z3 = wp.vec2d(stage_constant(y[0], hk, f64(esdirk.W_TRB), k1[0], f64(esdirk.W_TRB), k2[0], 2),
                          stage_constant(y[1], hk, f64(esdirk.W_TRB), k1[1], f64(esdirk.W_TRB), k2[1], 2))
            y3 = solve_stage(a, g, z3)
            k3 = a * y3
            y_new = wp.vec2d(y[0] + solution_increment(hk, k1[0], k2[0], k3[0]), y[1] + solution_increment(hk, k1[1], k2[1], k3[1]))
            if s == 0:
                first_error[k] = wp.vec2d(error_increment(hk, k1[0], k2[0], k3[0]), error_increment(hk, k1[1], k2[1], k3[1]))
            y = y_new
            k1 = k3  # FSAL: stiffly accurate, y_new is the last stage
        y_end[k] = y

    return integrate


def _run_tableau(a, y0, hs, steps):
    kernel = _tableau_kernel()
    y_end = wp.zeros(len(hs), dtype=wp.vec2d, device=DEVICE)
    err = wp.zeros(len(hs), dtype=wp.vec2d, device=DEVICE)
    wp.launch(kernel, dim=len(hs), inputs=[wp.mat22d(*a.ravel()), wp.vec2d(*y0), wp.array(hs, dtype=f64, device=DEVICE),
              wp.array(steps, dtype=int, device=DEVICE), y_end, err], device=DEVICE)
    return y_end.numpy(), err.numpy()


def test_tr_bdf2_orders_and_l_stability_on_a_linear_stiff_system():
    """y' = A y, A with eigenvalues -1 and -1e4 (not normal): at fixed steps the global error at t = 1
    falls with order 2, the embedded error estimate of one step with order 3, and the stiff mode is
    damped (L-stability: |R(h lambda)| -> 0) even at h*lambda = -1e4."""
    from scipy.linalg import expm

    a = np.array([[-1.0, 50.0], [0.0, -1e4]])
    y0 = np.array([1.0, 1.0])
    exact = expm(a * 1.0) @ y0
    hs = np.array([1 / 20, 1 / 40, 1 / 80, 1 / 160])
    y_end, err = _run_tableau(a, y0, hs, (1.0 / hs).round().astype(int))
    global_error = np.abs(y_end[:, 0] - exact[0])
    orders = np.log2(global_error[:-1] / global_error[1:])
    assert np.all(np.abs(orders - 2.0) < 0.15), orders
    # error estimate of the first step on the non-stiff problem (A = diag(-1, -2): both modes resolved)
    smooth = np.diag([-1.0, -2.0])
    _, err_smooth = _run_tableau(smooth, y0, hs, np.ones(len(hs), dtype=int))
    est_orders = np.log2(np.abs(err_smooth[:-1, 0]) / np.abs(err_smooth[1:, 0]))
    assert np.all(np.abs(est_orders - 3.0) < 0.1), est_orders
    # the estimate is the true local error to leading order (the embedded solution is order 3, one
    # above the step's: estimate / true error = 1 + O(h)); a controller misled by a constant factor
    # (0.3 < ratio < 3 let an estimate 0.4x the error pass) fails here
    y_one, _ = _run_tableau(smooth, y0, hs, np.ones(len(hs), dtype=int))
    true_local = y_one[:, 0] - np.exp(-hs)
    ratio = err_smooth[:, 0] / true_local
    assert np.all(np.abs(ratio - 1.0) < 0.03), ratio
    halving = np.abs(ratio[:-1] - 1.0) / np.abs(ratio[1:] - 1.0)  # O(h): the deviation halves with h
    assert np.all((halving > 1.7) & (halving < 2.3)), (ratio, halving)
    # L-stability: one step of h = 1 on y' = -1e4 y leaves |y| < 1e-3
    y_stiff, _ = _run_tableau(np.diag([-1e4, -1e4]), y0, np.array([1.0]), np.array([1]))
    assert np.all(np.abs(y_stiff) < 1e-3)
    # the tableau's conditions (the constants themselves): sum b = 1, sum b c = 1/2, b_hat order 3
    b = np.array([esdirk.W_TRB, esdirk.W_TRB, esdirk.GAMMA])
    c = np.array([0.0, esdirk.C2, 1.0])
    b_hat = np.array(esdirk.B_HAT)
    assert abs(b.sum() - 1) < 1e-15 and abs(b @ c - 0.5) < 1e-15
    assert abs(b_hat.sum() - 1) < 1e-15 and abs(b_hat @ c - 0.5) < 1e-15 and abs(b_hat @ c**2 - 1 / 3) < 1e-15


# ------------------------------------------------------------------------------------------------
# step-size controller
# ------------------------------------------------------------------------------------------------

@wp.kernel
def _controller_kernel(params: wp.array(dtype=types.MemberParams), settings: types.SolverSettings,
                       states: wp.array(dtype=types.IntegratorState), errors: wp.array(dtype=f64),
                       factors: wp.array(dtype=f64), steps: wp.array(dtype=controller.Step),
                       next_h: wp.array(dtype=f64), rejected: wp.array(dtype=types.IntegratorState)):
    k = wp.tid()
    st = states[k]
    factors[k] = controller.step_factor(errors[k], settings)
    step = controller.propose_step(params[k], st, settings, st.t)
    steps[k] = step
    next_h[k] = controller.accepted_step_size(st, step, factors[k])
    rejected[k] = controller.reject(st, settings, step.h * wp.min(factors[k], settings.step_safety), 0)


def test_controller_on_scripted_inputs():
    """step_factor against its formula; steps clipped to breakpoints, halved before them, ended at
    a located switch; a clipped step keeps its size; a rejected step below min_step underflows."""
    solver = wf.Solver(min_step=1e-12, initial_step=1e-6)
    settings = solver_settings(solver)
    values, _ = resolve_members({"eccentricity": np.zeros(6)}, wf.Parameters(end_time=30.0))
    params = member_params(values)
    st = np.zeros(6, dtype=types.IntegratorState.numpy_dtype())
    st["switch_limit"] = 1e300
    # (t, h): far from a breakpoint; passing the force-ramp end (10 s); within 2 h of it; at a switch
    st["t"] = [1.0, 9.5, 9.0, 1.0, 1.0, 5.0]
    st["h"] = [0.1, 1.0, 0.6, 0.1, 0.1, 1e-12]
    st["switch_limit"][3] = 1.05
    errors = np.array([0.5, 0.0, 8.0, 1e6, 1.0, 4.0])
    arrays = [wp.array(params, dtype=types.MemberParams, device=DEVICE), settings,
              wp.array(st, dtype=types.IntegratorState, device=DEVICE), wp.array(errors, dtype=f64, device=DEVICE)]
    factors = wp.zeros(6, dtype=f64, device=DEVICE)
    steps = wp.zeros(6, dtype=controller.Step, device=DEVICE)
    next_h = wp.zeros(6, dtype=f64, device=DEVICE)
    rejected = wp.zeros(6, dtype=types.IntegratorState, device=DEVICE)
    wp.launch(_controller_kernel, dim=6, inputs=arrays + [factors, steps, next_h, rejected], device=DEVICE)
    exponent = controller.ERROR_EXPONENT
    expected = np.where(errors > 0, np.clip(0.9 * np.maximum(errors, 1e-300) ** exponent, 0.2, 5.0), 5.0)
    np.testing.assert_allclose(factors.numpy(), expected, rtol=1e-15)
    assert abs(exponent + 1 / 3) < 1e-7  # -1/3 (rounded to float32: see controller.py)
    s = steps.numpy()
    assert s["clipped"].tolist() == [0, 1, 0, 2, 0, 0]
    np.testing.assert_allclose(s["t_new"], [1.1, 10.0, 9.5, 1.05, 1.1, 5.0 + 1e-12], rtol=1e-15)
    assert s["t_new"][1] == 10.0 and s["t_new"][3] == 1.05  # exactly on the breakpoint and the switch
    np.testing.assert_allclose(next_h.numpy()[[0, 1]], [0.1 * expected[0], max(0.5 * expected[1], 1.0)], rtol=1e-15)
    rej = rejected.numpy()
    assert (rej["steps_rejected"] == 1).all()
    meanings = types.STATUS_MEANINGS
    assert meanings[rej["status"][5]] == "step_size_underflow" and rej["done"][5] == 1
    assert (rej["done"][:5] == 0).all()


# ------------------------------------------------------------------------------------------------
# observers
# ------------------------------------------------------------------------------------------------

@wp.kernel
def _friction_points(params: wp.array(dtype=types.MemberParams), times: wp.array(dtype=f64),
                     mu: wp.array(dtype=f64), cubic: int, states: wp.array(dtype=types.IntegratorState)):
    st = states[0]
    for k in range(times.shape[0]):
        # int tau dx = mu, int sigma dx = 1: the coefficient is mu
        st = friction_point(st, params[0], times[k], mu[k], f64(1.0), f64(1.0), cubic)
    states[0] = st


def _observe_peak(times, mu, cubic):
    values, _ = resolve_members(None, wf.Parameters())
    st = np.zeros(1, dtype=types.IntegratorState.numpy_dtype())
    st["mu_s"] = -np.inf
    states = wp.array(st, dtype=types.IntegratorState, device=DEVICE)
    wp.launch(_friction_points, dim=1, inputs=[wp.array(member_params(values), dtype=types.MemberParams, device=DEVICE),
              wp.array(times, dtype=f64, device=DEVICE), wp.array(mu, dtype=f64, device=DEVICE), cubic, states], device=DEVICE)
    return states.numpy()[0]


def test_mu_s_observer_on_a_synthetic_peak():
    """mu(t) = 0.5 - 3 (t - 20.3)^2 sampled at irregular times: the running maximum refined by the
    parabola through the last three points is the exact peak (0.5 at 20.3 s), though no sample lies
    on it; lift-off stays 0 with sigma_n > 0."""
    rng = np.random.default_rng(1)
    times = np.sort(rng.uniform(20.0, 20.6, 40))
    times = times[np.abs(times - 20.3) > 0.01]
    mu = 0.5 - 3 * (times - 20.3) ** 2
    out = _observe_peak(times, mu, 0)
    assert mu.max() < 0.5 - 1e-4
    assert abs(out["mu_s"] - 0.5) < 1e-12 and abs(out["mu_s_time"] - 20.3) < 1e-10
    assert out["steps_accepted"] == len(times) and out["lift_off"] == 0 and out["mu_final"] == mu[-1]


def test_mu_s_cubic_observer_is_exact_on_a_cubic_peak():
    """ESDIRK4's refinement (cubic = 1): mu(t) = 0.5 - 3 x^2 + 5 x^3, x = t - 20.3 (a maximum of 0.5
    at x = 0), sampled at irregular times: the cubic through the last four points is exact; the
    parabola is not (its error is the cubic term over the bracketing steps)."""
    rng = np.random.default_rng(2)
    times = np.sort(rng.uniform(20.0, 20.6, 30))
    times = times[np.abs(times - 20.3) > 0.01]
    x = times - 20.3
    mu = 0.5 - 3 * x**2 + 5 * x**3
    cubic = _observe_peak(times, mu, 1)
    parabola = _observe_peak(times, mu, 0)
    assert abs(cubic["mu_s"] - 0.5) < 1e-12 and abs(cubic["mu_s_time"] - 20.3) < 1e-9
    assert abs(parabola["mu_s"] - 0.5) > 1e-7


def _switch_gates_kernel():
    stages = make_stages(f64, wf.Model())
    switch_gates = stages["gates"]["switch_gates"]
    make_coeffs = stages["terms"]["make_coeffs"]

    @wp.kernel(module="unique")
    def switch(params: wp.array(dtype=types.MemberParams), states: wp.array(dtype=types.IntegratorState),
               outputs: types.OutputSettings, state: wp.array3d(dtype=f64), K: wp.array4d(dtype=f64),
               gates: wp.array3d(dtype=f64), t_old: f64, t_new: f64, backward_euler: int,
               yield_time: wp.array2d(dtype=f64), arrival: wp.array3d(dtype=f64),
               arrival_error: wp.array3d(dtype=f64)):
        """One accepted step's gate update (thread kernel: the member's nodes in one thread)."""
        n = state.shape[1]
        c = make_coeffs(params[0], n)
        states[0] = switch_gates(c, params[0], states[0], outputs, 0, n, state, K, 2, gates, t_old, t_new,
                                 backward_euler, yield_time, arrival, arrival_error)

    return switch


def _switch_gates(nodes, t_old, t_new, backward_euler, t_prev, contact_front=1, recorded=np.nan, **scene):
    """Run switch_gates once on the node rows of ``nodes`` (dicts of gate slots; unset: 0), with the
    state tau = 1e4 Pa, phi = 2 s, V = 0, the FSAL slot K[2] = (0, 0, 1, 1) and every yield time and
    contact arrival ``recorded`` before (its error 0); returns the gates, yield times, contact
    arrivals and their errors, K[2], the member state and its MemberParams; ``scene``: Parameters
    fields."""
    n = len(nodes)
    params = _coeffs_params(**scene)
    st = np.zeros(1, dtype=types.IntegratorState.numpy_dtype())
    st["t"], st["t2"], st["npts"] = t_old, t_prev, 3
    gates = np.zeros((types.N_GATE, n, 1))
    for i, node in enumerate(nodes):
        for slot, value in node.items():
            gates[getattr(types, slot), i, 0] = value
    state = np.zeros((types.N_COMPONENTS, n, 1))
    state[types.C_TAU], state[types.C_PHI] = 1e4, 2.0
    K = np.zeros((3, types.N_COMPONENTS, n, 1))
    K[2, types.C_TAU] = K[2, types.C_PHI] = 1.0
    outputs = types.OutputSettings()
    outputs.contact_front = contact_front
    arrays = dict(gates=wp.array(gates, dtype=f64, device=DEVICE), K=wp.array(K, dtype=f64, device=DEVICE),
                  yield_time=wp.full((n, 1), recorded, dtype=f64, device=DEVICE),
                  arrival=wp.full((types.N_EVENTS, n, 1), recorded, dtype=f64, device=DEVICE),
                  arrival_error=wp.full((types.N_EVENTS, n, 1), 0.0 if np.isfinite(recorded) else np.nan,
                                        dtype=f64, device=DEVICE))
    states = wp.array(st, dtype=types.IntegratorState, device=DEVICE)
    wp.launch(_switch_gates_kernel(), dim=1, device=DEVICE, inputs=[
        params, states, outputs, wp.array(state, dtype=f64, device=DEVICE), arrays["K"], arrays["gates"], t_old, t_new, backward_euler,
        arrays["yield_time"], arrays["arrival"], arrays["arrival_error"]])
    out = {name: a.numpy() for name, a in arrays.items()}
    return (out["gates"][:, :, 0], out["yield_time"][:, 0], out["arrival"][types.EV_CONTACT, :, 0],
            out["arrival_error"][types.EV_CONTACT, :, 0], out["K"][2, :, :, 0], states.numpy()[0], params.numpy()[0])


def test_switch_gates_records_each_first_opening_after_the_disc_starts():
    """One accepted step's gate update on nodes in every regime and every change of regime, against
    the rules of kernels/gates.py switch_gates written out here: a closed node whose margin crosses 0
    opens (its yield time the margin's linear crossing; its contact arrival the root of the parabola through
    the last three margins, with its distance to the linear crossing as the error); a node in the
    sliding regime opens where its margin crosses 0, as a closed node does, and not where its solved
    gate leaves 0 with the margin still negative (the regularised gate's tail, far below the yield
    surface); a sliding node whose gate was already above 0, an open node and a node whose margin
    stays negative do not open; a node out of contact without friction stress (margin 0) that picks
    up some opens its gate but records no transition (it was not sticking); a time already
    recorded is kept; the FSAL relaxation rates follow each changed gate; a closed node whose
    margin crosses 0 into a side whose rate points back slides (Filippov), its gate started where
    the margin's rate, affine in the gate, brings it to 0 over the step; an opening before the disc
    starts records nothing, and one after the disc's stop no arrival."""
    t_prev, t_old, t_new = 20.09, 20.1, 20.102
    root = 20.1013  # the closed node's margin z(t) = 50 (t - root) - 4e4 (t - root)^2 (Pa)
    z = lambda t: 50.0 * (t - root) - 4e4 * (t - root) ** 2  # noqa: E731
    nodes = [
        dict(G_MARGIN_OLD=z(t_prev), G_MARGIN=z(t_old), G_MARGIN_END=z(t_new)),  # closed, opens
        dict(G_SLIDE=1.0, G_GATE_END=0.3, G_MARGIN_OLD=-0.2, G_MARGIN=-0.1, G_MARGIN_END=-0.05),  # sliding, gate leaves 0
        dict(G_SLIDE=1.0, G_GATE=0.5, G_GATE_END=0.7, G_MARGIN=-0.1, G_MARGIN_END=-0.05),  # sliding, already above 0
        dict(G_GATE=1.0, G_MARGIN=3.0, G_MARGIN_END=4.0),  # open, stays open
        dict(G_MARGIN=-3.0, G_MARGIN_END=-2.0),  # closed, stays closed
        dict(G_GATE=1.0, G_MARGIN=1.0, G_MARGIN_END=-1.0),  # open, closes (no opening)
        dict(G_MARGIN_OLD=z(t_prev), G_MARGIN=z(t_old), G_MARGIN_END=z(t_new), G_DMARGIN=-200.0),  # enters sliding
        dict(G_SLIDE=1.0, G_GATE=0.2, G_GATE_END=0.6, G_MARGIN_OLD=z(t_prev), G_MARGIN=z(t_old),
             G_MARGIN_END=z(t_new)),  # sliding, its margin crosses 0
        dict(G_MARGIN=0.0, G_MARGIN_END=3.0),  # out of contact without stress, picks up 3 Pa: opens, no transition
    ]
    gates, yield_time, arrival, error, K, st, p = _switch_gates(nodes, t_old, t_new, 0, t_prev)
    linear = t_old + (t_new - t_old) * z(t_old) / (z(t_old) - z(t_new))
    h = t_new - t_old
    # node 6: seen rate r_obs = (z1 - z0)/h, with the gate open the rate r_obs + dr < 0 (points back):
    # it slides, from the gate at which r_obs + g dr brings the margin z1 to 0 over a step, -z1/h
    r_obs = (z(t_new) - z(t_old)) / h
    assert r_obs - 200.0 < 0
    slide_gate = (-z(t_new) / h - r_obs) / -200.0
    assert 0.0 < slide_gate < 1.0
    assert np.isfinite(yield_time).tolist() == [True, False, False, False, False, False, True, True, False]
    assert yield_time[0] == pytest.approx(linear, abs=1e-12)
    for node in (6, 7):  # entering the sliding regime, and crossing inside it: the closed node's times
        assert yield_time[node] == yield_time[0] and arrival[node] == arrival[0] and error[node] == error[0]
    assert arrival[0] == pytest.approx(root, abs=1e-12) and error[0] == pytest.approx(abs(root - linear), abs=1e-12)
    assert np.isnan(arrival[[1, 2, 3, 4, 5, 8]]).all() and np.isnan(error[[1, 2, 3, 4, 5, 8]]).all()
    # (the sliding start gate to the round-off of the step's h = t_new - t_old at t ~ 20 s)
    np.testing.assert_allclose(gates[types.G_GATE], [1.0, 0.3, 0.7, 1.0, 0.0, 0.0, slide_gate, 0.6, 1.0], rtol=1e-10)
    np.testing.assert_array_equal(gates[types.G_SLIDE], [0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0])
    np.testing.assert_array_equal(gates[types.G_MARGIN], [node["G_MARGIN_END"] for node in nodes])
    np.testing.assert_array_equal(gates[types.G_MARGIN_OLD], [node.get("G_MARGIN", 0.0) for node in nodes])
    assert st["gate_switches"] == 4  # the regimes that changed: 0 and 8 closed -> open, 5 open -> closed, 6 closed -> sliding
    # the FSAL slot: d tau/dt and d phi/dt lose state * (gate change) * |v_disc - kif V| / D (V = 0)
    v_disc = p["disc_velocity"] * (t_new - p["rest_until"]) / p["velocity_ramp_time"]
    # (a sliding node's slot already follows its last stage's solved gate: no change)
    relax = np.array([1.0, 0.0, 0.0, 0.0, 0.0, -1.0, slide_gate, 0.0, 1.0]) * abs(v_disc) / p["memory_length"]
    np.testing.assert_allclose(K[types.C_TAU], 1.0 - 1e4 * relax, rtol=1e-10)
    np.testing.assert_allclose(K[types.C_PHI], 1.0 - 2.0 * relax, rtol=1e-10)
    # a first opening only: a node whose times are recorded keeps them
    kept = _switch_gates(nodes, t_old, t_new, 0, t_prev, recorded=20.05)
    assert (kept[1] == 20.05).all() and (kept[2] == 20.05).all() and (kept[3] == 0.0).all()
    # before the disc starts nothing is recorded, and without the contact front no arrival
    before = _switch_gates(nodes, 19.9, 19.902, 0, 19.89)
    assert np.isnan(before[1]).all() and np.isnan(before[2]).all()
    np.testing.assert_allclose(before[0][types.G_GATE], gates[types.G_GATE], rtol=1e-10)
    # the arrival's window ends at the disc's stop: a step that starts there records yield_time only
    stopped = _switch_gates(nodes, t_old, t_new, 0, t_prev, stop_time=t_old)
    np.testing.assert_array_equal(stopped[1], yield_time)
    assert np.isnan(stopped[2]).all()
    off = _switch_gates(nodes, t_old, t_new, 0, t_prev, contact_front=0)
    np.testing.assert_array_equal(off[1], yield_time)
    assert np.isnan(off[2]).all()
    # after a (re)start no earlier point belongs to the step's smooth piece: the linear crossing, the
    # whole step as the error
    restart = _switch_gates(nodes[:1], t_old, t_new, 1, t_prev)
    assert restart[2][0] == pytest.approx(linear, abs=1e-12) and restart[3][0] == pytest.approx(t_new - t_old)


# ------------------------------------------------------------------------------------------------
# kernel-visible structs in step with the public types
# ------------------------------------------------------------------------------------------------

def test_kernel_structs_stay_in_step_with_the_public_parameters():
    """Every field of MemberParams is a public parameter (plus the derived auto_end), every public
    parameter reaches the kernels (max_end_time folded into end_time), every SolverSettings field
    is filled from its warpfric.Solver setting, and OutputSettings from warpfric.Fronts."""
    kernel_fields = set(types.MemberParams.vars)
    public = {f.name for f in dataclasses.fields(wf.Parameters)}
    assert kernel_fields - public == {"auto_end"}
    assert public - kernel_fields == {"max_end_time"}  # folded into end_time by engine.member_params
    solver = wf.Solver(rtol=1e-4, switch_tol=2.0, initial_step=2e-6, min_step=3e-14, max_step=0.5, newton_tol=0.04,
                       sliding_width=2e-3, max_steps=1234, newton_max_iter=7, step_safety=0.8, step_min_factor=0.3,
                       step_max_factor=4.0, failure_factor=0.2, predict_switches=False, error_filter_nodes=321)
    settings = solver_settings(solver)
    derived = {"switch_rtol": 2e-4}
    for name in types.SolverSettings.vars:
        expected = derived.get(name, getattr(solver, name, None))
        assert expected is not None, f"SolverSettings.{name} has no Solver setting"
        if isinstance(expected, bool):
            expected = int(expected)  # flags are int32 in the kernels
        assert getattr(settings, name) == pytest.approx(expected), name
    from warpfric.engine import output_settings

    out = output_settings(wf.Fronts(event=("strength", "velocity"), threshold=0.3, direction="absolute"))
    assert (out.velocity_front, out.front_direction, out.front_threshold) == (1, types.FRONT_DIRECTIONS.index("absolute"), 0.3)
    assert (out.contact_front, out.strength_front) == (0, 1)
    assert output_settings(wf.Fronts(), stress_gate=True).contact_front == 1
    assert output_settings(wf.Fronts(), stress_gate=False).contact_front == 0  # no gate to open
    none = output_settings(None)
    assert (none.velocity_front, none.contact_front, none.strength_front) == (0, 0, 0)


def _fronts_kernel():
    stages = make_stages(f64, wf.Model())
    track_fronts = stages["observers"]["track_fronts"]
    make_coeffs = stages["terms"]["make_coeffs"]

    @wp.kernel(module="unique")
    def sweep(params: wp.array(dtype=types.MemberParams), states: wp.array(dtype=types.IntegratorState),
              crossing: wp.array(dtype=f64), slope: wp.array(dtype=f64), curvature: f64, contact: wp.array(dtype=f64),
              h: f64, steps: int, use_stage2: int, K: wp.array4d(dtype=f64), step_end: wp.array3d(dtype=f64),
              arrival: wp.array3d(dtype=f64), arrival_error: wp.array3d(dtype=f64)):
        """Steps of size h from t = 20.5 through a field whose detachment velocity at node i is
        w_i(t) = level + slope_i (t - crossing_i) + curvature (t - crossing_i)^2 (pad velocity -w: the
        disc moves in +x), fed to track_fronts as the FSAL, second-stage and last-stage slots."""
        st = states[0]
        n = crossing.shape[0]
        level = st.front_level
        for i in range(n):
            step_end[types.E_CONTACT, i, 0] = contact[i]
        for k in range(steps):
            t_old = f64(20.5) + f64(k) * h
            t_new = t_old + h
            t_mid = t_old + f64(esdirk.C2) * h
            for i in range(n):
                d0 = t_old - crossing[i]
                dm = t_mid - crossing[i]
                d1 = t_new - crossing[i]
                K[0, types.C_U, i, 0] = -(level + slope[i] * d0 + curvature * d0 * d0)
                K[1, types.C_U, i, 0] = -(level + slope[i] * dm + curvature * dm * dm)
                K[2, types.C_U, i, 0] = -(level + slope[i] * d1 + curvature * d1 * d1)
            st = track_fronts(make_coeffs(params[0], n), params[0], st, 0, n, K, step_end, 0, 1, 2, t_old, t_new, arrival, arrival_error, 0,
                              f64(0.4), use_stage2)
        states[0] = st

    return sweep


@pytest.mark.parametrize("use_stage2", [1, 0])
def test_front_observer_on_a_synthetic_field(use_stage2):
    """Arrival times from a field with known crossings: exact on the quadratic through the step's
    ends and its second stage (TR-BDF2 steps), the linear crossing after a backward-Euler step, each
    with its error estimate; a node without contact never arrives; the event maximum is the largest
    w seen at a step end."""
    n, h, steps = 6, 0.01, 40
    crossing = 20.5 + np.array([0.053, 0.1, 0.1475, 0.21, 0.30, 0.11])
    slope = np.array([1e-3, 2e-3, 5e-4, 1e-3, 3e-3, 1e-3])
    curvature = 2e-3
    contact = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 0.0])
    values, _ = resolve_members(None, wf.Parameters())
    st = np.zeros(1, dtype=types.IntegratorState.numpy_dtype())
    level = 1e-4
    st["front_level"] = level
    st["front_max"] = -np.inf
    arrays = dict(K=wp.zeros((3, types.N_COMPONENTS, n, 1), dtype=f64, device=DEVICE),
                  step_end=wp.zeros((types.N_STEP_END, n, 1), dtype=f64, device=DEVICE),
                  arrival=wp.full((types.N_EVENTS, n, 1), np.nan, dtype=f64, device=DEVICE),
                  arrival_error=wp.full((types.N_EVENTS, n, 1), np.nan, dtype=f64, device=DEVICE))
    states = wp.array(st, dtype=types.IntegratorState, device=DEVICE)
    wp.launch(_fronts_kernel(), dim=1, device=DEVICE, inputs=[
        wp.array(member_params(values), dtype=types.MemberParams, device=DEVICE), states,
        wp.array(crossing, dtype=f64, device=DEVICE), wp.array(slope, dtype=f64, device=DEVICE), curvature,
        wp.array(contact, dtype=f64, device=DEVICE), h, steps, use_stage2,
        arrays["K"], arrays["step_end"], arrays["arrival"], arrays["arrival_error"]])
    arrival = arrays["arrival"].numpy()[types.EV_VELOCITY, :, 0]
    error = arrays["arrival_error"].numpy()[types.EV_VELOCITY, :, 0]
    assert np.isnan(arrival[5]) and np.isnan(error[5])  # lifted off
    if use_stage2:
        np.testing.assert_allclose(arrival[:5], crossing[:5], rtol=0, atol=1e-12)
        # the estimate is the distance to the linear crossing: nonzero inside a step (the field is
        # curved), zero where the crossing falls on a step end (0.1, 0.21, 0.30 s after the start)
        on_step_end = np.abs((crossing[:5] - 20.5) / h - np.round((crossing[:5] - 20.5) / h)) < 1e-9
        assert on_step_end.tolist() == [False, True, False, True, True]
        assert np.all(error[:5][~on_step_end] > 1e-6) and np.all(error[:5] < h)
        np.testing.assert_allclose(error[:5][on_step_end], 0.0, atol=1e-12)
    else:
        t_old = 20.5 + np.floor((crossing[:5] - 20.5) / h + 1e-9) * h
        w = lambda t, i: level + slope[i] * (t - crossing[i]) + curvature * (t - crossing[i]) ** 2  # noqa: E731
        lin = [t_old[i] + h * (level - w(t_old[i], i)) / (w(t_old[i] + h, i) - w(t_old[i], i)) for i in range(5)]
        np.testing.assert_allclose(arrival[:5], lin, rtol=0, atol=1e-12)
        np.testing.assert_allclose(error[:5], h)
    t_end = 20.5 + steps * h
    w_end = level + slope[:5] * (t_end - crossing[:5]) + curvature * (t_end - crossing[:5]) ** 2
    assert states.numpy()[0]["front_max"] == pytest.approx(w_end.max(), rel=1e-12)


def _newton_kernel():
    stages = make_stages(f64, wf.Model())
    make_coeffs = stages["terms"]["make_coeffs"]
    newton_solve = stages["newton"]["newton_solve"]

    @wp.kernel(module="unique")
    def solve(params: wp.array(dtype=types.MemberParams), settings: types.SolverSettings, work: wp.array3d(dtype=f64),
              gates: wp.array3d(dtype=f64), step_end: wp.array3d(dtype=f64), out: wp.array2d(dtype=int)):
        m = wp.tid()
        n = work.shape[1]
        c = make_coeffs(params[m], n)
        ok, d0, a, iters, bad, _curvature = newton_solve(c, params[m], settings, m, n, work, gates, step_end,
                                                         f64(1e-6), f64(10.0), f64(10.0), f64(6e-6), f64(0.0),
                                                         f64(0.0))
        out[m, 0] = ok
        out[m, 1] = bad
        out[m, 2] = iters

    return solve


def test_newton_flags_a_non_finite_update():
    """A stage whose contact age is negative (log of a negative number: NaN friction) must end as a
    non-finite Newton failure, never as converged: Warp's wp.max drops NaN (fmax), so a norm alone
    would read 0. Member 1, with a positive contact age, has no non-finite update."""
    nodes = 11
    values, _ = resolve_members({"eccentricity": [0.0, 0.0]}, wf.Parameters())
    work = np.zeros((types.N_WORK, nodes, 2))
    work[types.W_ZP, :, 0] = -1.0  # contact age phi < 0 in member 0
    work[types.W_ZP, :, 1] = 0.3
    gates = np.ones((types.N_GATE, nodes, 2))
    gates[types.G_SLIDE] = 0.0
    out = wp.zeros((2, 3), dtype=int, device=DEVICE)
    wp.launch(_newton_kernel(), dim=2, device=DEVICE, inputs=[
        wp.array(member_params(values), dtype=types.MemberParams, device=DEVICE), solver_settings(wf.Solver()),
        wp.array(work, dtype=f64, device=DEVICE), wp.array(gates, dtype=f64, device=DEVICE),
        wp.zeros((types.N_STEP_END, nodes, 2), dtype=f64, device=DEVICE), out])
    result = out.numpy()
    assert result[0, 0] == 0 and result[0, 1] == 1 and result[0, 2] == 1  # stopped at the first NaN update
    assert result[1, 1] == 0


@pytest.mark.filterwarnings("ignore:Solver\\(lanes=:UserWarning")  # a team on the CPU's fibers
@pytest.mark.parametrize("dtype, gate, fronts, lanes", [("float64", "stress", True, 1), ("float32", "none", False, 1),
                                                        ("float64", "stress", True, 8)])
def test_device_memory_per_member_is_reported(dtype, gate, fronts, lanes):
    """device_bytes_per_member counts the integration arrays of kernels/types.py: state (4 N),
    stages (12 N), step_end (2 N) and work (N_WORK N = 13 N; not where the blocked GPU kernel keeps
    it in shared memory, work_memory "shared") in the working precision, the stress gate's gates
    (N_GATE N = 7 N, working precision) and yield times (N, float64), the fronts' arrival times and errors of the three
    events (6 N, float64; the contact front's, the default), and the member's parameter and state
    structs; kernel builds are timed apart from the run. A team's arrays hold each member
    contiguously (transposed views; they were counted short, 4,248 bytes against 9,112)."""
    n = 24
    ds = wf.simulate({"eccentricity": [0.0, 0.1, 0.2]}, model=wf.Model(relaxation_gate=gate),
                     solver=wf.Solver(nodes=n, dtype=dtype, lanes=lanes), fronts=wf.Fronts() if fronts else None,
                     device=DEVICE, progress=False)
    size = 8 if dtype == "float64" else 4
    work = types.N_WORK if ds.attrs["work_memory"] == "global" else 0
    expected = (size * n * (4 + 12 + types.N_STEP_END + work) + (size * types.N_GATE * n + 8 * n if gate == "stress" else 0)
                + (2 * types.N_EVENTS * 8 * n if fronts else 0))
    expected += np.dtype(types.MemberParams.numpy_dtype()).itemsize + np.dtype(types.IntegratorState.numpy_dtype()).itemsize
    assert ds.attrs["device_bytes_per_member"] == expected
    assert types.N_WORK == 13 and types.N_STEP_END == 2 and types.N_GATE == 7
    assert ds.attrs["kernel_build_time_s"] >= 0 and ds.attrs["wall_time_s"] > 0
