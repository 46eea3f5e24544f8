"""The engine behind ``simulate``: kernel-visible settings from the public ones, the device arrays,
the integration passes (launch, straggler rule, progress) and the read-back to NumPy.

One pass, unless the velocity front is asked for (docs/model.md, "Fronts"): the contact and strength
fronts are located inside the steps of the one pass; the velocity front needs the event maximum of
the detachment velocity before its arrival times are taken, so pass 1 integrates the whole protocol
(every other output, and that maximum) and pass 2 repeats the same deterministic trajectory up to the
last possible crossing (front_last of pass 1) and records the arrival times at the level that pass 1
found.
"""

from __future__ import annotations

import dataclasses
import itertools
import os
import threading
import time
import warnings

import numpy as np

from .parameters import Fronts, Model, Record, Solver
from .progress import Progress, building_note, end_time_attempts, launch_steps


@dataclasses.dataclass
class EngineResult:
    """What the passes produced, on the host. Shapes: member_states (member,); fields (component,
    member, node); normal_stress, friction_stress, yield_time, yield_gate (member, node) (the
    Dataset's order); arrival, arrival_error: {front event row (kernels/types.py EV_*): (node,
    member) s} for the events asked for, NaN where a node never arrived (a strength peak not
    confirmed by the end of the run included); strength_peak (node, member): each node's peak of
    tau_f/sigma_n; record (record_field, time, node, recorded); event (member,) bool: the velocity
    front's event was real."""

    member_states: np.ndarray
    fields: np.ndarray  # (component, member, node): the final state
    normal_stress: np.ndarray  # (member, node) Pa
    friction_stress: np.ndarray  # (member, node) Pa
    yield_time: np.ndarray | None  # (member, node) s
    yield_gate: np.ndarray | None  # (member, node)
    arrival: dict | None  # front event row (kernels/types.py EV_*) -> (node, member) s, the events asked for
    arrival_error: dict | None
    strength_peak: np.ndarray | None
    event: np.ndarray | None
    record: np.ndarray | None
    # compiling (or loading from Warp's cache) the integrator's modules and the fronts' segmentation
    # kernel, and the first import of the kernels' Python modules in a process, s
    kernel_build_s: float
    device_bytes_per_member: float  # device memory of the integration arrays per member, bytes (recorded
    # fields, the front segmentation and the read-back copies not included)
    lanes: int  # threads per member (1: the thread-per-member kernel; > 1: the cooperative kernel)
    team_exchange: str  # how a team's lanes exchange values (kernels/team.py; "none" for one lane)
    block_members: int  # members per thread block of the cooperative kernel, in step at each attempt (1: one)
    work_memory: str  # where the integrator's work array lives: "shared" (team kernels, where it fits) or "global"
    member_order: str  # the order the kernel ran the members in: "similar" (member_order) or "given" (the caller's)
    passes: int  # integration passes (2 with the velocity front, else 1)


# the cooperative kernel's largest one-warp team when Solver.lanes is None (docs/performance.md, "GPU:
# where the time goes", team size: on the H100 32 lanes beat 8, and 64 by tiles, at N = 200), and the fewest
# nodes for which it is chosen (a team of 8 lanes of 2 nodes); a run whose members' teams of several
# warps fit the GPU at once (WIDE_WARPS_PER_SM warps an SM) takes those, up to MAX_TEAM_LANES
# (docs/performance.md, "Teams of several warps": 96 lanes at N = 200, one member 0.047 -> 0.031 s,
# 264 members 0.092 -> 0.074 s; 528, two rounds of blocks, 0.108 against 0.105 s)
AUTO_LANES = 32
AUTO_MIN_NODES = 16
WIDE_WARPS_PER_SM = 8  # the warps an SM's registers hold at 255 registers a thread


# The blocked kernel's members wait for each other at every attempt (kernels/integrator.py,
# "Members in step"), so a block runs at the pace of its slowest member, attempt by attempt. Members
# with close parameters take nearly the same steps, so run() hands the kernel its members in an
# order where neighbours are alike (member_order) and puts the outputs back into the caller's
# order. A member's outputs do not depend on its block's other members: the order changes the
# time, not one bit of the results (docs/performance.md, "Similar members share a block").
# WARPFRIC_MEMBER_ORDER: "similar" (on any device; also the CPU's, where it only costs a copy) or
# "given" (the caller's order); unset: "similar" where the blocked kernel runs blocks of several
# members in at least SIMILAR_ORDER_MIN_WAVES blocks per SM. In one wave of blocks the run lasts as
# long as its slowest block, and alike members put the slowest together, where they share an SM's
# issue slots: 1,000 members (125 blocks on 132 SMs) took 0.164 s in the similar order against
# 0.144 s as drawn; 3,000 (2.8 blocks per SM) 0.344 against 0.358 s, 10,000 0.925 against 1.041 s
# (H100, studies/results/h100/member_order_8114533.jsonl).
MEMBER_ORDERS = ("similar", "given")
SIMILAR_ORDER_MIN_WAVES = 2
KEY_BITS = 64  # bits of a member's sort key: its Z-order cell, then its own number


def morton_key(coords: np.ndarray, bits: int) -> np.ndarray:
    """Z-order key (uint64) of points with coordinates coords (point, dim) in [0, 1]: each
    coordinate quantised to ``bits`` bits, the bits interleaved, the most significant first."""
    n_points, n_dims = coords.shape
    cells = np.minimum((coords * (1 << bits)).astype(np.uint64), np.uint64((1 << bits) - 1))
    key = np.zeros(n_points, dtype=np.uint64)
    for bit in range(bits - 1, -1, -1):
        for dim in range(n_dims):
            key = (key << np.uint64(1)) | ((cells[:, dim] >> np.uint64(bit)) & np.uint64(1))
    return key


def alike_blocks(layout, n_members: int, sm_count: int) -> bool:
    """Whether a run of n_members in ``layout`` (kernels/integrator.py TeamLayout) on a device of
    sm_count SMs gets the similar member order by default: blocks of several members, at least
    SIMILAR_ORDER_MIN_WAVES blocks per SM."""
    blocks = -(-n_members // layout.block_members)
    return layout.blocked and layout.block_members > 1 and blocks >= SIMILAR_ORDER_MIN_WAVES * sm_count


def alike(column) -> bool:
    """Whether a (member,) parameter column takes one value in every member (NaN: not alike)."""
    column = np.asarray(column)
    return column.size == 0 or bool(column.min() == column.max())


def member_order(values: dict, blocked: bool, requested: str | None = None) -> np.ndarray | None:
    """The order in which run() hands its members to the kernel (an index array), or None for the
    caller's order: ``requested`` (WARPFRIC_MEMBER_ORDER) or, unset, "similar" where ``blocked``
    (alike_blocks). "similar": the members sorted along a Z-order curve through the
    parameters that vary among them, each mapped to [0, 1] by the rank of its distinct values
    (equal values, equal coordinates; the spacing of the values does not matter), so that runs
    of consecutive members (a block's) lie close in every varied parameter; ties keep the caller's
    order."""
    requested = requested or None
    if requested is not None and requested not in MEMBER_ORDERS:
        raise ValueError(f"WARPFRIC_MEMBER_ORDER={requested!r} is invalid; valid: {', '.join(MEMBER_ORDERS)} or unset")
    if (requested or ("similar" if blocked else "given")) == "given":
        return None
    varied = []
    for name in sorted(values):
        column = np.asarray(values[name], dtype=np.float64)
        if column.size and alike(column):
            continue  # alike in every member (found without np.unique's sort: most columns of a run)
        distinct, rank = np.unique(column, return_inverse=True)
        if distinct.size > 1:
            varied.append(rank / (distinct.size - 1))
    if not varied:  # one member, or members alike in every parameter
        return None
    # the key: the Z-order cell in the high bits, the member's number in the low ones, so that every
    # key differs and numpy's fast unstable sort keeps ties in the caller's order (a stable sort of
    # 100,000 keys took 6 ms, this one 1 ms); bits enough for every distinct rank while the varied
    # parameters number at most 64 // index_bits - 1 (3 at 10,000 members, 2 at 100,000), fewer beyond
    n_members = varied[0].size
    index_bits = max(1, (n_members - 1).bit_length())
    varied = varied[:KEY_BITS - index_bits]
    bits = min((KEY_BITS - index_bits) // len(varied), index_bits)  # index_bits: every rank its own cell
    cell = morton_key(np.stack(varied, axis=1), bits)
    key = (cell << np.uint64(index_bits)) | np.arange(n_members, dtype=np.uint64)
    return np.argsort(key)


def choose_lanes(solver: Solver, device: str, members: int | None = None, sm_count: int = 0) -> int:
    """Threads per member: Solver.lanes, or for None, on a CUDA device in float64 with at least
    AUTO_MIN_NODES nodes, the cooperative kernel with min(AUTO_LANES, nodes // 2) lanes (the most
    lanes of at least two nodes each, one warp at most: a lane's time grows with its nodes; at
    N = 40 on the H100, 20 lanes beat the 16 of a power of two by 3 % for one member and 9 % for
    100, docs/performance.md); where nodes // 2 >= 64, the most whole warps of such lanes instead
    (a team of several warps, kernels/team.py make_warps_team: 96 lanes at N = 200, 192 at N = 400,
    at most MAX_TEAM_LANES) if the run's ``members`` fit the GPU's ``sm_count`` SMs at once in
    those (WIDE_WARPS_PER_SM warps an SM: 264 members of 96 lanes on an H100), unless the
    benchmark switches ask for what only one-warp teams do (WARPFRIC_TEAM_BLOCK_MEMBERS above 1, or
    an exchange other than shuffles: kernels/integrator.py team_compile_options); else 1 (the
    thread-per-member kernel: on the CPU a team's lanes run one after the other on Warp's fibers,
    which only costs)."""
    from warpfric.kernels.integrator import team_compile_options
    from warpfric.kernels.team import MAX_TEAM_LANES, WARP_SIZE

    if solver.lanes is not None:
        return solver.lanes
    if str(device).startswith("cuda") and solver.dtype == "float64" and solver.nodes >= AUTO_MIN_NODES:
        wide = min(MAX_TEAM_LANES, solver.nodes // 2 // WARP_SIZE * WARP_SIZE)
        options = team_compile_options()
        one_warp_asked = (options.block_members or 1) > 1 or options.exchange not in (None, "shuffle")
        if members is not None and wide > WARP_SIZE and not one_warp_asked:
            at_once = sm_count * (WIDE_WARPS_PER_SM // (wide // WARP_SIZE))  # members whose wide teams fit the GPU
            if members <= at_once:
                return wide
        return min(AUTO_LANES, solver.nodes // 2)
    return 1


def run_layout(solver: Solver, device: str, n_members: int):
    """(lanes, TeamLayout) of a run of n_members on ``device``: choose_lanes, then the members per
    block and the work array's memory (kernels/integrator.py team_layout). The integrate kernel a
    run builds depends on both (its lanes and its shared work array)."""
    import warp as wp

    from warpfric.kernels.integrator import team_layout

    cuda = str(device).startswith("cuda")
    gpu = wp.get_device(device) if cuda else None
    sm_count = gpu.sm_count if cuda else 1
    lanes = choose_lanes(solver, device, n_members, sm_count)
    return lanes, team_layout(lanes, solver.nodes, n_members, cuda, sm_count,
                              gpu.max_shared_memory_per_block if cuda else 0)


def slower_float32(solver: Solver, device: str) -> str | None:
    """Why float32 is the slower precision for this run, or None: on a CUDA device float32 runs the
    thread-per-member kernel (the cooperative kernel is compiled for float64 only), where float64
    would run the faster cooperative kernel (docs/performance.md, "float32 with the float64
    fallback")."""
    if solver.dtype != "float32" or not str(device).startswith("cuda"):
        return None
    if choose_lanes(dataclasses.replace(solver, dtype="float64"), device) == 1:
        return None
    return (f"Solver(dtype='float32') on {device} runs the thread-per-member kernel, where float64 would run "
            "the cooperative kernel, which was the faster on an H100 (10,000 gate-less members at N = 200: "
            "0.19 s in float64, 0.98 s in float32; docs/performance.md); float64 is also the more robust precision")


class cpu_blocks:
    """Let a launch on the CPU run blocks of several threads (Warp's cooperative CPU fibers; needed
    by the cooperative kernel there, e.g. in the tests)."""

    def __init__(self, enable: bool):
        self.enable = enable

    def __enter__(self):
        import warp as wp

        self.saved = wp.config.enable_cpu_blocks
        if self.enable:
            wp.config.enable_cpu_blocks = True

    def __exit__(self, *exc):
        import warp as wp

        wp.config.enable_cpu_blocks = self.saved


def solver_settings(solver: Solver):
    """warpfric.Solver -> the kernels' SolverSettings."""
    from warpfric.kernels.types import SolverSettings

    s = SolverSettings()
    s.rtol = solver.rtol
    s.initial_step = solver.initial_step
    s.min_step = solver.min_step
    s.max_step = solver.max_step
    s.newton_tol = solver.newton_tol
    s.switch_rtol = solver.rtol * solver.switch_tol
    s.sliding_width = solver.sliding_width
    s.max_steps = solver.max_steps
    s.newton_max_iter = solver.newton_max_iter
    s.step_safety = solver.step_safety
    s.step_min_factor = solver.step_min_factor
    s.step_max_factor = solver.step_max_factor
    s.failure_factor = solver.failure_factor
    s.predict_switches = 1 if solver.predict_switches else 0
    s.error_filter_nodes = float(solver.error_filter_nodes)
    s.viscous_velocity_cap = float(solver.viscous_velocity_cap)
    return s


def output_settings(fronts: Fronts | None, stress_gate: bool = True):
    """warpfric.Fronts (or None) -> the kernels' OutputSettings (the contact front only under the
    stress gate: the other laws have no gate to open)."""
    from warpfric.kernels.types import FRONT_DIRECTIONS, OutputSettings

    events = fronts.events if fronts is not None else ()
    out = OutputSettings()
    out.velocity_front = 1 if "velocity" in events else 0
    out.front_direction = FRONT_DIRECTIONS.index(fronts.direction) if fronts is not None else 0
    out.front_threshold = fronts.threshold if fronts is not None else 1.0
    out.contact_front = 1 if "contact" in events and stress_gate else 0
    out.strength_front = 1 if "strength" in events else 0
    return out


def array_bytes(a) -> int:
    """Bytes of a Warp array's elements: its capacity, or for a transposed view (a team's
    member-major arrays, kernels/types.py member_zeros), whose capacity Warp reports short, its size
    times the element size."""
    import warp as wp

    return a.capacity if a.is_contiguous else a.size * wp.types.type_size_in_bytes(a.dtype)


def observer_set(fronts: Fronts | None):
    """The fronts' observers a run compiles into its kernel (kernels/observers.py ObserverSet): the
    velocity and strength fronts where its front events include them. The recording is compiled
    always, so that a sweep's chunks with and without recorded members, its workers' warm-up, the
    grid check and the float32 fallback all run the kernel of the same fronts."""
    from warpfric.kernels.observers import ObserverSet

    events = fronts.events if fronts is not None else ()
    return ObserverSet(velocity_front="velocity" in events, strength_front="strength" in events)


def arrival_pass_settings(outputs):
    """OutputSettings of the velocity front's arrival pass (pass 2): the velocity front alone; the
    contact and strength fronts of pass 1 stay as they are."""
    from warpfric.kernels.types import OutputSettings

    out = OutputSettings()
    out.velocity_front = outputs.velocity_front
    out.front_direction = outputs.front_direction
    out.front_threshold = outputs.front_threshold
    out.contact_front = 0
    out.strength_front = 0
    return out


def confirmed_strength_peaks(strength, arrival, arrival_error, final_time: np.ndarray) -> np.ndarray:
    """The strength front's peaks that the run confirmed: a node's maximum of tau_f/sigma_n counts
    when the ratio at the last accepted point has fallen STRENGTH_PEAK_DROP below it and the maximum
    came before the end; elsewhere (still rising at the end: the peak lies beyond the run) the
    arrival and its error become NaN, in place. Returns the peaks (node, member), NaN where not
    confirmed. strength: (strength_slot, node, member), or a dict of the slots S_MAX and S_RATIO1;
    arrival, arrival_error: (front_event, node, member) s, or a dict of the events' rows;
    final_time: (member,) s."""
    from warpfric.kernels.observers import STRENGTH_PEAK_DROP
    from warpfric.kernels.types import EV_STRENGTH, S_MAX, S_RATIO1

    peak, last = strength[S_MAX], strength[S_RATIO1]
    with np.errstate(invalid="ignore"):
        confirmed = (np.isfinite(peak) & (peak > 0) & (arrival[EV_STRENGTH] < final_time[None, :])
                     & ~(last > (1.0 - STRENGTH_PEAK_DROP) * peak))
    arrival[EV_STRENGTH] = np.where(confirmed, arrival[EV_STRENGTH], np.nan)
    arrival_error[EV_STRENGTH] = np.where(confirmed, arrival_error[EV_STRENGTH], np.nan)
    return np.where(confirmed, peak, np.nan)


def param_columns(values: dict) -> dict:
    """The MemberParams fields of resolved parameters (name -> (member,) float64), as columns: the
    parameters' own, end_time max_end_time where it is None (inf: the automatic end; an explicit
    end_time is not capped) and auto_end (1 there). Fields not given stay 0 in member_params."""
    from warpfric.kernels.types import MemberParams

    columns = {name: values[name] for name in MemberParams.numpy_dtype()["names"] if name in values}
    auto_end = np.isinf(values["end_time"])
    columns["end_time"] = np.where(auto_end, values["max_end_time"], values["end_time"])
    columns["auto_end"] = auto_end.astype(np.float64)
    return columns


def member_params(values: dict) -> np.ndarray:
    """Resolved parameters (name -> (member,) float64) -> MemberParams as a structured array
    (param_columns)."""
    from warpfric.kernels.types import MemberParams

    params = np.zeros(values["normal_force"].shape[0], dtype=MemberParams.numpy_dtype())
    for name, column in param_columns(values).items():
        params[name] = column
    return params


# members from which the MemberParams and start states are built on the device (below, the host's
# arrays are small and one upload is quicker than the device's few: ~0.2 ms a run, CPU, one member)
DEVICE_BUILT_MIN_MEMBERS = 4096


def device_member_params(values: dict, layout: dict):
    """The members' MemberParams as a Warp array on the current device, as member_params(values)
    gives them; from DEVICE_BUILT_MIN_MEMBERS members on built there: the host uploads one
    member's parameters and the columns that differ among the members (layout: the layout
    kernels, kernels/integrator.py; at 100,000 members the host's structured array was 22 MB of
    fresh memory on the critical path)."""
    import warp as wp

    from warpfric.kernels.types import MemberParams

    n_members = values["normal_force"].shape[0]
    if n_members < DEVICE_BUILT_MIN_MEMBERS:
        return wp.array(member_params(values), dtype=MemberParams)
    dtype = np.dtype(MemberParams.numpy_dtype())
    if any(dtype[name] != np.float64 for name in dtype.names) or dtype.itemsize != 8 * len(dtype.names):
        raise AssertionError("device_member_params: MemberParams must be float64 fields without padding")
    first = member_params({name: np.asarray(column)[:1] for name, column in values.items()})
    columns = param_columns(values)
    varying = [name for name in dtype.names if name in columns and not alike(columns[name])]
    params = wp.empty(n_members, dtype=MemberParams)
    rows = wp.array(ptr=params.ptr, shape=(n_members, len(dtype.names)), dtype=wp.float64, device=params.device)
    stacked = np.stack([np.asarray(columns[name], dtype=np.float64) for name in varying]) if varying \
        else np.zeros((0, n_members))
    wp.launch(layout["member_params"], dim=rows.shape,
              inputs=[wp.array(first.view(np.float64), dtype=wp.float64), wp.array(stacked, dtype=wp.float64),
                      wp.array([dtype.names.index(name) for name in varying], dtype=wp.int32)], outputs=[rows])
    return params


def device_member_states(n_members: int, solver: Solver, record_slots: np.ndarray, layout: dict,
                         front_level: np.ndarray | None = None, front_until: np.ndarray | None = None):
    """The members' IntegratorStates at t = 0 as initial_states gives them, a Warp array on the
    current device (from DEVICE_BUILT_MIN_MEMBERS members on built there from one member's state):
    record_slots (member,), and front_level (m/s) and front_until (s) (member,) where given (the
    velocity front's arrival pass)."""
    import warp as wp

    from warpfric.kernels.types import IntegratorState

    if n_members < DEVICE_BUILT_MIN_MEMBERS:
        states = initial_states(n_members, solver, record_slots)
        if front_level is not None:
            states["front_level"], states["front_until"] = front_level, front_until
        return wp.array(states, dtype=IntegratorState)
    start = wp.array(initial_states(1, solver, np.full(1, -1, np.int32)), dtype=IntegratorState)
    states = wp.empty(n_members, dtype=IntegratorState)
    given = front_level is not None
    wp.launch(layout["member_states"], dim=n_members,
              inputs=[start, wp.array(record_slots, dtype=wp.int32),
                      wp.array(front_level if given else np.zeros(0), dtype=wp.float64),
                      wp.array(front_until if given else np.zeros(0), dtype=wp.float64)], outputs=[states])
    return states


def initial_states(n_members: int, solver: Solver, record_slots: np.ndarray) -> np.ndarray:
    """IntegratorState of every member at t = 0 (a backward-Euler start, no maximum yet)."""
    from warpfric.kernels.types import IntegratorState

    st = np.zeros(n_members, dtype=IntegratorState.numpy_dtype())
    st["h"] = solver.initial_step
    st["restart"] = 1
    st["mu_s"] = -np.inf
    st["front_max"] = -np.inf
    st["front_last"] = -np.inf
    st["front_now"] = -np.inf
    st["front_level"] = np.inf
    st["front_until"] = np.inf
    st["detachment_end"] = np.inf
    st["switch_limit"] = 1e300
    st["record_slot"] = record_slots
    return st


def record_slots(record: Record | None, n_members: int) -> np.ndarray:
    """Per member: its index among the recorded members, or -1."""
    slots = np.full(n_members, -1, dtype=np.int32)
    if record is None:
        return slots
    for slot, member in enumerate(record.members):
        if member >= n_members:
            raise ValueError(f"record setting 'members' contains {member}; valid: member indices 0..{n_members - 1} "
                             "(a member's index is its number less simulate's member_offset: for a run numbered "
                             "from K, Record.detachment(ds, members=..., member_offset=K))")
        slots[member] = slot
    return slots


# Diagnostics for benchmarks (studies/bench_engine.py --launch-log): when a list, every integrate
# launch appends a LaunchRecord. Off (None) by default: recording costs a synchronisation per launch.
LAUNCH_LOG: list | None = None


@dataclasses.dataclass
class LaunchRecord:
    """One integrate launch of a pass: its kernel time (CUDA events; on the CPU the wall time of the
    launch call), the members that were running when it started, and the attempted steps and Newton
    iterations those members made in it (sum and the largest of one member)."""

    pass_index: int
    launch: int
    kernel_s: float
    running_members: int
    attempts: int
    max_member_attempts: int
    newton_iterations: int


# no straggler limit (the kernel's int32 attempt counter never exceeds it)
NO_STALL_LIMIT = 2**31 - 1


def straggler_limit(st: np.ndarray, solver: Solver) -> int:
    """The attempted steps after which a running member is stopped as a straggler (status
    ``stalled``; the integrate kernel applies it), from a snapshot of the member states.

    Once at least half of the members have ended ok, the limit is max(stall_min_steps,
    stall_factor * the lower median of the attempted steps of the members that ended ok or still
    run, a running member counted at its attempts so far); failed members do not count. One member
    can then cost a launch at most about stall_factor times a typical member. The members advance in
    step (each launch gives every running member the same attempts), so a running member has made at
    least as many attempts as any that has ended, and the lower median is an ended member's final
    count, the ensemble's own, whichever launch's snapshot it is read from. (The median of the ended
    members alone is that of the faster half when half have ended, and grew from launch to launch: a
    member needing 9.6x the ensemble's median was stopped in one run and not in another; the plain
    median of all counts would, with exactly half ended, average in a running member's count and
    follow it.) Before half have ended, and for a lone member (no peers), there is none
    (NO_STALL_LIMIT; max_steps still bounds every member)."""
    finished = (st["done"] != 0) & (st["status"] == 0)
    if finished.sum() * 2 < st.shape[0] or not finished.any() or not np.isfinite(solver.stall_factor):
        return NO_STALL_LIMIT
    counted = finished | (st["done"] == 0)
    attempts = np.sort((st["steps_accepted"].astype(np.int64) + st["steps_rejected"])[counted])
    limit = max(solver.stall_min_steps, solver.stall_factor * float(attempts[(attempts.size - 1) // 2]))
    return int(min(limit, NO_STALL_LIMIT))


def apply_straggler_limit(st: np.ndarray, solver: Solver, stall_limit, last_limit: int) -> int:
    """Set the device's stall_limit (a (1,) int32 array the integrate kernel reads) to the
    straggler_limit of the snapshot ``st`` where it differs from ``last_limit``, the one set before;
    returns the limit now set."""
    limit = straggler_limit(st, solver)
    if limit != last_limit:
        stall_limit.fill_(limit)
    return limit


def real_event(front_max, front_last, values, fronts: Fronts) -> np.ndarray:
    """Members with a detachment event: a maximum detachment velocity of at least
    fronts.min_event_fraction * |disc_velocity| (docs/model.md, "Fronts"). Below it (e.g. a disc that
    never moves: round-off of 1e-22 m/s) there is no front, and every front output is NaN."""
    floor = fronts.min_event_fraction * np.abs(values["disc_velocity"])
    return (front_max > 0) & (front_max >= floor) & np.isfinite(front_last)


# pinned host buffers of the state read-back kept between runs, (device, members) -> free buffers:
# allocating and freeing pinned memory costs ~1.3 ms, 9 % of a one-member run at N = 40 on the H100
# (docs/performance.md, "One member's host time"); only small ones are kept, and at most
# PINNED_POOL_MAX_TOTAL bytes in all (the oldest member counts go first)
_PINNED_POOL: dict = {}
_PINNED_LOCK = threading.Lock()
PINNED_POOL_MAX_BYTES = 1 << 20  # per buffer kept
PINNED_POOL_MAX_TOTAL = 16 << 20  # all buffers kept


def take_members(a: np.ndarray, index: np.ndarray) -> np.ndarray:
    """a[index] along the first axis of a 1-D array; a structured array (the member states) is
    gathered as rows of raw bytes: numpy's fancy indexing copies a structured record field by
    field (100,000 IntegratorStates: 20 ms against 0.8 ms, on this project's CPU)."""
    if a.dtype.names is None:
        return a[index]
    records = np.ascontiguousarray(a).view(np.uint8).reshape(a.shape[0], a.dtype.itemsize)
    return np.take(records, index, axis=0).view(a.dtype).reshape(len(index))


def touched_empty(shape, dtype) -> np.ndarray:
    """np.empty(shape, dtype) with every page written once (one value per 4 KiB): the OS's
    first-touch page faults are taken now, so that a later copy into it runs at the copy's own
    speed. The engine allocates its read-back arrays so while the kernel runs (landing_arrays)."""
    out = np.empty(shape, dtype)
    flat = out.reshape(-1)
    flat[:: max(1, 4096 // out.itemsize)] = 0
    return out


def landing_arrays(n_members: int, n: int, ft, stress_gate: bool) -> dict:
    """The host arrays that the final fields are read back into (names as in run(), shapes as
    member_rows and host_copy give them), allocated and touched (touched_empty) while the GPU
    integrates: the read-back after the last launch, on the critical path, then only copies."""
    import warp as wp

    from warpfric.kernels.types import G_GATE, N_COMPONENTS

    real = wp.dtype_to_numpy(ft)
    arrays = dict(fields=touched_empty((N_COMPONENTS, n_members, n), real),
                  normal_stress=touched_empty((n_members, n), real), friction_stress=touched_empty((n_members, n), real))
    if stress_gate:  # float64, like the kernels' yield_time and gates
        arrays.update(yield_time=touched_empty((1, n_members, n), np.float64),
                      gates=touched_empty((G_GATE + 1, n_members, n), np.float64))
    return arrays


def host_copy(a, out: np.ndarray | None = None) -> np.ndarray:
    """A contiguous float device array copied into a new numpy array, or into ``out`` (of a's shape
    and dtype; e.g. one of landing_arrays). Like ``a.numpy()`` (on the default stream, so
    synchronous), but into memory numpy allocates, which the OS backs with huge pages where it can:
    writing 64 MB there costs half the page faults' time of Warp's own host allocation
    (docs/performance.md, "Host time around the kernel")."""
    import warp as wp

    real = np.dtype(wp.dtype_to_numpy(a.dtype))
    if out is None:
        out = np.empty(a.shape, dtype=real)
    elif (out.shape != tuple(a.shape) or out.dtype != real or not out.flags.c_contiguous
          or not out.flags.writeable):
        raise ValueError(f"host_copy: out is {out.dtype}{out.shape} (C-contiguous: {out.flags.c_contiguous}, "
                         f"writeable: {out.flags.writeable}); it must be the device array's {real}{tuple(a.shape)}, "
                         "C-contiguous and writeable")
    with wp.ScopedStream(a.device.null_stream):
        wp.copy(wp.array(out, dtype=a.dtype, device="cpu", copy=False), a)
    return out


def member_rows(layout: dict, source, slots: int, kernel_member, out: np.ndarray | None = None) -> np.ndarray:
    """The first ``slots`` slots of a (slot, node, member) device array (any layout) on the host as
    (slot, member, node), arranged by the layout kernels' member_rows on the device, the caller's
    member m being the kernel's kernel_member[m] (an int32 device array); into ``out`` if given."""
    import warp as wp

    rows = wp.empty((slots, source.shape[2], source.shape[1]), dtype=source.dtype, device=source.device)
    wp.launch(layout["member_rows"], dim=rows.shape, inputs=[source, kernel_member, rows], device=source.device)
    return host_copy(rows, out)


def member_columns(layout: dict, source, kernel_member) -> np.ndarray:
    """A (node, member) float64 device array on the host with its members in the caller's order
    (kernel_member as in member_rows; None where the kernel ran the caller's order)."""
    import warp as wp

    if kernel_member is None:
        return host_copy(source)
    columns = wp.empty(source.shape, dtype=wp.float64, device=source.device)
    wp.launch(layout["member_columns"], dim=columns.shape, inputs=[source, kernel_member, columns],
              device=source.device)
    return host_copy(columns)


class StateSnapshots:
    """Read-back of the member states that does not stall the launch queue: ``take`` queues a copy
    into a host buffer (pinned on a CUDA device) behind the launches queued so far and returns a
    ticket; ``wait`` blocks until that copy has landed and returns the states in a host array of its
    own, which the next ``wait`` overwrites (takes and waits alternate; one array a run, so that its
    pages are written for the first time once: 25 MB at 100,000 members). ``close`` gives a small
    pinned buffer back to a pool that the next run of as many members on the device takes (the
    buffer is only ever used by one run at a time)."""

    def __init__(self, n_members: int, device):
        import warp as wp

        from warpfric.kernels.types import IntegratorState

        self.cuda = wp.get_device(device).is_cuda
        self.key = (str(wp.get_device(device)), n_members)
        self.buffer = None
        self.states = None  # the host array that wait() copies into
        if self.cuda:
            with _PINNED_LOCK:
                free = _PINNED_POOL.get(self.key)
                if free:
                    self.buffer = free.pop()
        if self.buffer is None:
            self.buffer = wp.empty(n_members, dtype=IntegratorState, device="cpu", pinned=self.cuda)

    def close(self):
        """After the last ``wait``: a small pinned buffer goes back to the pool."""
        if self.cuda and self.buffer is not None and self.buffer.capacity <= PINNED_POOL_MAX_BYTES:
            with _PINNED_LOCK:
                _PINNED_POOL[self.key] = _PINNED_POOL.pop(self.key, []) + [self.buffer]  # the newest key last
                while sum(b.capacity for free in _PINNED_POOL.values() for b in free) > PINNED_POOL_MAX_TOTAL:
                    del _PINNED_POOL[next(iter(_PINNED_POOL))]
        self.buffer = None

    def take(self, member_states):
        import warp as wp

        wp.copy(self.buffer, member_states)
        return self.buffer, (wp.record_event() if self.cuda else None)

    def final(self, ticket) -> np.ndarray:
        """``wait`` for the last snapshot of a pass: its host array is the caller's from now on (a
        later ``wait`` fills another)."""
        states = self.wait(ticket)
        self.states = None
        return states

    def wait(self, ticket) -> np.ndarray:
        import warp as wp

        buffer, event = ticket
        if event is not None:
            wp.synchronize_event(event)
        landed = buffer.numpy()
        if self.states is None:
            self.states = np.empty_like(landed)
        np.copyto(self.states, landed)
        return self.states


def log_launches(log: list, pass_index: int, member_states, launch, device, stall_limit, solver: Solver):
    """Diagnostic integration of a pass (LAUNCH_LOG): launch after launch, synchronised, timing each
    and appending a LaunchRecord, until every member is done; the straggler rule is applied as in
    the pipelined loop. The member states are left done, so that the loop after it ends at once."""
    import warp as wp

    cuda = wp.get_device(device).is_cuda
    before = member_states.numpy().copy()
    last_limit = NO_STALL_LIMIT
    for k in itertools.count():
        if cuda:
            start, end = wp.Event(enable_timing=True), wp.Event(enable_timing=True)
            wp.record_event(start)
            launch()
            wp.record_event(end)
            kernel_s = wp.get_event_elapsed_time(start, end) / 1000.0
        else:
            t0 = time.perf_counter()
            launch()
            wp.synchronize_device(device)
            kernel_s = time.perf_counter() - t0
        after = member_states.numpy().copy()
        attempts = (after["steps_accepted"].astype(np.int64) + after["steps_rejected"]
                    - before["steps_accepted"] - before["steps_rejected"])
        log.append(LaunchRecord(pass_index, k, kernel_s, int((before["done"] == 0).sum()), int(attempts.sum()),
                                int(attempts.max()), int((after["newton_iterations"] - before["newton_iterations"]).sum())))
        before = after
        if (after["done"] != 0).all():
            return
        if pass_index == 0:
            last_limit = apply_straggler_limit(after, solver, stall_limit, last_limit)


def run(values: dict, model: Model, solver: Solver, fronts: Fronts | None, record: Record | None, device: str,
        show_progress: bool = False, label: str = "") -> EngineResult:
    """Allocate, integrate every member through its passes, read back. ``values``: resolved
    parameters (name -> (member,) float64); a progress line on stderr when show_progress."""
    t_import = time.perf_counter()
    import warp as wp

    from warpfric.kernels.integrator import block_threads, get_integrator
    from warpfric.kernels.types import FRONT_EVENTS, G_GATE, N_COMPONENTS, S_MAX, S_RATIO1, IntegratorState, allocate

    import_s = time.perf_counter() - t_import  # the kernels' Python modules (their first import: ~70 ms)
    n_members = values["normal_force"].shape[0]
    n = solver.nodes
    cuda = str(device).startswith("cuda")
    sm_count = wp.get_device(device).sm_count if cuda else 1
    # threads per member, members per block and the work array's memory
    lanes, layout = run_layout(solver, device, n_members)
    team = lanes > 1
    if team and not cuda:
        warnings.warn(f"Solver(lanes={lanes}) on {device}: the cooperative kernel runs there on Warp's experimental "
                      "CPU fibers, slowly and for tests only (docs/model.md, 'Time integration'); "
                      "lanes=1 is the CPU's kernel", stacklevel=3)
    note = slower_float32(solver, device)
    if note is not None:
        warnings.warn(note, stacklevel=3)
    # before the kernels are built, so that a bad WARPFRIC_MEMBER_ORDER is refused first
    order = member_order(values, alike_blocks(layout, n_members, sm_count), os.environ.get("WARPFRIC_MEMBER_ORDER"))
    if order is not None:  # the kernel's order; the outputs go back into the caller's on their way to the host
        # a column alike in every member is its own reordering (most columns of a run: 6 of 28 ms
        # of host time before a 100,000-member launch went into copying them)
        values = {name: column if alike(column) else np.asarray(column)[order] for name, column in values.items()}
    t_build = time.perf_counter()
    kern = get_integrator(solver.dtype, model, lanes, solver.method, cuda=cuda, observed=observer_set(fronts),
                          shared_work=layout.shared_work)
    # compile or load now, so that it is timed apart (and said, where it takes long: a compilation)
    with cpu_blocks(team), building_note(show_progress):
        block_dim = block_threads(lanes, kern["blocked"])
        wp.load_module(kern["integrate"].module, device=device, block_dim=block_dim if team else None)
        wp.load_module(kern["evaluate_fields"].module, device=device)
        for layout_kernel in kern["layout"].values():
            wp.load_module(layout_kernel.module, device=device)
        if fronts is not None:  # the fronts' segmentation kernel (warpfric/fronts.py), launched after the run
            from warpfric.kernels.reductions import segment_fronts

            wp.load_module(segment_fronts.module, device=device)
    kernel_build_s = time.perf_counter() - t_build + import_s
    block_members = layout.block_members
    blocks = -(-n_members // block_members)  # of a team kernel's launch
    ft = kern["ft"]
    settings = solver_settings(solver)
    stress_gate = model.relaxation_gate == "stress"
    outputs = output_settings(fronts, stress_gate)
    slots = record_slots(record, n_members)
    if order is not None:
        slots = slots[order]
    strength = outputs.strength_front == 1
    n_passes = 2 if outputs.velocity_front == 1 else 1
    with wp.ScopedDevice(device):
        arrays = allocate(ft, device_member_params(values, kern["layout"]), n, stress_gate, fronts is not None,
                          record.times if record is not None else None, len(record.members) if record is not None else 0,
                          member_major=team, method=solver.method, strength=strength,
                          global_work=layout.shared_work is None)
        per_member = [arrays.params, arrays.state, arrays.stages]  # not the (.., 1, 1) placeholders
        per_member += [arrays.step_end] + ([arrays.work] if layout.shared_work is None else [])
        per_member += [arrays.gates, arrays.yield_time] if stress_gate else []
        per_member += [arrays.arrival, arrays.arrival_error] if fronts is not None else []
        per_member += [arrays.strength] if strength else []
        n_bytes = sum(array_bytes(a) for a in per_member) + n_members * np.dtype(IntegratorState.numpy_dtype()).itemsize
        device_bytes_per_member = n_bytes / n_members
        front_max = front_last = event = None
        stall_limit = wp.full(1, NO_STALL_LIMIT, dtype=wp.int32)  # attempts after which a member stalls
        snapshot = StateSnapshots(n_members, device)
        initial_age = wp.array(values["initial_age"], dtype=wp.float64)
        # the kernel's member m is the caller's order[m], so the caller's member m is the kernel's
        # back[m]: outputs are read back through kernel_member (back) or written to row_of (order)
        back = np.arange(n_members) if order is None else np.argsort(order)
        kernel_member = wp.array(back, dtype=wp.int32)
        row_of = wp.array(np.arange(n_members) if order is None else order, dtype=wp.int32)

        def launch_integrate(inputs, outputs_):
            if team:
                with cpu_blocks(True):
                    wp.launch_tiled(kern["integrate"], dim=[blocks], inputs=inputs, outputs=outputs_, block_dim=block_dim)
            else:
                wp.launch(kern["integrate"], dim=n_members, inputs=inputs, outputs=outputs_)

        bar = Progress(show_progress, n_members, label, n_passes, solver,  # warpfric/progress.py
                       extra=end_time_attempts(values["end_time"], values["rest_until"]))
        for pass_index in range(n_passes):
            if pass_index == 0:
                member_states = device_member_states(n_members, solver, slots, kern["layout"])
            else:
                # the velocity front's arrival pass: the contact and strength fronts (pass 1's) are kept
                member_states = device_member_states(
                    n_members, solver, np.full(n_members, -1, np.int32), kern["layout"],
                    front_level=np.where(event, fronts.threshold * front_max, np.inf),
                    front_until=np.where(event, front_last, -np.inf))  # no event: nothing to redo
            wp.launch(kern["layout"]["initial_state"], dim=arrays.state.shape, inputs=[initial_age, arrays.state])
            arrays.stages.zero_()  # K[fsal] holds f(y) of the state: zero for the state at rest
            arrays.gates.zero_()  # every gate closed: no friction stress at the start
            if pass_index == 0:
                arrays.arrival.fill_(np.nan)
                arrays.arrival_error.fill_(np.nan)
                arrays.strength.fill_(np.nan)
                arrays.yield_time.fill_(np.nan)
            bar.start_pass(pass_index)
            stall_limit.fill_(NO_STALL_LIMIT)
            last_limit = NO_STALL_LIMIT
            inputs = [arrays.params, settings, outputs if pass_index == 0 else arrival_pass_settings(outputs),
                      launch_steps(solver, n_members, device), block_members, stall_limit, arrays.record_times,
                      member_states, arrays.state, arrays.stages, arrays.work, arrays.step_end, arrays.gates,
                      arrays.record_previous]
            outputs_ = [arrays.arrival, arrays.arrival_error, arrays.strength, arrays.yield_time, arrays.record]
            # the launches are queued one ahead of the host: while chunk k + 1 runs, the host reads the
            # member states after chunk k (an asynchronous copy into pinned memory), updates the
            # progress line and the straggler limit (which chunk k + 2 applies) and stops once every
            # member was done after chunk k (chunk k + 1 then returned at once for every member)
            if LAUNCH_LOG is not None:
                log_launches(LAUNCH_LOG, pass_index, member_states, lambda: launch_integrate(inputs, outputs_),
                             device, stall_limit, solver)
            launch_integrate(inputs, outputs_)
            pending = snapshot.take(member_states)
            if pass_index == 0:  # while a GPU runs (a CPU launch has run by now: the same copies, nothing overlapped)
                landing = landing_arrays(n_members, n, ft, stress_gate)
            while True:
                launch_integrate(inputs, outputs_)
                st_now = snapshot.wait(pending)
                pending = snapshot.take(member_states)
                if pass_index == 0:
                    last_limit = apply_straggler_limit(st_now, solver, stall_limit, last_limit)
                n_done = int(st_now["done"].sum())
                bar.update(st_now)
                if n_done == n_members:
                    break
            st_now = snapshot.final(pending)  # every member was done before the launch it follows
            bar.end_pass(st_now)
            if pass_index == 0:
                st = st_now
                front_max, front_last = st["front_max"], st["front_last"]
                event = real_event(front_max, front_last, values, fronts) if fronts is not None else None
                # read back in the Dataset's (member, node) order, arranged on the device: the host
                # writes each value once (docs/performance.md, "Host time around the kernel"); the
                # fields' device copy is freed before the stresses are allocated
                fields = member_rows(kern["layout"], arrays.state, N_COMPONENTS, kernel_member, landing["fields"])
                sigma_out = wp.zeros((n_members, n), dtype=ft)
                tau_out = wp.zeros((n_members, n), dtype=ft)
                wp.launch(kern["evaluate_fields"], dim=n_members,
                          inputs=[arrays.params, member_states, arrays.state, row_of], outputs=[sigma_out, tau_out])
                sigma = host_copy(sigma_out, landing["normal_stress"])
                tau = host_copy(tau_out, landing["friction_stress"])
                yield_np = gate_np = None
                if stress_gate:  # float64 (the stress gate refuses float32), like yield_time
                    yield_np = member_rows(kern["layout"], arrays.yield_time.reshape((1, n, n_members)), 1,
                                           kernel_member, landing["yield_time"])[0]
                    gate_np = member_rows(kern["layout"], arrays.gates, G_GATE + 1, kernel_member,
                                          landing["gates"])[G_GATE]
        snapshot.close()
        if order is not None:  # the member states and events back into the caller's order (the rest: above, below)
            st = take_members(st, back)
            event = None if event is None else event[back]
        arrival = arrival_error = strength_peak = None
        if fronts is not None:
            rows = sorted({FRONT_EVENTS.index(name) for name in fronts.events})  # only what is asked for is read
            by_member = None if order is None else kernel_member
            arrival = {row: member_columns(kern["layout"], arrays.arrival[row], by_member) for row in rows}
            arrival_error = {row: member_columns(kern["layout"], arrays.arrival_error[row], by_member) for row in rows}
            if strength:
                strength_rows = {slot: member_columns(kern["layout"], arrays.strength[slot], by_member)
                                 for slot in (S_MAX, S_RATIO1)}
                strength_peak = confirmed_strength_peaks(strength_rows, arrival, arrival_error, st["t"])
        result = EngineResult(
            member_states=st, fields=fields, normal_stress=sigma, friction_stress=tau, yield_time=yield_np, yield_gate=gate_np,
            arrival=arrival, arrival_error=arrival_error, strength_peak=strength_peak,
            event=event, record=arrays.record.numpy() if record is not None else None,
            kernel_build_s=kernel_build_s, device_bytes_per_member=device_bytes_per_member, lanes=lanes,
            team_exchange=kern["exchange"], block_members=block_members, passes=n_passes,
            work_memory="global" if layout.shared_work is None else "shared",
            member_order="given" if order is None else "similar",
        )
        wp.synchronize_device(device)
    return result
