"""Who works on a member: one thread (the thread-per-member kernel) or a team of ``lanes`` threads
(the cooperative kernel: a Warp tile block per member, or, where the lanes exchange by warp
shuffles, a warp per member and up to eight members per block: kernels/integrator.py
blocked_layout; docs/model.md, "Time integration").

In a team, lane k owns the contiguous nodes [first_node, end_node) = [k*N//P, (k+1)*N//P) of its
member (P = lanes <= N/2, so every lane owns at least two nodes) and runs every per-node loop of
the integrator on them alone; what a loop reduces over the nodes (sums, maxima, the error norm) is
combined over the lanes, and every lane gets the same bits, so that every lane takes the same
decisions (step accepted, Newton converged, ...) and keeps an identical copy of the member's
IntegratorState. Team operations synchronise the lanes: the reductions double as barriers between
a lane's writes and its neighbours' reads of halo nodes; ``barrier`` is the explicit one where no
reduction falls.

How the lanes exchange values (``exchange``):
- "tile": Warp's tile primitives (the CPU's cooperative fibers, and teams of more than 32 lanes
  that are not whole warps).
  A tile operation synchronises the block. Every reduction ends with ``settle``: a one-element
  shared tile assignment, which synchronises before it writes, so that no lane starts the next
  tile operation while another still reads this one's result. Without it, Warp's CPU reductions
  write their flags into the freed shared memory of the previous result before their first
  synchronisation, and the lanes of a team of 2-8 read different sums (found in review: teams of
  7 and 8 lanes failed on a lift-off member; tests/test_team.py checks the sums of every lane).
  The separator system is solved by each lane's twisted factorisation.
- "shuffle": warp shuffles, on a GPU, for a team of at most 32 lanes (one warp), or of several
  whole warps (64 to MAX_TEAM_LANES lanes: shuffles inside each warp, a shared buffer between
  them, make_warps_team); below.
- "emulated": the shuffles' algorithms with each shuffle through a tile, so that the CPU tests
  them.

``make_team(ft, lanes, exchange)`` builds the functions; with lanes = 1 they are the identity
(``make_solo``: no team operation is compiled, the thread-per-member kernel is unchanged bit for
bit), else the tile reductions and separator exchange (``make_tile_reductions``,
``make_separator_exchange``) or their shuffle versions (``make_exchange_team``). A team needs
float64 (``ft``): the cooperative kernel is compiled for float64 only.
"""

from typing import Any

import warp as wp

# vector types the team exchanges (float64): the border-row entries a lane's end nodes give its
# neighbours' nodes (kernels/newton.py assemble_system), the reduced system's rows (A, B, C, D0, D1, D2), a
# node's solution as affine in the neighbouring separators (xP0, xP1, xP2, xL, xR), the Newton
# sums (force and moment residuals, the 2 x 2 D block, the six border products)
vec3d = wp.types.vector(length=3, dtype=wp.float64)
vec4d = wp.types.vector(length=4, dtype=wp.float64)
vec5d = wp.types.vector(length=5, dtype=wp.float64)
vec6d = wp.types.vector(length=6, dtype=wp.float64)
vec12d = wp.types.vector(length=12, dtype=wp.float64)


@wp.func
def node_range(lane: int, lanes: int, n: int):
    """The nodes [first, end) of lane ``lane`` of ``lanes`` (all n for a team of one)."""
    return (lane * n) // lanes, ((lane + 1) * n) // lanes


@wp.func
def settle():
    """A barrier that synchronises before it writes (a shared tile's assignment: sync, write,
    sync): every lane has finished what it did before, reads of the last reduction included."""
    wp.tile_extract(wp.tile(int(0)), 0)


def make_solo():
    """The team of one (the thread-per-member kernel): every reduction is the identity and no tile
    operation is compiled, so that kernel is unchanged bit for bit."""

    @wp.func
    def team_max(x: Any):
        return x

    @wp.func
    def team_min(x: Any):
        return x

    @wp.func
    def team_sum(x: Any):
        return x

    @wp.func
    def team_count(x: int):
        return x

    @wp.func
    def barrier():
        pass

    return dict(lanes=1, team_max=team_max, team_min=team_min, team_sum=team_sum, team_count=team_count,
                barrier=barrier)


def make_tile_reductions(lanes: int):
    """Reductions over a team of ``lanes`` threads (float64) with Warp's tile primitives, each ending
    with ``settle``, and the explicit ``barrier``."""

    @wp.func
    def team_max(x: wp.float64):
        """Maximum over the lanes (a NaN lane value is dropped: callers map non-finite to inf)."""
        r = wp.tile_max(wp.tile(x))[0]
        settle()
        return r

    @wp.func
    def team_min(x: wp.float64):
        r = wp.tile_min(wp.tile(x))[0]
        settle()
        return r

    @wp.func
    def team_sum(x: wp.float64):
        r = wp.tile_sum(wp.tile(x))[0]
        settle()
        return r

    @wp.func
    def team_count(x: int):
        r = wp.tile_sum(wp.tile(x))[0]
        settle()
        return r

    @wp.func
    def barrier():
        """Every lane's writes before this call are seen by every lane after it."""
        settle()

    @wp.func
    def team_sum_vec12(x: vec12d):
        r = wp.tile_sum(wp.tile(x, preserve_type=True))[0]
        settle()
        return r

    return dict(team_max=team_max, team_min=team_min, team_sum=team_sum, team_count=team_count, barrier=barrier,
                team_sum_vec12=team_sum_vec12)


def make_separator_exchange(lanes: int):
    """The team's part of the partitioned tridiagonal solve (kernels/newton.py make_team_solver): a
    neighbour lane's value (from_next_lane) and the separators' reduced system (reduced_solve)."""

    @wp.func
    def from_next_lane(x: vec5d, lane: int):
        """The value of lane + 1 (zero for the last lane)."""
        t = wp.tile(x, preserve_type=True)
        out = vec5d()
        if lane + 1 < lanes:
            out = wp.tile_extract(t, lane + 1)
        return out

    @wp.func
    def from_neighbour_lanes(x: vec4d, lane: int):
        """The values of lane - 1 and lane + 1 (zero beyond the first and the last lane); ends with
        a settle, so that the next tile operation cannot overwrite them while a lane still reads."""
        t = wp.tile(x, preserve_type=True)
        prev = vec4d()
        nxt = vec4d()
        if lane > 0:
            prev = wp.tile_extract(t, lane - 1)
        if lane + 1 < lanes:
            nxt = wp.tile_extract(t, lane + 1)
        settle()
        return prev, nxt

    @wp.func
    def eliminate(coupling: wp.float64, diagonal: wp.float64, rhs: vec3d, pivot: wp.float64, carried: wp.float64,
                  carried_rhs: vec3d, first: bool):
        """One step of a tridiagonal elimination: the row (coupling to the eliminated neighbour,
        diagonal, right-hand sides) minus coupling/pivot times the neighbour's eliminated row
        (pivot, its coupling back to this row: carried, its right-hand sides); the first row of a
        sweep is kept. Returns the new pivot and right-hand sides."""
        if first:
            return diagonal, rhs
        f = coupling / pivot
        return diagonal - f * carried, rhs - f * carried_rhs

    @wp.func
    def reduced_solve(row: vec6d, lane: int):
        """The separators of the partitioned tridiagonal solve: lane k gives row k of the P x P
        tridiagonal system A_k E_{k-1} + B_k E_k + C_k E_{k+1} = D_k (three right-hand sides;
        row = (A, B, C, D0, D1, D2)) and gets (E_{k-1}, E_k) (E_{-1} = 0). Each lane eliminates
        the rows above it downwards and the rows below it upwards (a twisted factorisation, P - 1
        row operations, no back substitution) and closes with its own row."""
        t = wp.tile(row, preserve_type=True)
        b_up = wp.float64(1.0)
        c_up = wp.float64(0.0)
        d_up = vec3d()
        for j in range(lane):  # rows 0..k-1, eliminated downwards
            r = wp.tile_extract(t, j)
            b_up, d_up = eliminate(r[0], r[1], vec3d(r[3], r[4], r[5]), b_up, c_up, d_up, j == 0)
            c_up = r[2]
        b_dn = wp.float64(1.0)
        a_dn = wp.float64(0.0)
        d_dn = vec3d()
        for jj in range(lanes - 1 - lane):  # rows P-1..k+1, eliminated upwards
            j = lanes - 1 - jj
            r = wp.tile_extract(t, j)
            b_dn, d_dn = eliminate(r[2], r[1], vec3d(r[3], r[4], r[5]), b_dn, a_dn, d_dn, jj == 0)
            a_dn = r[0]
        num = vec3d(row[3], row[4], row[5])
        den = row[1]
        if lane > 0:
            num = num - (row[0] / b_up) * d_up
            den = den - row[0] * c_up / b_up
        if lane < lanes - 1:
            num = num - (row[2] / b_dn) * d_dn
            den = den - row[2] * a_dn / b_dn
        e_self = num / den
        e_prev = vec3d()
        if lane > 0:
            e_prev = (d_up - c_up * e_self) / b_up
        return e_prev, e_self

    return dict(from_next_lane=from_next_lane, from_neighbour_lanes=from_neighbour_lanes, reduced_solve=reduced_solve)


# ---- the lane exchange by value (exchange = "shuffle" or "emulated") ----
# On a GPU a team of at most 32 lanes is one warp: its lanes read each other's registers with warp
# shuffles, so nothing goes through shared memory and no block barrier is needed (only __syncwarp,
# for the lanes' global-memory writes, which every team operation but reduced_solve starts with, as
# the tiles' synchronisation did; in one warp reduced_solve works on registers only and follows
# from_next_lane; a team of several warps exchanges through a buffer: make_warps_team). Reductions are butterflies (every lane adds its partner's partial sum at
# distance 16, 8, .., 1; commutativity gives every lane the same bits) for a power-of-two team,
# else a tree to lane 0 and lane 0's value to every lane; the separators' reduced system is solved
# by parallel cyclic reduction (make_exchange_team). "emulated" runs the same operations with each
# shuffle through a tile, on the CPU's fibers, so that the CPU tests the algorithms the GPU runs.

# the CUDA side of the shuffles: the lanes' mask, a double as two 32-bit halves, one shuffle of each
_SHUFFLE_PRELUDE = r"""
    const unsigned mask = lanes >= 32 ? 0xffffffffu : ((1u << lanes) - 1u);
    #define WF_SHFL64(kind, clamp, value, lane_arg, out) { \
        unsigned lo_, hi_; \
        asm("mov.b64 {%0, %1}, %2;" : "=r"(lo_), "=r"(hi_) : "d"(value)); \
        asm volatile("shfl.sync." kind ".b32 %0, %1, %2, " clamp ", %3;" : "=r"(lo_) : "r"(lo_), "r"(lane_arg), "r"(mask)); \
        asm volatile("shfl.sync." kind ".b32 %0, %1, %2, " clamp ", %3;" : "=r"(hi_) : "r"(hi_), "r"(lane_arg), "r"(mask)); \
        asm("mov.b64 %0, {%1, %2};" : "=d"(out) : "r"(lo_), "r"(hi_)); }
"""


def _reduction_snippet(ctype: str, combine: str) -> str:
    """A warp reduction of x over ``lanes`` lanes (CUDA; the CPU never runs it): a butterfly for a
    power-of-two team, else a tree to lane 0 and lane 0's value to every lane. ``combine`` merges
    v and other."""
    if ctype == "double":
        shfl = lambda kind, clamp, lane, out: f'WF_SHFL64("{kind}", "{clamp}", v, {lane}, {out});'  # noqa: E731
    else:
        shfl = lambda kind, clamp, lane, out: (  # noqa: E731
            f'asm volatile("shfl.sync.{kind}.b32 %0, %1, %2, {clamp}, %3;" : "=r"({out}) : "r"(v), "r"({lane}), "r"(mask));')
    return (r"""
#if defined(__CUDA_ARCH__)
""" + _SHUFFLE_PRELUDE + f"""
    {ctype} v = x;
    if ((lanes & (lanes - 1)) == 0) {{
        for (int s = lanes >> 1; s > 0; s >>= 1) {{
            {ctype} other;
            {shfl("bfly", "0x1f", "s", "other")}
            v = {combine};
        }}
    }} else {{
        const int lane = threadIdx.x & 31;  // the lane in its warp (a block may hold a member per warp)
        int top = 1;
        while (top * 2 < lanes) top *= 2;
        for (int s = top; s > 0; s >>= 1) {{
            {ctype} other;
            {shfl("down", "0x1f", "s", "other")}
            if (lane + s < lanes) v = {combine};
        }}
        {ctype} first;
        const int zero = 0;
        {shfl("idx", "0x1f", "zero", "first")}
        v = first;
    }}
    return v;
#else
    return x;  // never used: the shuffle team is built for CUDA devices only
#endif
""")


@wp.func_native(_reduction_snippet("double", "v + other"))
def warp_sum_f64(x: wp.float64, lanes: int) -> wp.float64:
    """The sum of x over the team's lanes, the same bits in every lane (warp shuffles)."""
    ...


@wp.func_native(_reduction_snippet("double", "fmax(v, other)"))
def warp_max_f64(x: wp.float64, lanes: int) -> wp.float64:
    """The maximum of x over the team's lanes (warp shuffles; a NaN is dropped, as fmax does)."""
    ...


@wp.func_native(_reduction_snippet("double", "fmin(v, other)"))
def warp_min_f64(x: wp.float64, lanes: int) -> wp.float64:
    """The minimum of x over the team's lanes (warp shuffles)."""
    ...


@wp.func_native(_reduction_snippet("int", "v + other"))
def warp_sum_i32(x: int, lanes: int) -> int:
    """The sum of x over the team's lanes (warp shuffles)."""
    ...


def _move_snippet(kind: str, clamp: str) -> str:
    return (r"""
#if defined(__CUDA_ARCH__)
""" + _SHUFFLE_PRELUDE + f"""
    double v = x;
    double out;
    WF_SHFL64("{kind}", "{clamp}", v, delta, out);
    return out;
#else
    return x;  // never used: the shuffle team is built for CUDA devices only
#endif
""")


@wp.func_native(_move_snippet("up", "0"))
def warp_up_f64(x: wp.float64, delta: int, lanes: int) -> wp.float64:
    """x of lane - delta (a lane below delta gets its own x: callers do not use it)."""
    ...


@wp.func_native(_move_snippet("down", "0x1f"))
def warp_down_f64(x: wp.float64, delta: int, lanes: int) -> wp.float64:
    """x of lane + delta (undefined from lane lanes - delta on, in a partial warp: callers replace
    it, and never compute with it)."""
    ...


@wp.func_native(r"""
#if defined(__CUDA_ARCH__)
    __syncwarp(lanes >= 32 ? 0xffffffffu : ((1u << lanes) - 1u));
#endif
""")
def warp_sync(lanes: int):
    """The team's lanes wait for each other; their global-memory writes before it are seen by all
    after it (__syncwarp)."""
    ...


@wp.func_native(r"""
#if defined(__CUDA_ARCH__)
#if __CUDA_ARCH__ >= 700
    asm volatile("barrier.sync 0;" ::: "memory");
#else
    __syncthreads();
#endif
#endif
""")
def block_barrier():
    """The warps of a thread block wait for each other: PTX barrier.sync 0 without .aligned, which
    may be reached from different places and waits for the non-exited threads only (a warp that
    has left the kernel no longer counts). It orders nothing the kernel relies on: it only keeps a
    block's members at the same place in the code (docs/performance.md)."""
    ...


@wp.func_native("return (int)WP_TILE_THREAD_IDX;")
def lane_index() -> int:
    """This thread's lane in its team (the thread's index in its tile block; CPU fibers included)."""
    ...


# ---- a team of several warps (exchange = "shuffle", lanes a multiple of 32 up to MAX_TEAM_LANES) ----
# Its lanes reduce inside their warp by the shuffles above, and the warps combine their partial
# results through a small static shared buffer, the same for every team operation: each operation
# is a block barrier (the lanes' global-memory writes seen by all, and the buffer's last reads
# done), its writes into the buffer, another barrier and its reads. A neighbour's value comes
# through the buffer too (a lane at a warp's edge has its neighbour in the next warp). The member
# is the thread block (one member per block: kernels/integrator.py blocked_layout).
WARP_SIZE = 32  # threads of a warp: a team of at most this many lanes is one warp
MAX_TEAM_LANES = 256  # 8 warps: at 255 registers per thread one such block fills an SM's registers
TEAM_BUFFER_ROWS = 12  # the buffer's rows: the widest exchange (a vec12d's partial sums, a vec6d row)
_TEAM_BUFFER_LEN = TEAM_BUFFER_ROWS * MAX_TEAM_LANES
TEAM_BUFFER_BYTES = 8 * _TEAM_BUFFER_LEN  # the static shared memory it takes (kernels/integrator.py team_layout)


@wp.func_native(f"""
#if defined(__CUDA_ARCH__)
    __shared__ double wf_team_buffer[{_TEAM_BUFFER_LEN}];
    return (uint64_t)(wf_team_buffer);
#else
    return 0;  // never used: a team of several warps is built for CUDA devices only
#endif
""")
def team_buffer_base() -> wp.uint64:
    """The address of the block's team buffer: TEAM_BUFFER_ROWS x MAX_TEAM_LANES float64 of static
    shared memory (24 KB), through which a team of several warps exchanges values."""
    ...


@wp.func_native(r"""
#if defined(__CUDA_ARCH__)
    __syncthreads();
#endif
""")
def team_block_sync():
    """Every thread of the block waits for the others; their shared- and global-memory writes before
    it are seen by all after it (__syncthreads)."""
    ...


# ---- the same operations through a tile (exchange = "emulated") ----

@wp.func
def tile_value(x: Any, source: int):
    """Lane ``source``'s x through a tile (the CPU's fibers)."""
    r = wp.tile_extract(wp.tile(x), source)
    settle()
    return r


@wp.func
def plus(a: Any, b: Any):
    return a + b


@wp.func
def larger(a: Any, b: Any):
    return wp.max(a, b)


@wp.func
def smaller(a: Any, b: Any):
    return wp.min(a, b)


def make_emulated_shuffles(lanes: int):
    """warp_sum_f64, .., warp_sync of a team of ``lanes`` with each shuffle through a tile, in the
    same order of operations (for several warps, those of make_warps_team)."""
    warps = warps_of(lanes)
    in_warp = lanes if warps == 1 else WARP_SIZE  # the lanes a butterfly spans
    power_of_two = in_warp & (in_warp - 1) == 0
    levels = max(1, (in_warp - 1).bit_length())  # ceil(log2(in_warp))

    @wp.func
    def partner(v: Any, lane: int, s: int):
        """The butterfly's partner lane ^ s, or the tree's lane + s (clamped; masked by callers)."""
        if wp.static(power_of_two):
            return tile_value(v, lane ^ s)
        return tile_value(v, wp.min(lane + s, lanes - 1))

    @wp.func
    def merged(lane: int, s: int):
        """Whether a lane merges its partner's value at stride s."""
        return wp.static(power_of_two) or lane + s < lanes

    def reduction(combine):
        """The reduction of _reduction_snippet, merging with ``combine``: a butterfly for a
        power-of-two team, else a tree to lane 0 and lane 0's value to every lane; for a team of
        several warps (make_warps_team) a butterfly inside each warp, then the warps' results
        merged in the warps' order."""

        @wp.func
        def reduce(x: Any, lanes_: int):
            lane = lane_index()
            v = x
            s = int(1 << (levels - 1))
            for _level in range(levels):
                other = partner(v, lane, s)
                if merged(lane, s):
                    v = combine(v, other)
                s = s // 2
            if wp.static(not power_of_two):
                v = tile_value(v, 0)
            if wp.static(warps > 1):
                r = tile_value(v, 0)
                for w in range(1, warps):
                    r = combine(r, tile_value(v, w * WARP_SIZE))
                v = r
            return v

        return reduce

    total = reduction(plus)

    @wp.func
    def up_f64(x: wp.float64, delta: int, lanes_: int):
        return tile_value(x, wp.max(lane_index() - delta, 0))

    @wp.func
    def down_f64(x: wp.float64, delta: int, lanes_: int):
        return tile_value(x, wp.min(lane_index() + delta, lanes - 1))

    @wp.func
    def sync(lanes_: int):
        settle()

    return dict(sum_f64=total, max_f64=reduction(larger), min_f64=reduction(smaller), sum_i32=total,
                up_f64=up_f64, down_f64=down_f64, sync=sync)


def exchanges_by_value(lanes: int) -> bool:
    """Whether a team of ``lanes`` can exchange by value (shuffles, or their emulation): one warp (at
    most 32 lanes) or whole warps up to MAX_TEAM_LANES."""
    return lanes <= WARP_SIZE or (lanes % WARP_SIZE == 0 and lanes <= MAX_TEAM_LANES)


def warps_team(lanes: int, exchange: str) -> bool:
    """Whether a team of ``lanes`` with its lane exchange is a team of several warps on a GPU
    (make_warps_team): one member a block, the block's threads its lanes."""
    return exchange == "shuffle" and lanes > WARP_SIZE


def warps_of(lanes: int) -> int:
    """The warps of a team that exchanges by value: 1 for at most 32 lanes, else lanes / 32 (a team
    of several warps has full warps only, at most MAX_TEAM_LANES lanes)."""
    if lanes <= WARP_SIZE:
        return 1
    if not exchanges_by_value(lanes):
        raise ValueError(f"a team of {lanes} lanes that exchanges by value is invalid: at most {WARP_SIZE} lanes, "
                         f"or a multiple of {WARP_SIZE} up to {MAX_TEAM_LANES}")
    return lanes // WARP_SIZE


def make_warps_team(lanes: int):
    """The operations of make_exchange_team for a team of several warps on a GPU: reductions by
    shuffles inside each warp and the warps' results merged in the warps' order through the team
    buffer; the neighbours' values through the buffer (team_buffer_base)."""
    warps = warps_of(lanes)

    @wp.func
    def team_buffer():
        """The block's team buffer, (TEAM_BUFFER_ROWS, MAX_TEAM_LANES) float64 in shared memory."""
        return wp.array(ptr=team_buffer_base(), shape=(TEAM_BUFFER_ROWS, MAX_TEAM_LANES), dtype=wp.float64)

    def merged_in_warp_order(combine):
        """Row ``row`` of the buffer's first ``warps`` columns (each warp's result, written before
        a block barrier) merged with ``combine`` in the warps' order: the same bits in every lane."""

        @wp.func
        def merge(row: int):
            buffer = team_buffer()
            r = buffer[row, 0]
            for w in range(1, warps):
                r = combine(r, buffer[row, w])
            return r

        return merge

    merged_sum = merged_in_warp_order(plus)

    @wp.func
    def publish(warp_result: wp.float64):
        """Each warp's first lane writes its warp's result into the buffer's row 0; a block barrier."""
        lane = lane_index()
        if lane % WARP_SIZE == 0:
            buffer = team_buffer()
            buffer[0, lane // WARP_SIZE] = warp_result
        team_block_sync()

    def reduction(in_warp, merge):
        """A reduction over the team (called after ``sync``, which leaves the buffer free): the
        warp's result by shuffles (``in_warp``), each warp's written by its first lane, merged in
        warp order (``merge``, of merged_in_warp_order)."""

        @wp.func
        def reduce(x: wp.float64, lanes_: int):
            publish(in_warp(x, WARP_SIZE))
            return merge(0)

        return reduce

    total = reduction(warp_sum_f64, merged_sum)

    @wp.func
    def sum12(x: vec12d):
        """The sums of a vec12d's components over the team (after ``sync``): each component as
        ``total`` sums it, with one barrier for the twelve."""
        v = vec12d()
        for k in range(12):
            v[k] = warp_sum_f64(x[k], WARP_SIZE)
        lane = lane_index()
        if lane % WARP_SIZE == 0:
            buffer = team_buffer()
            for k in range(12):
                buffer[k, lane // WARP_SIZE] = v[k]
        team_block_sync()
        r = vec12d()
        for k in range(12):
            r[k] = merged_sum(k)
        return r

    @wp.func
    def sum_i32(x: int, lanes_: int):
        """The sum of an int over the team (the warps' sums pass through the float64 buffer, exact
        for the counts a team sums)."""
        publish(wp.float64(warp_sum_i32(x, WARP_SIZE)))
        return int(merged_sum(0))

    def neighbours(vector, length: int):
        """The vector x of lanes - delta and + delta (clamped to the team: callers do not use a
        value from beyond its edges), one write of each lane's x into the buffer. ``level``: 0 for
        an exchange of its own, which first waits for the lanes (their global-memory writes and
        the buffer's last reads: a team operation's barrier); k > 0 for the k-th level of the
        cyclic reduction, which writes into the other half of the buffer than level k - 1 and
        needs no barrier first: the half it writes was last read at level k - 2 (or before level
        0's leading barrier), and every lane did those reads before level k - 1's barrier."""

        @wp.func
        def both(x: vector, delta: int, level: int):
            lane = lane_index()
            buffer = team_buffer()
            half = (level % 2) * (TEAM_BUFFER_ROWS // 2)
            if level == 0:
                team_block_sync()
            for k in range(length):
                buffer[half + k, lane] = x[k]
            team_block_sync()
            below = wp.max(lane - delta, 0)
            above = wp.min(lane + delta, lanes - 1)
            up = vector()
            dn = vector()
            for k in range(length):
                up[k] = buffer[half + k, below]
                dn[k] = buffer[half + k, above]
            return up, dn

        return both

    @wp.func
    def sync(lanes_: int):
        team_block_sync()

    return dict(sum_f64=total, max_f64=reduction(warp_max_f64, merged_in_warp_order(larger)),
                min_f64=reduction(warp_min_f64, merged_in_warp_order(smaller)), sum_i32=sum_i32, sum12=sum12, sync=sync,
                neighbours=neighbours)


def make_exchange_team(lanes: int, exchange: str):
    """The team's operations (those of make_tile_reductions and make_separator_exchange) on the lane
    exchange by value: ``exchange`` = "shuffle" (warp shuffles: CUDA, lanes <= 32, or whole warps up
    to MAX_TEAM_LANES through make_warps_team) or "emulated" (the same through a tile)."""
    if warps_team(lanes, exchange):
        ops = make_warps_team(lanes)
    elif exchange == "shuffle":
        ops = dict(sum_f64=warp_sum_f64, max_f64=warp_max_f64, min_f64=warp_min_f64, sum_i32=warp_sum_i32,
                   up_f64=warp_up_f64, down_f64=warp_down_f64, sync=warp_sync)
    else:
        ops = make_emulated_shuffles(lanes)
    sum_f64, max_f64, min_f64, sum_i32 = ops["sum_f64"], ops["max_f64"], ops["min_f64"], ops["sum_i32"]
    sync = ops["sync"]
    levels = max(1, (lanes - 1).bit_length())  # ceil(log2(lanes)): the cyclic reduction's levels

    if "neighbours" in ops:  # a team of several warps: through its buffer, each exchange its own barrier
        both3, both4 = ops["neighbours"](vec3d, 3), ops["neighbours"](vec4d, 4)
        both5, rows, sum12 = ops["neighbours"](vec5d, 5), ops["neighbours"](vec6d, 6), ops["sum12"]

        @wp.func
        def next5(x: vec5d):
            """x of lane + 1, after the team's barrier (undefined for the last lane)."""
            _prev, nxt = both5(x, 1, 0)
            return nxt

        @wp.func
        def prev_next4(x: vec4d):
            """x of lanes - 1 and + 1, after the team's barrier (undefined beyond the edges)."""
            return both4(x, 1, 0)

        @wp.func
        def prev3(x: vec3d):
            """x of lane - 1 (undefined for lane 0)."""
            prev, _next = both3(x, 1, 0)
            return prev
    else:
        up_f64, down_f64 = ops["up_f64"], ops["down_f64"]

        def vector_move(vector, length: int, move):
            """The vector x of lane -/+ delta, component by component through ``move`` (up_f64 or
            down_f64: what they say of lanes beyond the team's edges holds here)."""

            @wp.func
            def moved(x: vector, delta: int):
                out = vector()
                for k in range(length):
                    out[k] = move(x[k], delta, lanes)
                return out

            return moved

        up3 = vector_move(vec3d, 3, up_f64)
        up4, down4 = vector_move(vec4d, 4, up_f64), vector_move(vec4d, 4, down_f64)
        down5 = vector_move(vec5d, 5, down_f64)
        up6, down6 = vector_move(vec6d, 6, up_f64), vector_move(vec6d, 6, down_f64)

        @wp.func
        def next5(x: vec5d):
            sync(lanes)
            return down5(x, 1)

        @wp.func
        def prev_next4(x: vec4d):
            sync(lanes)
            return up4(x, 1), down4(x, 1)

        @wp.func
        def prev3(x: vec3d):
            return up3(x, 1)

        @wp.func
        def rows(x: vec6d, s: int, level: int):
            """The rows of lanes - s and + s."""
            return up6(x, s), down6(x, s)

        @wp.func
        def sum12(x: vec12d):
            return vec12d(sum_f64(x[0], lanes), sum_f64(x[1], lanes), sum_f64(x[2], lanes), sum_f64(x[3], lanes),
                          sum_f64(x[4], lanes), sum_f64(x[5], lanes), sum_f64(x[6], lanes), sum_f64(x[7], lanes),
                          sum_f64(x[8], lanes), sum_f64(x[9], lanes), sum_f64(x[10], lanes), sum_f64(x[11], lanes))

    @wp.func
    def team_sum(x: wp.float64):
        sync(lanes)
        return sum_f64(x, lanes)

    @wp.func
    def team_max(x: wp.float64):
        """Maximum over the lanes (a NaN lane value is dropped: callers map non-finite to inf)."""
        sync(lanes)
        return max_f64(x, lanes)

    @wp.func
    def team_min(x: wp.float64):
        sync(lanes)
        return min_f64(x, lanes)

    @wp.func
    def team_count(x: int):
        sync(lanes)
        return sum_i32(x, lanes)

    @wp.func
    def barrier():
        """Every lane's writes before this call are seen by every lane after it."""
        sync(lanes)

    @wp.func
    def team_sum_vec12(x: vec12d):
        sync(lanes)
        return sum12(x)

    @wp.func
    def from_next_lane(x: vec5d, lane: int):
        """The value of lane + 1 (zero for the last lane)."""
        out = next5(x)
        if lane + 1 >= lanes:
            out = vec5d()
        return out

    @wp.func
    def from_neighbour_lanes(x: vec4d, lane: int):
        """The values of lane - 1 and lane + 1 (zero beyond the first and the last lane)."""
        prev, nxt = prev_next4(x)
        if lane == 0:
            prev = vec4d()
        if lane + 1 >= lanes:
            nxt = vec4d()
        return prev, nxt

    @wp.func
    def reduced_solve(row: vec6d, lane: int):
        """The separators of the partitioned tridiagonal solve (as the tile team's reduced_solve:
        row = (A, B, C, D0, D1, D2) of row k, returns (E_{k-1}, E_k)) by parallel cyclic
        reduction: at stride s = 1, 2, 4, .. each row eliminates its couplings to rows k - s and
        k + s with those rows, which couples it to rows k - 2s and k + 2s, until no coupling is
        left inside the team; then E_k = D_k / B_k. Diagonal dominance (the Newton matrix has it)
        keeps it stable without pivoting, as it does the Thomas algorithm."""
        r = row
        if lane == 0:
            r[0] = wp.float64(0.0)
        if lane + 1 >= lanes:
            r[2] = wp.float64(0.0)
        s = int(1)
        for level in range(levels):
            # row k - s (up) and row k + s (down); a coupling across the team's edge is zero at
            # every level
            up, dn = rows(r, s, level)
            # the rows beyond the team's edges are not read, not even multiplied by zero: a
            # shuffle from beyond a partial warp's last lane returns an undefined value (NaN * 0)
            new = vec6d(wp.float64(0.0), r[1], wp.float64(0.0), r[3], r[4], r[5])
            if lane - s >= 0:
                alpha = -r[0] / up[1]
                new[0] = alpha * up[0]
                new[1] = new[1] + alpha * up[2]
                for k in range(3, 6):
                    new[k] = new[k] + alpha * up[k]
            if lane + s < lanes:
                gamma = -r[2] / dn[1]
                new[2] = gamma * dn[2]
                new[1] = new[1] + gamma * dn[0]
                for k in range(3, 6):
                    new[k] = new[k] + gamma * dn[k]
            r = new
            s = s * 2
        inv = wp.float64(1.0) / r[1]
        e_self = vec3d(r[3] * inv, r[4] * inv, r[5] * inv)
        e_prev = prev3(e_self)
        if lane == 0:
            e_prev = vec3d()
        return e_prev, e_self

    return dict(team_max=team_max, team_min=team_min, team_sum=team_sum, team_count=team_count, barrier=barrier,
                team_sum_vec12=team_sum_vec12, from_next_lane=from_next_lane,
                from_neighbour_lanes=from_neighbour_lanes, reduced_solve=reduced_solve)


EXCHANGES = ("tile", "shuffle", "emulated")


def make_team(ft, lanes: int, exchange: str = "tile"):
    """Reductions over a member's team (identity for lanes = 1) and the separator exchange of the
    team's tridiagonal solve: through Warp's tiles (exchange = "tile"), warp shuffles ("shuffle":
    CUDA, at most 32 lanes or whole warps up to MAX_TEAM_LANES) or the shuffles' algorithms through
    a tile ("emulated")."""
    if lanes == 1:
        return make_solo()
    if ft != wp.float64:
        raise ValueError("a team of lanes needs float64")
    if exchange not in EXCHANGES:
        raise ValueError(f"team exchange {exchange!r} is invalid; valid: {', '.join(EXCHANGES)}")
    if exchange == "tile":
        return dict(lanes=lanes, exchange=exchange, **make_tile_reductions(lanes), **make_separator_exchange(lanes))
    warps_of(lanes)  # refuses a team of several warps that are not full, or of more than MAX_TEAM_LANES
    return dict(lanes=lanes, exchange=exchange, block_barrier=block_barrier, **make_exchange_team(lanes, exchange))
