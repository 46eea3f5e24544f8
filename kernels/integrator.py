"""Batched implicit adaptive time integration of the pad model: one Warp thread per member, or a
team of threads per member (kernels/team.py).

The ``integrate`` kernel is a loop of attempted steps, each: the controller proposes a step
(kernels/controller.py), the stepper attempts it (kernels/esdirk.py: TR-BDF2 or, with
Solver.method = 'esdirk4', ESDIRK4(3)6L[2]SA; backward Euler at a (re)start; the stages solved by
kernels/newton.py on the model terms of kernels/model_terms.py), the stress gate may ask to retry it
up to a located switch (kernels/gates.py), and an accepted step (``accept_step``) advances the
state, updates the gates and calls the observers (kernels/observers.py: mu_s, fronts, recording).
``make_stages`` builds the device functions stage by stage; ``make_acceptance``,
``make_integrate_kernel`` and ``make_field_kernel`` build on them. Arrays and structs:
kernels/types.py. Scheme and choices: docs/model.md, "Time integration" and "Gate switches".
"""

import os
from typing import NamedTuple

import warp as wp

from .controller import Step, accepted_step_size, out_of_steps, propose_step, reject, stalled, step_factor_for
from .esdirk import make_esdirk
from .gates import make_gates
from .model_terms import disc_velocity_at, make_model_terms
from .newton import make_newton
from .observers import ObserverSet, latch_detachment_end, make_observers, run_finished
from .team import (EXCHANGES, MAX_TEAM_LANES, TEAM_BUFFER_BYTES, WARP_SIZE, exchanges_by_value, make_team, node_range,
                   warps_team)
from .types import C_PHI, N_WORK, IntegratorState, MemberParams, OutputSettings, SolverSettings, stage_slots

_CACHE: dict = {}


class TeamCompileOptions(NamedTuple):
    """Benchmark switches of the cooperative kernel's compilation (docs/performance.md, "GPU: where
    the time goes"); the defaults are the compiler's own choices."""

    max_registers: int | None = None  # registers per thread (None: the compiler's, 255 on the H100)
    inline: str | None = None  # 'force' or 'never': inline every device function of the integrator, or none
    smem_spilling: bool = False  # let CUDA 13 spill registers to shared memory
    out_of_line: tuple = ()  # names of device functions kept out of line
    exchange: str | None = None  # the team's lane exchange, kernels/team.py (None: the automatic choice)
    block_members: int | None = None  # members per thread block (None: per run, block_members_for; 1: a block each)
    shared_work: bool = True  # the work array in shared memory where it fits (team_layout: blocked kernel, wide teams)
    poison_shared_work: bool = False  # a check: the shared work array filled with NaN at each launch's start
    shared_pad: int = 0  # bytes of shared memory reserved beyond the work array (a probe of the L1 it leaves)


def team_compile_options() -> TeamCompileOptions:
    """The benchmark switches from the environment: WARPFRIC_TEAM_MAX_REGISTERS (an integer > 0),
    WARPFRIC_INLINE ('force' or 'never'), WARPFRIC_TEAM_SMEM_SPILLING (1), WARPFRIC_NOINLINE
    (comma-separated function names), WARPFRIC_TEAM_EXCHANGE ('tile', 'shuffle' or 'emulated':
    kernels/team.py), WARPFRIC_TEAM_BLOCK_MEMBERS (1 to 8: members per thread block,
    blocked_layout; at most shared_work_members where the work is in shared memory),
    WARPFRIC_TEAM_SHARED_WORK (0: the team kernel's work array in global memory; team_layout) and
    WARPFRIC_TEAM_POISON_SHARED_WORK (1: that shared array filled with NaN at the start of every
    launch, so that a value read before the attempt wrote it shows; a check, not for runs) and
    WARPFRIC_TEAM_SHARED_PAD (bytes, a multiple of 8: that much more shared memory reserved beside
    the shared work array, unused; a probe of how the L1 left to the SM matters)."""
    registers = int(os.environ.get("WARPFRIC_TEAM_MAX_REGISTERS", "0"))
    inline = os.environ.get("WARPFRIC_INLINE", "") or None
    if inline not in (None, "force", "never"):
        raise ValueError(f"WARPFRIC_INLINE={inline!r} is invalid; valid: 'force', 'never' or unset")
    out_of_line = tuple(sorted(name for name in os.environ.get("WARPFRIC_NOINLINE", "").split(",") if name))
    exchange = os.environ.get("WARPFRIC_TEAM_EXCHANGE", "") or None
    if exchange not in (None,) + EXCHANGES:
        raise ValueError(f"WARPFRIC_TEAM_EXCHANGE={exchange!r} is invalid; valid: {', '.join(EXCHANGES)} or unset")
    block_members = os.environ.get("WARPFRIC_TEAM_BLOCK_MEMBERS", "") or None
    if block_members is not None:
        if not block_members.isdigit() or not 1 <= int(block_members) <= MAX_BLOCK_MEMBERS:
            raise ValueError(f"WARPFRIC_TEAM_BLOCK_MEMBERS={block_members!r} is invalid; valid: an integer from 1 to "
                             f"{MAX_BLOCK_MEMBERS}, or unset")
        block_members = int(block_members)
    shared_work = os.environ.get("WARPFRIC_TEAM_SHARED_WORK", "") or "1"
    if shared_work not in ("0", "1"):
        raise ValueError(f"WARPFRIC_TEAM_SHARED_WORK={shared_work!r} is invalid; valid: 0, 1 or unset")
    poison = os.environ.get("WARPFRIC_TEAM_POISON_SHARED_WORK", "") or "0"
    if poison not in ("0", "1"):
        raise ValueError(f"WARPFRIC_TEAM_POISON_SHARED_WORK={poison!r} is invalid; valid: 0, 1 or unset")
    pad = os.environ.get("WARPFRIC_TEAM_SHARED_PAD", "") or "0"
    if not pad.isdigit() or int(pad) % 8:
        raise ValueError(f"WARPFRIC_TEAM_SHARED_PAD={pad!r} is invalid; valid: a multiple of 8 bytes >= 0, or unset")
    return TeamCompileOptions(max_registers=registers if registers > 0 else None, inline=inline,
                              smem_spilling=os.environ.get("WARPFRIC_TEAM_SMEM_SPILLING", "0") == "1",
                              out_of_line=out_of_line, exchange=exchange, block_members=block_members,
                              shared_work=shared_work == "1", poison_shared_work=poison == "1",
                              shared_pad=int(pad))


# Where a team's lanes exchange by warp shuffles (a team of at most 32 lanes: one warp), a thread
# block of the team kernel has MAX_BLOCK_MEMBERS warps, one member each (the warp's threads beyond
# the team's lanes idle), and a run puts block_members_for(...) members into each block; they wait
# for each other at the start of every attempt, so that an SM's warps run the same code at the
# same time and its instruction cache serves them all (docs/performance.md, "Members in step").
# 8: the registers of one SM hold 8 warps of this kernel (255 registers per thread), so one block
# fills an SM as 8 blocks of one member did.
MAX_BLOCK_MEMBERS = 8


def blocked_layout(lanes: int, exchange: str, requested: int | None = None) -> bool:
    """Whether the team kernel of ``lanes`` lanes with its lane exchange runs blocks of several
    members: teams that exchange by warp shuffles, unless WARPFRIC_TEAM_BLOCK_MEMBERS (``requested``)
    is 1 (tiles and the emulated exchange span their block: one member each)."""
    warp_team = exchange == "shuffle" and 2 <= lanes <= WARP_SIZE
    if requested is not None and requested > 1 and not warp_team:
        raise ValueError(f"WARPFRIC_TEAM_BLOCK_MEMBERS={requested} needs teams that exchange by warp shuffles "
                         f"(at most {WARP_SIZE} lanes); got {lanes} lanes, exchange {exchange!r}; valid here: 1, "
                         f"or unset")
    return warp_team and requested != 1


def block_members_for(n_members: int, sm_count: int, requested: int | None = None,
                      most: int = MAX_BLOCK_MEMBERS) -> int:
    """Members per block of a run of n_members in the blocked layout on a GPU of sm_count SMs:
    ``requested`` (WARPFRIC_TEAM_BLOCK_MEMBERS), else min(most, ceil(n_members / sm_count)): the
    blocks then number at most the SMs while members are few (one member alone on an SM runs faster
    than eight sharing it), and an SM's eight warps are one block's beyond. ``most``: the most a
    block holds (MAX_BLOCK_MEMBERS, or shared_work_members); a request above it gets it."""
    if requested is not None:
        return min(requested, most)
    return max(1, min(most, -(-n_members // max(sm_count, 1))))


# The blocked kernel's work array (kernels/types.py: the scratch of one attempted step, nothing in it
# outlives the attempt) is kept in the block's shared memory where it fits (docs/performance.md,
# "The work array in shared memory"): (N_WORK = 13, N, stride) float64, member fastest, with an odd
# member stride >= the block's members, so that the lanes of a warp, each on its own nodes, fall
# into different banks (at most two lanes a bank at N = 200 and N = 40). Every stride gives the
# same outputs bit for bit (tests/test_team.py); the global work array's do not: the compiler
# fuses a few multiply-adds differently (round-off, within 2e-12 of mu_s on the H100). What a step
# leaves for its error norm and acceptance, read once per node, is in ``step_end`` and ``gates``
# (kernels/types.py), so that 8 members' work fits at N = 200 in 187 KB, which leaves the SM 60 KB
# of L1 (the shared-memory carve-out of 196 KB).
SHARED_WORK_RESERVE = 4096  # bytes of a block's opt-in shared memory left to the kernel's static shared memory


def shared_work_stride(n_nodes: int, block_members: int, max_shared: int) -> int:
    """The member stride of a block's shared work array: the smallest odd number >= block_members,
    or 0 where (N_WORK, n_nodes, stride) float64 does not fit into max_shared bytes (the device's
    opt-in shared memory per block) less SHARED_WORK_RESERVE."""
    stride = block_members | 1
    return stride if N_WORK * n_nodes * stride * 8 <= max_shared - SHARED_WORK_RESERVE else 0


def shared_work_members(n_nodes: int, max_shared: int) -> int:
    """The most members of a block whose work is in shared memory: MAX_BLOCK_MEMBERS (8) where the
    stride 9 fits (N <= 243 on the H100), 7 where only 7 does (a member fewer per block: 243 < N <=
    313), else 0: the work stays in global memory (N > 313). Fewer members per block than 7 were not
    measured, so they are not chosen."""
    if shared_work_stride(n_nodes, MAX_BLOCK_MEMBERS, max_shared):
        return MAX_BLOCK_MEMBERS
    if shared_work_stride(n_nodes, MAX_BLOCK_MEMBERS - 1, max_shared):
        return MAX_BLOCK_MEMBERS - 1
    return 0


class TeamLayout(NamedTuple):
    """How a run's members map onto the cooperative kernel's blocks (team_layout)."""

    blocked: bool  # several members per block, a warp each (blocked_layout)
    block_members: int  # members per block (1 unless blocked)
    shared_work: tuple | None  # (nodes, member stride) of the work array in shared memory; None: global memory


def team_layout(lanes: int, n_nodes: int, n_members: int, cuda: bool, sm_count: int = 1,
                max_shared: int = 0) -> TeamLayout:
    """The layout of a run of n_members at n_nodes with ``lanes`` lanes per member on a CUDA device of
    sm_count SMs and max_shared bytes of opt-in shared memory per block, or the CPU (cuda False).
    The work array goes into shared memory wherever the blocked kernel runs and a block of 7
    members' work fits (shared_work_members), whatever n_members: a member's outputs then do not
    depend on the ensemble it runs in; and for a team of several warps (one member a block,
    kernels/team.py make_warps_team) wherever its member's work fits beside the team buffer. Not
    with Warp's debug mode, whose bounds checks reject the shared view's indexing by member
    (make_integrate_kernel), nor with WARPFRIC_TEAM_SHARED_WORK=0. The thread-per-member kernel
    (lanes 1) reads none of the team's switches."""
    if lanes <= 1:
        return TeamLayout(False, 1, None)
    options = team_compile_options()
    exchange = team_exchange(lanes, cuda, options.exchange)
    shared_allowed = options.shared_work and wp.config.mode != "debug"
    if not blocked_layout(lanes, exchange, options.block_members):
        if (shared_allowed and warps_team(lanes, exchange)
                and shared_work_stride(n_nodes, 1, max_shared - TEAM_BUFFER_BYTES)):  # one member beside the team buffer
            return _padded(TeamLayout(False, 1, (n_nodes, 1)), options.shared_pad, max_shared - TEAM_BUFFER_BYTES)
        return TeamLayout(False, 1, None)
    most = 0
    if shared_allowed:
        most = shared_work_members(n_nodes, max_shared)
    block_members = block_members_for(n_members, sm_count, options.block_members, most or MAX_BLOCK_MEMBERS)
    if not most:
        return TeamLayout(True, block_members, None)
    return _padded(TeamLayout(True, block_members, (n_nodes, shared_work_stride(n_nodes, block_members, max_shared))),
                   options.shared_pad, max_shared)


def _padded(layout: TeamLayout, pad: int, max_shared: int) -> TeamLayout:
    """layout, where the probe WARPFRIC_TEAM_SHARED_PAD (``pad`` bytes) fits beside its shared work
    array in max_shared bytes less SHARED_WORK_RESERVE; a ValueError naming the room otherwise."""
    nodes, stride = layout.shared_work
    room = max_shared - SHARED_WORK_RESERVE - N_WORK * nodes * stride * 8
    if pad > room:
        raise ValueError(f"WARPFRIC_TEAM_SHARED_PAD={pad} does not fit beside the shared work array of this run: "
                         f"at most {room} bytes here")
    return layout


@wp.func_native(r"""
#if defined(__CUDA_ARCH__)
    extern __shared__ char wf_dynamic_shared[];
    return (uint64_t)(wf_dynamic_shared);
#else
    return 0;
#endif
""")
def dynamic_shared_base() -> wp.uint64:
    """The address of the block's dynamic shared memory, where Warp puts the kernel's first shared
    tile (kernels/integrator.py make_integrate_kernel: the reservation of the shared work array)."""
    ...


def block_threads(lanes: int, blocked: bool) -> int:
    """Threads per block of the team kernel (its launches and its launch bounds): the team's lanes,
    or in the blocked layout a warp for each of MAX_BLOCK_MEMBERS members."""
    return WARP_SIZE * MAX_BLOCK_MEMBERS if blocked else lanes


def team_exchange(lanes: int, cuda: bool, requested: str | None = None) -> str:
    """The lane exchange of a team of ``lanes`` on a CUDA device (cuda) or the CPU: ``requested``
    (WARPFRIC_TEAM_EXCHANGE), else warp shuffles on a GPU for a team of one warp (<= 32 lanes) and
    Warp's tiles otherwise (docs/performance.md, "Warp shuffles")."""
    by_value = exchanges_by_value(lanes)
    if requested is None:
        return "shuffle" if cuda and by_value else "tile"
    if requested == "shuffle" and not (cuda and by_value):
        raise ValueError(f"WARPFRIC_TEAM_EXCHANGE='shuffle' needs a CUDA device and at most {WARP_SIZE} lanes or a "
                         f"multiple of {WARP_SIZE} up to {MAX_TEAM_LANES}; got {'a CUDA device' if cuda else 'the CPU'} "
                         f"and {lanes} lanes")
    if requested == "emulated" and not by_value:
        raise ValueError(f"WARPFRIC_TEAM_EXCHANGE='emulated' needs at most {WARP_SIZE} lanes or a multiple of "
                         f"{WARP_SIZE} up to {MAX_TEAM_LANES}; got {lanes}")
    return requested


def device_functions(kernel) -> list:
    """Every user device function (wp.func) the kernel calls, directly or through other functions
    (closures and module globals), as Warp Function objects."""
    found, stack = {}, [kernel.func]  # id -> Function, in the order found
    while stack:
        py = stack.pop()
        refs = [cell.cell_contents for cell in (py.__closure__ or ()) if _filled(cell)]
        refs += [py.__globals__.get(name) for name in py.__code__.co_names]
        for ref in refs:
            if isinstance(ref, wp.Function) and not ref.is_builtin() and ref.func is not None and id(ref) not in found:
                found[id(ref)] = ref
                stack.append(ref.func)
    return list(found.values())


def _filled(cell) -> bool:
    try:
        cell.cell_contents
    except ValueError:
        return False
    return True


def get_integrator(dtype: str, model, lanes: int = 1, method: str = "tr_bdf2", cuda: bool = False,
                   observed: ObserverSet = ObserverSet(), shared_work: tuple | None = None) -> dict:
    """Compiled kernels for one working precision, one set of model switches, one team size
    (lanes = 1: one thread per member; > 1: the cooperative kernel, float64 only, launched with
    block_threads; kernels/team.py), one time integrator (Solver.method: 'tr_bdf2' or 'esdirk4'),
    the kind of device they run on (cuda: a team's lane exchange, team_exchange), the observers
    compiled in (kernels/observers.py ObserverSet; all by default) and, for the blocked kernel, the
    work array in shared memory (shared_work: (nodes, member stride), team_layout; None: in global
    memory) (cached)."""
    if method not in ("tr_bdf2", "esdirk4"):
        raise ValueError(f"integrator method {method!r} is invalid; valid: 'tr_bdf2' or 'esdirk4'")
    options = team_compile_options() if lanes > 1 else TeamCompileOptions()
    if lanes > 1:
        options = options._replace(exchange=team_exchange(lanes, cuda, options.exchange))
    key = (dtype, model, lanes, method, options, observed, shared_work)
    if key not in _CACHE:
        _CACHE[key] = _make_integrator(dtype, model, lanes, method, options, observed, shared_work)
    # on every call, cached kernels included: Warp compiles a kernel at its first launch, with the
    # hints the functions have then
    _apply_inline_hints(_CACHE[key]["integrate"], options.inline, options.out_of_line)
    return _CACHE[key]


# device functions whose inline hint a benchmark switch changed, with the hint they had before:
# shared functions (module-level ones such as team.settle) serve every kernel, so each
# get_integrator call first undoes the hints of the one before (the switches apply to the kernels
# asked for while they are set)
_HINTED: dict = {}


def _set_hint(fn, hint) -> None:
    fn.inline_hint = hint
    for overload in fn.user_overloads.values():
        overload.inline_hint = hint


def _apply_inline_hints(kernel, inline, out_of_line) -> None:
    """Undo the previous build's benchmark hints, then set this build's (team_compile_options)."""
    for fn, hint in _HINTED.values():
        _set_hint(fn, hint)
    _HINTED.clear()
    if inline is None and not out_of_line:
        return
    for fn in device_functions(kernel):
        hint = None
        if inline is not None:
            hint = "forceinline" if inline == "force" else "noinline"
        if fn.func.__name__ in out_of_line:
            hint = "noinline"
        if hint is not None:
            _HINTED[id(fn)] = (fn, fn.inline_hint)
            _set_hint(fn, hint)


def make_stages(ft, model, lanes: int = 1, method: str = "tr_bdf2", exchange: str = "tile",
                observed: ObserverSet = ObserverSet()) -> dict:
    """Every device function of the integrator for scalar type ``ft``, ``model``, a team of
    ``lanes`` threads per member with its lane exchange (kernels/team.py), an integrator method and
    the observers compiled in, by stage."""
    team = make_team(ft, lanes, exchange)
    terms = make_model_terms(ft, model)
    gates = make_gates(ft, model, terms, team)
    newton = make_newton(ft, model, terms, gates, team, method)
    esdirk = make_esdirk(ft, model, terms, newton, gates, team, method)
    observers = make_observers(ft, model, terms, team, method, observed)
    return dict(team=team, terms=terms, gates=gates, newton=newton, esdirk=esdirk, observers=observers)


def _make_integrator(dtype: str, model, lanes: int, method: str = "tr_bdf2", options=TeamCompileOptions(),
                     observed: ObserverSet = ObserverSet(), shared_work: tuple | None = None):
    """The integrate and evaluate_fields kernels, and the layout kernels of the state's transfers
    (make_layout_kernels), for one working precision, model, team size, method and observer set
    (get_integrator caches them)."""
    ft = wp.float64 if dtype == "float64" else wp.float32
    stages = make_stages(ft, model, lanes, method, options.exchange or "tile", observed)
    acceptance = make_acceptance(ft, model, method, stages)
    blocked = lanes > 1 and blocked_layout(lanes, options.exchange, options.block_members)
    if shared_work is not None and not (blocked or warps_team(lanes, options.exchange)):
        raise ValueError(f"shared_work={shared_work} needs the blocked layout of the team kernel or a team of several "
                         f"warps (team_layout)")
    integrate = make_integrate_kernel(ft, model, lanes, method, stages, acceptance, options, blocked, shared_work)
    evaluate_fields = make_field_kernel(ft, stages)
    return dict(integrate=integrate, evaluate_fields=evaluate_fields, ft=ft, stages=stages,
                layout=make_layout_kernels(ft),
                exchange=(options.exchange or "tile") if lanes > 1 else "none",
                blocked=blocked, shared_work=shared_work)


def make_acceptance(ft, model, method, stages):
    """accept_step: what follows an accepted step in the integrate kernel (advance, gates, step
    size, observers)."""
    esdirk4 = method == "esdirk4"
    stress_gate = model.relaxation_gate == "stress"
    terms, gates, esdirk, observers = stages["terms"], stages["gates"], stages["esdirk"], stages["observers"]
    Coeffs = terms["Coeffs"]
    StepResult = esdirk["StepResult"]
    advance_state = esdirk["advance_state"]
    advance_state4 = esdirk.get("advance_state4", advance_state)
    switch_gates = gates["switch_gates"]
    after_accept = gates["after_accept"]
    drop_stale_limit = gates["drop_stale_limit"]
    on_accept = observers["on_accept"]
    array3 = wp.array3d(dtype=ft)
    array4 = wp.array4d(dtype=ft)

    @wp.func
    def accept_step(
        c: Coeffs, p: MemberParams, st: IntegratorState, settings: SolverSettings, outputs: OutputSettings, m: int,
        n: int, state: array3, K: array4, work: array3, step_end: array3, gates: array3, s1: int, s2: int, s3: int,
        t: wp.float64, step: Step, factor: wp.float64, res: StepResult, restart: int, yield_time: wp.array2d(dtype=wp.float64),
        arrival: wp.array3d(dtype=wp.float64), arrival_error: wp.array3d(dtype=wp.float64),
        strength: wp.array3d(dtype=wp.float64), record_times: wp.array(dtype=wp.float64), record_previous: array3,
        record: array4,
    ):
        """The step from t to step.t_new was accepted (res: its StepResult, factor: the step-size
        factor of its error, restart: 1 for a backward-Euler (re)start): advance the state, switch
        the gates, set the next step size and the FSAL slot s3, and run the observers. Returns st."""
        if wp.static(esdirk4):
            if restart != 0:
                advance_state(c, m, n, state, K, work, s3, ft(step.h), restart)
            else:
                advance_state4(c, m, n, state, K, s1, ft(step.h))
        else:
            advance_state(c, m, n, state, K, work, s3, ft(step.h), restart)
        if wp.static(stress_gate):
            switches_before = st.gate_switches
            st = switch_gates(c, p, st, outputs, m, n, state, K, s3, gates, t, step.t_new, restart, yield_time,
                              arrival, arrival_error)
            if restart == 0:
                st = after_accept(st, settings, switches_before, res.switch_test, step.t_new, step.clipped)
        delta0 = res.delta0
        tilt = res.tilt
        if restart != 0:
            st.restart = 0
            st.h = settings.initial_step
        else:
            st.h = accepted_step_size(st, step, factor)
        st.fsal = s3
        st = on_accept(c, p, st, outputs, m, n, state, K, step_end, s1, s2, s3, t, step.t_new, delta0, tilt,
                       res.sums.friction, res.sums.normal, res.sums.min_normal, restart, arrival, arrival_error,
                       strength, record_times, record_previous, record)
        if wp.static(stress_gate):
            st = drop_stale_limit(st, step.t_new)
        if st.restart != 0:
            st.h = settings.initial_step  # the step ended on the sudden stop: restart
        return st

    return dict(accept_step=accept_step)


def make_integrate_kernel(ft, model, lanes: int, method, stages, acceptance, options=TeamCompileOptions(),
                          blocked: bool = False, shared_work: tuple | None = None):
    """The integrate kernel: the loop of attempted steps (stepper, controller, accept_step); blocked:
    the team kernel's blocked layout (blocked_layout); shared_work: (nodes, member stride) of the
    work array in the block's shared memory (team_layout; the kernel's ``work`` argument is then
    not used), None: in global memory."""
    team_on = lanes > 1
    esdirk4 = method == "esdirk4"
    n_slots = stage_slots(method)
    step_factor = step_factor_for(method)
    stress_gate = model.relaxation_gate == "stress"
    make_coeffs = stages["terms"]["make_coeffs"]
    contact_velocity_scale = stages["terms"]["contact_velocity_scale"]
    esdirk = stages["esdirk"]
    implicit_step = esdirk["implicit_step"]
    esdirk4_step = esdirk.get("esdirk4_step", implicit_step)
    locate_switch = stages["gates"]["locate_switch"]
    accept_step = acceptance["accept_step"]
    array3 = wp.array3d(dtype=ft)
    array4 = wp.array4d(dtype=ft)
    block_barrier = stages["team"].get("block_barrier", None)
    team_barrier = stages["team"]["barrier"]
    shared_on = shared_work is not None
    shared_nodes, shared_stride = shared_work if shared_on else (1, 1)
    shared_len = N_WORK * shared_nodes * shared_stride
    reserved_len = shared_len + options.shared_pad // 8
    poison_on = shared_on and options.poison_shared_work
    threads = block_threads(lanes, blocked)

    # enable_backward=False: no adjoint code is generated (nothing differentiates through the
    # integrator); the forward code is the same, and the first compile takes a third of the time
    # (CPU, default law: 13.2 s -> 4.7 s)
    # the benchmark switches (team_compile_options): shared-memory spilling needs launch bounds
    # instead of a register cap
    if options.smem_spilling:  # the launch bounds: the threads of a block (engine.py)
        limits = dict(enable_cuda_smem_spilling=True, launch_bounds=threads)
    else:
        limits = dict(cuda_max_registers=options.max_registers)

    @wp.kernel(module="unique", enable_backward=False, **limits)
    def integrate(
        # inputs
        params: wp.array(dtype=MemberParams),
        settings: SolverSettings,
        outputs: OutputSettings,
        launch_steps: int,
        block_members: int,
        stall_limit: wp.array(dtype=wp.int32),
        record_times: wp.array(dtype=wp.float64),
        # state, read and written (persists between launches)
        member_states: wp.array(dtype=IntegratorState),
        state: array3,
        K: array4,
        work: array3,
        step_end: array3,
        gates: array3,
        record_previous: array3,
        # outputs
        arrival: wp.array3d(dtype=wp.float64),
        arrival_error: wp.array3d(dtype=wp.float64),
        strength: wp.array3d(dtype=wp.float64),
        yield_time: wp.array2d(dtype=wp.float64),
        record: array4,
    ):
        """Advance each member by at most ``launch_steps`` attempted steps (or to its end, or until its
        attempts exceed stall_limit[0]).
        Shapes and units: kernels/types.py. A team: every lane keeps the same IntegratorState; every
        lane stores it before the stage code of an attempt and reads it back after, and lane 0
        stores it at the end."""
        if wp.static(shared_on):  # the first tile: reserves the block's dynamic shared memory for the work view below
            wp.tile_empty(shape=(reserved_len,), dtype=ft, storage="shared")
        if wp.static(poison_on):  # the check WARPFRIC_TEAM_POISON_SHARED_WORK: all of it NaN, by every thread
            _poison_block, poison_thread = wp.tid()
            reserved = wp.array(ptr=dynamic_shared_base(), shape=(shared_len,), dtype=ft)
            for k in range(poison_thread, shared_len, threads):
                reserved[k] = ft(wp.nan)
            block_barrier()
        lane = int(0)
        m = int(0)
        work_view = work
        if wp.static(team_on):
            block, thread = wp.tid()
            if wp.static(blocked):
                # block_members members per block, a warp each, in step at every attempt (blocked_layout);
                # the block's other warps and a warp's threads beyond the team's lanes have nothing to do
                warp = thread // WARP_SIZE
                m = block * block_members + warp
                lane = thread % WARP_SIZE
                if warp >= block_members or m >= member_states.shape[0] or lane >= lanes:
                    return
                if wp.static(shared_on):
                    # (N_WORK, N, stride), member fastest, indexed by the member m as ``work`` is: the
                    # base is offset by the block's first member (no bounds check: Warp's release mode)
                    first = wp.uint64(block * block_members) * wp.uint64(8)
                    work_view = wp.array(ptr=dynamic_shared_base() - first, shape=(N_WORK, shared_nodes, shared_stride),
                                         dtype=ft)
            else:
                m = block
                lane = thread
                if wp.static(shared_on):  # a team of several warps: its member's work, stride 1, indexed by m
                    work_view = wp.array(ptr=dynamic_shared_base() - wp.uint64(block) * wp.uint64(8),
                                         shape=(N_WORK, shared_nodes, shared_stride), dtype=ft)
        else:
            m = wp.tid()
        st = member_states[m]
        if st.done != 0:
            return
        p = params[m]
        n = state.shape[1]
        c = make_coeffs(p, n)
        if wp.static(team_on):
            c.lane = lane
            first_node, end_node = node_range(lane, lanes, n)
            c.first_node = first_node
            c.end_node = end_node
        delta0 = ft(st.delta0)
        tilt = ft(st.tilt)
        attempt_limit = stall_limit[0]
        for _attempt in range(launch_steps):
            if wp.static(blocked):
                block_barrier()
            st = latch_detachment_end(p, st, outputs)
            if run_finished(p, st, outputs):
                st.done = 1
                break
            st = out_of_steps(st, settings)
            st = stalled(st, attempt_limit)
            if st.done != 0:
                break
            t = st.t
            step = propose_step(p, st, settings, t)
            c.v_scale_contact = contact_velocity_scale(c, p, settings.viscous_velocity_cap, step.t_new, t)
            s1 = st.fsal
            s2 = (s1 + 1) % n_slots
            s3 = (s1 + n_slots - 1) % n_slots  # the last stage's slot (TR-BDF2: s1 + 2; ESDIRK4: s1 + 5)
            restart = st.restart
            curvature_in = ft(st.newton_curvature)
            # The member state waits in global memory while the stage code runs, so that its fields
            # take no registers or stack there (a 1,128-byte stack per thread became 912 B: sm_90,
            # studies/sass_sites.py). Every lane stores the same values; the barrier first lets every
            # lane of the team read the last attempt's state back before it is overwritten.
            team_barrier()
            member_states[m] = st
            # ---- stepper ----
            if wp.static(esdirk4):
                if restart != 0:
                    res = implicit_step(c, p, settings, m, n, state, K, work_view, gates, step_end, s1, s2, s3, t, step.h,
                                        step.t_new, delta0, tilt, 1, ft(0.0))
                else:
                    res = esdirk4_step(c, p, settings, m, n, state, K, work_view, gates, step_end, s1, t, step.h, step.t_new,
                                       delta0, tilt)
            else:  # TR-BDF2, or backward Euler at a (re)start: one call, so the stage code is compiled once
                res = implicit_step(c, p, settings, m, n, state, K, work_view, gates, step_end, s1, s2, s3, t, step.h,
                                    step.t_new, delta0, tilt, restart, curvature_in)
            st = member_states[m]  # this lane's own store, or another lane's of the same values
            if wp.static(not esdirk4):
                # the next step's first Newton iteration is judged with this step's curvature
                # (kernels/newton.py newton_solve); a failed solve or a restart forgets it
                st.newton_curvature = wp.float64(0.0)
                if res.ok == 1 and restart == 0:
                    st.newton_curvature = wp.float64(res.newton_curvature)
            st.newton_iterations = st.newton_iterations + res.iterations
            # ---- controller ----
            if res.ok != 1:
                st.rejected_newton = st.rejected_newton + 1
                st = reject(st, settings, step.h * settings.failure_factor, res.non_finite)
                if st.done != 0:
                    break
                continue
            factor = step_factor(res.error, settings)
            if wp.static(stress_gate):
                if restart == 0 and res.error <= wp.float64(1.0):
                    st, retry = locate_switch(st, settings, t, step.h, res.switch_test)
                    if retry == 1:
                        continue
            if res.error > wp.float64(1.0):
                st.rejected_error_test = st.rejected_error_test + 1
                st = reject(st, settings, step.h * wp.min(factor, settings.step_safety), 0)
                if st.done != 0:
                    break
                continue
            # ---- accepted: advance, gates, observers ----
            st = accept_step(c, p, st, settings, outputs, m, n, state, K, work_view, step_end, gates, s1, s2, s3, t, step, factor, res,
                             restart, yield_time, arrival, arrival_error, strength, record_times, record_previous, record)
            delta0 = res.delta0
            tilt = res.tilt
        st.delta0 = wp.float64(delta0)
        st.tilt = wp.float64(tilt)
        team_barrier()  # every lane has read the state back (an attempt's read) before lane 0 stores the last
        if lane == 0:
            member_states[m] = st

    return integrate


_LAYOUT_KERNELS: dict = {}


def make_layout_kernels(ft):
    """The state's layout between host and device, done on the device so that the host touches
    each value once: ``initial_state`` (the pad at rest) and ``member_rows`` ((slot, node, member)
    -> (slot, member, node) copies, the Dataset's (member, x) order, with the members put back into
    the caller's order: warpfric/engine.py member_order). One set per scalar type, shared by every
    integrator of that type (cached), with the float64 ``member_columns``, which every type shares."""
    if ft in _LAYOUT_KERNELS:
        return _LAYOUT_KERNELS[ft]
    array3 = wp.array3d(dtype=ft)

    @wp.kernel(module="unique", enable_backward=False)
    def initial_state(initial_age: wp.array(dtype=wp.float64), state: array3):
        """The pad at rest: every component 0 but the contact age phi = initial_age[m] (s) at every
        node. state: (component, node, member), any layout."""
        comp, i, m = wp.tid()
        value = ft(0.0)
        if comp == C_PHI:
            value = ft(initial_age[m])
        state[comp, i, m] = value

    @wp.kernel(module="unique", enable_backward=False)
    def member_rows(source: array3, kernel_member: wp.array(dtype=wp.int32), rows: array3):
        """rows[k, m, i] = source[k, i, kernel_member[m]]: (slot, node, member) -> (slot, member, node),
        the caller's member m being the integrate kernel's member kernel_member[m]; launched over
        rows' shape, so a leading part of source's slots."""
        k, m, i = wp.tid()
        rows[k, m, i] = source[k, i, kernel_member[m]]

    _LAYOUT_KERNELS[ft] = dict(initial_state=initial_state, member_rows=member_rows, member_columns=member_columns,
                               member_states=start_member_states, member_params=fill_member_params)
    return _LAYOUT_KERNELS[ft]


@wp.kernel(module="unique", enable_backward=False)
def start_member_states(start: wp.array(dtype=IntegratorState), record_slot: wp.array(dtype=wp.int32),
                        front_level: wp.array(dtype=wp.float64), front_until: wp.array(dtype=wp.float64),
                        states: wp.array(dtype=IntegratorState)):
    """states[m] = start[0] (a member's state at t = 0, warpfric/engine.py initial_states) with member
    m's record_slot[m] and, where given ((member,) arrays; empty: none), its front_level[m] (m/s)
    and front_until[m] (s): the velocity front's arrival pass. The host builds one state, not
    (member,) of them (25 MB at 100,000 members)."""
    m = wp.tid()
    st = start[0]
    st.record_slot = record_slot[m]
    if front_level.shape[0] > 0:
        st.front_level = front_level[m]
        st.front_until = front_until[m]
    states[m] = st


@wp.kernel(module="unique", enable_backward=False)
def fill_member_params(first: wp.array(dtype=wp.float64), columns: wp.array2d(dtype=wp.float64),
                       fields: wp.array(dtype=wp.int32), rows: wp.array2d(dtype=wp.float64)):
    """The members' MemberParams, whose fields are all float64, viewed as rows (member, field):
    rows[m, f] = first[f] (a member's parameters), but columns[j, m] in the fields f = fields[j]
    that differ among the members (SI units, kernels/types.py). The host uploads only those columns."""
    m, f = wp.tid()
    value = first[f]
    for j in range(fields.shape[0]):
        if fields[j] == f:
            value = columns[j, m]
    rows[m, f] = value


@wp.kernel(module="unique", enable_backward=False)
def member_columns(source: wp.array2d(dtype=wp.float64), kernel_member: wp.array(dtype=wp.int32),
                   columns: wp.array2d(dtype=wp.float64)):
    """columns[i, m] = source[i, kernel_member[m]]: a (node, member) float64 output (the fronts'
    arrival times, the strength ratios) with the members put back into the caller's order."""
    i, m = wp.tid()
    columns[i, m] = source[i, kernel_member[m]]


def make_field_kernel(ft, stages):
    """The evaluate_fields kernel: the interface stresses of the current state."""
    make_coeffs = stages["terms"]["make_coeffs"]
    state_displacement = stages["observers"]["state_displacement"]
    state_contact = stages["observers"]["state_contact"]
    array3 = wp.array3d(dtype=ft)

    @wp.kernel(module="unique", enable_backward=False)
    def evaluate_fields(
        params: wp.array(dtype=MemberParams),
        member_states: wp.array(dtype=IntegratorState),
        state: array3,
        row_of: wp.array(dtype=wp.int32),
        normal_stress_out: wp.array2d(dtype=ft),
        friction_stress_out: wp.array2d(dtype=ft),
    ):
        """Interface normal stress (Pa, contact part max(sigma_n, 0)) and friction stress (Pa) of
        the current state of each member, (member, node): the Dataset's order, the kernel's member m
        in row row_of[m] (the caller's order: warpfric/engine.py member_order)."""
        m = wp.tid()
        row = row_of[m]
        st = member_states[m]
        p = params[m]
        n = state.shape[1]
        c = make_coeffs(p, n)
        delta0 = ft(st.delta0)
        tilt = ft(st.tilt)
        v_disc = ft(disc_velocity_at(p, st.t, st.t))
        u_l = ft(0.0)
        u_c = state_displacement(state, 0, n, m)
        for i in range(n):
            u_r = state_displacement(state, i + 1, n, m)
            ns, fr = state_contact(c, state, i, n, m, u_l, u_c, u_r, delta0, tilt, v_disc)
            normal_stress_out[row, i] = fr.contact * ns.value
            friction_stress_out[row, i] = fr.stress
            u_l = u_c
            u_c = u_r

    return evaluate_fields
