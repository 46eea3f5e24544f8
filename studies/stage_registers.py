"""Registers and stack of the team kernel's stage code, piece by piece: a check of the premise of
the on-chip redesign (docs/performance.md, "A kernel with the member on chip: what it rests on"),
that a thread can do a member's node work in at most ~200 registers without a stack once the
member-level work (the attempt loop, the controller, the accepted step's gates and observers)
leaves it.

    python studies/stage_registers.py [--nodes 200] [--lanes 32 64] [--caps 255 200 168 128]
                                      [--pieces rows newton derivatives step accept kernel] [--arch 90]

Each piece is a kernel of one team per member (a block of ``lanes`` threads, the work array in
global memory) that runs the default law's device functions as the integrate kernel calls them,
once, from a member's state as the kernel holds it:

    rows         node_row over the lane's nodes (the friction law and one Newton row per node)
    rows_table   the same, with the member's coefficients (Coeffs) read from a (member,) table at
                 each node and each row's sum stored before the next node's: the coefficients
                 cannot stay in registers across nodes, as where they would be read from shared
                 memory
    newton       one stage's Newton solve (newton_solve: rows, the team's bordered solve, updates)
    derivatives  the derivatives of a step's last converged stage (stage_derivatives with the
                 stress gate's switch test)
    derivatives_mid  those of a stage inside the step (no switch test)
    step         a TR-BDF2 attempt (implicit_step: two stages, their derivatives, the error norm)
    accept       the attempt and the accepted step's code (implicit_step, then accept_step)
    kernel       the integrate kernel itself (the attempt loop, the controller and all of the above),
                 built as the pieces are: a block a member, the work array in global memory
                 (WARPFRIC_TEAM_BLOCK_MEMBERS=1, WARPFRIC_TEAM_SHARED_WORK=0; a run's default
                 kernel, eight members a block with the work in shared memory, keeps less stack)
    start        what every piece does before its own code (the member's state and parameters
                 loaded, its coefficients derived): a launch's fixed cost, to subtract from a
                 piece's kernel time where one member's pieces are timed

Every piece is compiled ahead of time for sm_<arch> (Warp's NVRTC, no GPU or driver needed) with
the register cap given (cuda_max_registers; 255 is the H100's own limit), and its registers and
stack bytes are read with cuobjdump -res-usage ($CUDA_BIN, the PATH or /usr/local/cuda/bin; the
PyPI wheel nvidia-cuda-cuobjdump carries it). These are static counts of compiled code, not
timings.
"""

import argparse
import os
import re
import subprocess
import sys

import warp as wp

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import warpfric as wf  # noqa: E402
from sass_sites import tool  # noqa: E402

RES_USAGE = re.compile(r"REG:(\d+)\s+STACK:(\d+)")
PIECES = ("rows", "rows_table", "newton", "derivatives", "derivatives_mid", "step", "accept", "kernel", "start")


def piece_kernel(piece: str, lanes: int, cap: int, model):
    """The kernel of one piece (module docstring) for a team of ``lanes``, at ``cap`` registers."""
    from warpfric.kernels.integrator import (get_integrator, make_acceptance, make_stages, team_exchange)
    from warpfric.kernels.newton import make_stage_equations
    from warpfric.kernels.controller import Step
    from warpfric.kernels.team import node_range
    from warpfric.kernels.types import IntegratorState, MemberParams, OutputSettings, SolverSettings

    ft = wp.float64
    if piece == "kernel":
        os.environ["WARPFRIC_TEAM_MAX_REGISTERS"] = str(cap)
        os.environ["WARPFRIC_TEAM_BLOCK_MEMBERS"] = "1"  # a block a member, as the pieces
        os.environ["WARPFRIC_TEAM_SHARED_WORK"] = "0"  # the work in global memory, as the pieces
        try:
            built = get_integrator("float64", model, lanes, "tr_bdf2", cuda=True)
        finally:
            for key in ("WARPFRIC_TEAM_MAX_REGISTERS", "WARPFRIC_TEAM_BLOCK_MEMBERS", "WARPFRIC_TEAM_SHARED_WORK"):
                del os.environ[key]
        return built["integrate"]
    stages = make_stages(ft, model, lanes, "tr_bdf2", team_exchange(lanes, True))
    make_coeffs = stages["terms"]["make_coeffs"]
    newton_solve = stages["newton"]["newton_solve"]
    stage_derivatives = stages["newton"]["stage_derivatives"]
    implicit_step = stages["esdirk"]["implicit_step"]
    accept_step = make_acceptance(ft, model, "tr_bdf2", stages)["accept_step"]
    Coeffs = stages["terms"]["Coeffs"]
    node_row = make_stage_equations(ft, model, stages["terms"], stages["gates"])["node_row"]
    array3 = wp.array3d(dtype=ft)
    array4 = wp.array4d(dtype=ft)
    code = PIECES.index(piece)

    @wp.kernel(module="unique", enable_backward=False, cuda_max_registers=cap)
    def stage_piece(
        params: wp.array(dtype=MemberParams), settings: SolverSettings, outputs: OutputSettings,
        record_times: wp.array(dtype=wp.float64), member_states: wp.array(dtype=IntegratorState), state: array3,
        K: array4, work: array3, step_end: array3, gates: array3, record_previous: array3,
        arrival: wp.array3d(dtype=wp.float64), arrival_error: wp.array3d(dtype=wp.float64),
        strength: wp.array3d(dtype=wp.float64), yield_time: wp.array2d(dtype=wp.float64), record: array4,
        result: wp.array2d(dtype=wp.float64), coeff_table: wp.array(dtype=Coeffs), row_sums: array3,
    ):
        m, lane = wp.tid()
        st = member_states[m]
        p = params[m]
        n = state.shape[1]
        c = make_coeffs(p, n)
        c.lane = lane
        first_node, end_node = node_range(lane, lanes, n)
        c.first_node = first_node
        c.end_node = end_node
        t = st.t
        h = st.h
        g = ft(h * wp.float64(0.29))
        delta0 = ft(st.delta0)
        tilt = ft(st.tilt)
        s1 = st.fsal
        s2 = (s1 + 1) % 3
        s3 = (s1 + 2) % 3
        out = wp.float64(0.0)
        if wp.static(code == 1):  # rows_table
            for i in range(first_node, end_node):
                ci = coeff_table[m]
                ci.lane = lane
                ci.first_node = first_node
                ci.end_node = end_node
                row = node_row(ci, settings, m, n, work, gates, i, work[0, wp.max(i - 1, 0), m], work[0, i, m],
                               work[0, wp.min(i + 1, n - 1), m], delta0, tilt, ft(p.disc_velocity), g)
                row_sums[0, i, m] = (row.residual + row.jac_left + row.jac_center + row.jac_right + row.col_delta0
                                     + row.col_tilt + row.e1 + row.e2 + row.d11 + row.d12 + row.d21 + row.d22
                                     + row.c1_left + row.c1_center + row.c1_right + row.c2_left + row.c2_center
                                     + row.c2_right + row.kink)
        elif wp.static(code == 8):  # start
            out = wp.float64(c.MH + c.M_over_H + c.lam + c.G + c.two_G_over_H + c.rhoH + c.damping + c.kif + c.Kh
                             + c.inv_hardness + c.eta_vstar + c.vstar + c.inv_vstar + c.b + c.phi0 + c.inv_phi0
                             + c.inv_D + c.tau_c + c.v0 + c.dx + c.inv_dx + c.L + c.h_arm + c.tau_scale + c.u_scale
                             + c.v_scale + c.phi_scale + c.delta_scale + c.tilt_scale + g + delta0 + tilt)
            out += wp.float64(s1 + s2 + s3)
        elif wp.static(code == 0):  # rows
            total = ft(0.0)
            for i in range(first_node, end_node):
                row = node_row(c, settings, m, n, work, gates, i, work[0, wp.max(i - 1, 0), m], work[0, i, m],
                               work[0, wp.min(i + 1, n - 1), m], delta0, tilt, ft(p.disc_velocity), g)
                total += (row.residual + row.jac_left + row.jac_center + row.jac_right + row.col_delta0
                          + row.col_tilt + row.e1 + row.e2 + row.d11 + row.d12 + row.d21 + row.d22 + row.c1_left
                          + row.c1_center + row.c1_right + row.c2_left + row.c2_center + row.c2_right + row.kink)
            out = wp.float64(total)
        elif wp.static(code == 2):  # newton
            ok, d0, a, iters, bad, curvature = newton_solve(c, p, settings, m, n, work, gates, step_end, g, t + h, t,
                                                            delta0, tilt, ft(st.newton_curvature))
            out = wp.float64(d0 + a + curvature) + wp.float64(ok + iters + bad)
        elif wp.static(code == 3 or code == 4):  # derivatives, derivatives_mid
            sums, test = stage_derivatives(c, p, settings, m, n, work, gates, step_end, K, s3, g, t + h, t, delta0,
                                           tilt, ft(h), wp.static(1 if code == 3 else 0))
            out = wp.float64(sums.friction + sums.normal + sums.min_normal) + wp.float64(test.error)
        else:  # step, accept
            res = implicit_step(c, p, settings, m, n, state, K, work, gates, step_end, s1, s2, s3, t, h, t + h,
                                delta0, tilt, st.restart, ft(st.newton_curvature))
            out = res.error + wp.float64(res.delta0)
            if wp.static(code == 6):
                step = Step()
                step.h = h
                step.t_new = t + h
                st = accept_step(c, p, st, settings, outputs, m, n, state, K, work, step_end, gates, s1, s2, s3, t,
                                 step, wp.float64(1.0), res, st.restart, yield_time, arrival, arrival_error, strength,
                                 record_times, record_previous, record)
                out += st.mu_s
        result[m, lane] = out

    return stage_piece


def res_usage(kernel, lanes: int, arch: int) -> tuple:
    """(registers, stack bytes) of the kernel compiled for sm_<arch> with blocks of ``lanes``."""
    kernel.module.options["block_dim"] = lanes
    cubin = str(wp.compile_aot_module(kernel.module, arch=arch, use_ptx=False,
                                      module_dir=os.path.join(wp.config.kernel_cache_dir, "stage_registers"))[0])
    usage = subprocess.run([tool("cuobjdump"), "-res-usage", cubin], capture_output=True, text=True,
                           check=True).stdout
    return parse_res_usage(usage, cubin)


def parse_res_usage(usage: str, where: str = "the cubin") -> tuple:
    """(registers, stack bytes) of the kernel in cuobjdump -res-usage's text ``usage``: the entry
    with the most registers (the kernel; functions kept out of line have their own entries)."""
    found = RES_USAGE.findall(usage)
    if not found:
        raise RuntimeError(f"no REG/STACK line in cuobjdump -res-usage of {where}:\n{usage}")
    return max((int(r), int(s)) for r, s in found)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nodes", type=int, default=200, help="only for the record: the code does not depend on N")
    ap.add_argument("--lanes", type=int, nargs="+", default=[32, 64])
    ap.add_argument("--caps", type=int, nargs="+", default=[255, 200, 168, 128])
    ap.add_argument("--pieces", nargs="+", default=list(PIECES), choices=PIECES)
    ap.add_argument("--relaxation-gate", default="stress")
    ap.add_argument("--arch", type=int, default=90)
    args = ap.parse_args(argv)
    wp.config.quiet = True
    wp.init()
    model = wf.Model(relaxation_gate=args.relaxation_gate)
    print(f"sm_{args.arch}, default solver, relaxation_gate={args.relaxation_gate!r}: registers / stack bytes "
          f"per thread")
    print(f"{'piece':>12s} {'lanes':>5s} " + " ".join(f"{'cap ' + str(cap):>12s}" for cap in args.caps))
    for piece in args.pieces:
        for lanes in args.lanes:
            cells = []
            for cap in args.caps:
                registers, stack = res_usage(piece_kernel(piece, lanes, cap, model), lanes, args.arch)
                cells.append(f"{registers:>5d} / {stack:<5d}")
            print(f"{piece:>12s} {lanes:>5d} " + " ".join(f"{cell:>12s}" for cell in cells), flush=True)


if __name__ == "__main__":
    main()
