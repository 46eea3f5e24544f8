"""In-kernel reductions over time: memory independent of the number of steps.

mu_s (SPEC section 7) is the maximum over time of mu(t) = sign(v_max) * int tau_f dx / int sigma_n dx.
Sampling mu only at accepted steps would miss the peak by O(h^2 * mu''); each time the middle of
the last three accepted points is a local maximum, the parabola through the three points is
maximised instead (docs/model.md, "Outputs").
"""


import warp as wp

from .types import FRONT_ABSOLUTE, FRONT_WITH_DISC, IntegratorState


# a refined maximum may rise above the discrete one by at most this many times the largest fall from
# it to the points the refinement rests on (peak_within_falls)
PEAK_RISE_FACTOR = 5.0


@wp.func
def peak_within_falls(peak: wp.float64, middle: wp.float64, lowest: wp.float64):
    """Whether a refined maximum ``peak`` of a curve through accepted points whose value ``middle``
    is a discrete maximum rises above it by at most PEAK_RISE_FACTOR times the largest fall from it,
    to ``lowest`` (the least of the other points' values). A kink does not pass: mu(t) falls from
    ~0.02 to ~0 within microseconds where a fast disc starts, and a parabola through a long step
    and that drop rose to mu = 79.6 (F = 5e4 N, v = 0.03 m/s, N = 40); over 300 random members (N =
    30, both laws and methods, |2e/L| <= 0.6, F = 10 N-300 kN, |v| = 1e-6-0.3 m/s) such vertices
    rose 9.5 to 33,578 times the fall, and those kept rose at most 3.7 times it (a parabola whose
    step before the vertex's interval was 8 us and the next 122 ms: an exact parabola's rise is up
    to 1/(4r(1+r)) times the fall, r the ratio of its two steps, so a smooth maximum between steps
    of very different lengths can exceed any factor). Where the refinement does not pass, the
    discrete maximum stands."""
    return peak - middle <= wp.float64(PEAK_RISE_FACTOR) * (middle - lowest)


@wp.func
def record_friction_point(st: IntegratorState, t: wp.float64, mu: wp.float64):
    """Fold the accepted point (t, mu) into the running maximum of ``st`` and return ``st``."""
    if mu > st.mu_s:  # mu_s starts at -inf (set by the host)
        st.mu_s = mu
        st.mu_s_time = t
    st = parabola_peak(st, t, mu)
    return shift_friction_points(st, t, mu)


@wp.func
def parabola_peak(st: IntegratorState, t: wp.float64, mu: wp.float64):
    """``st`` with mu_s raised to the vertex of the parabola through the last two stored points and
    (t, mu), where the middle one is a discrete maximum and the vertex passes peak_within_falls."""
    if st.npts >= 2 and st.mu1 >= st.mu2 and st.mu1 >= mu and t > st.t1 and st.t1 > st.t2:
        d1 = (st.mu1 - st.mu2) / (st.t1 - st.t2)
        d2 = (mu - st.mu1) / (t - st.t1)
        curv = (d2 - d1) / (t - st.t2)
        if curv < wp.float64(0.0):
            t_peak = wp.float64(0.5) * (st.t1 + st.t2) - d1 / (wp.float64(2.0) * curv)
            if t_peak >= st.t2 and t_peak <= t:
                mu_peak = st.mu2 + d1 * (t_peak - st.t2) + curv * (t_peak - st.t2) * (t_peak - st.t1)
                lowest = wp.min(st.mu2, mu)
                if st.npts >= 3:
                    lowest = wp.min(lowest, st.mu3)
                if mu_peak > st.mu_s and peak_within_falls(mu_peak, st.mu1, lowest):
                    st.mu_s = mu_peak
                    st.mu_s_time = t_peak
    return st


@wp.func
def shift_friction_points(st: IntegratorState, t: wp.float64, mu: wp.float64):
    """The accepted point (t, mu) becomes the newest of the stored points (t1, t2, t3 shift back)."""
    st.t3 = st.t2
    st.mu3 = st.mu2
    st.t2 = st.t1
    st.mu2 = st.mu1
    st.t1 = t
    st.mu1 = mu
    st.mu_final = mu
    st.npts = st.npts + 1
    return st


@wp.func
def record_friction_point_cubic(st: IntegratorState, t: wp.float64, mu: wp.float64):
    """record_friction_point with a cubic instead of the parabola (ESDIRK4, Solver.method =
    'esdirk4': its long steps make the parabola's O(h^3) error the largest in mu_s): when the last
    point t1 is a discrete maximum (mu1 >= mu2, mu1 >= mu), the maximum of the cubic through the
    last four accepted points (t3, t2, t1, t) on [t2, t] where it passes peak_within_falls, else the
    parabola's vertex where that passes; the parabola while fewer than four points."""
    if st.npts < 3:
        return record_friction_point(st, t, mu)
    if mu > st.mu_s:
        st.mu_s = mu
        st.mu_s_time = t
    if st.mu1 >= st.mu2 and st.mu1 >= mu and t > st.t1 and st.t1 > st.t2 and st.t2 > st.t3:
        # Newton form on s = time - t1 with the nodes s0 = t3 - t1, s1 = t2 - t1, 0, s3 = t - t1
        s0 = st.t3 - st.t1
        s1 = st.t2 - st.t1
        s3 = t - st.t1
        f01 = (st.mu2 - st.mu3) / (s1 - s0)
        f12 = (st.mu1 - st.mu2) / (wp.float64(0.0) - s1)
        f23 = (mu - st.mu1) / s3
        f012 = (f12 - f01) / (wp.float64(0.0) - s0)
        f123 = (f23 - f12) / (s3 - s1)
        f0123 = (f123 - f012) / (s3 - s0)
        # power form around t1: p(s) = mu1 + a1 s + a2 s^2 + a3 s^3
        a1 = f01 - f012 * (s0 + s1) + f0123 * s0 * s1
        a2 = f012 - f0123 * (s0 + s1)
        a3 = f0123
        # p'(s) = a1 + 2 a2 s + 3 a3 s^2 = 0, a root in [s1, s3] with p'' < 0
        best = st.mu_s
        best_s = wp.float64(0.0)
        found = int(0)
        qa = wp.float64(3.0) * a3
        qb = wp.float64(2.0) * a2
        disc = qb * qb - wp.float64(4.0) * qa * a1
        if disc >= wp.float64(0.0):
            sq = wp.sqrt(disc)
            qq = wp.float64(-0.5) * (qb + wp.sign(qb) * sq)
            if qb == wp.float64(0.0):
                qq = wp.float64(-0.5) * sq
            for k in range(2):
                root = wp.float64(0.0)
                valid = False
                if k == 0 and qa != wp.float64(0.0):
                    root = qq / qa
                    valid = True
                if k == 1 and qq != wp.float64(0.0):
                    root = a1 / qq
                    valid = True
                if valid and root >= s1 and root <= s3 and qb + wp.float64(2.0) * qa * root < wp.float64(0.0):
                    val = st.mu1 + root * (a1 + root * (a2 + root * a3))
                    if val > best:
                        best = val
                        best_s = root
                        found = 1
        if found == 1 and peak_within_falls(best, st.mu1, wp.min(wp.min(st.mu3, st.mu2), mu)):
            st.mu_s = best
            st.mu_s_time = st.t1 + best_s
        elif found == 1:  # the cubic rose too far: the parabola, if it passes
            st = parabola_peak(st, t, mu)
    return shift_friction_points(st, t, mu)


# ------------------------------------------------------------------------------------------------
# Detachment fronts (SPEC section 7, docs/model.md "Fronts")
# ------------------------------------------------------------------------------------------------


@wp.func
def detachment_velocity(velocity: wp.float64, disc_sign: wp.float64, direction: int):
    """The detachment velocity w (m/s) of a pad velocity u_t (m/s): -sign(v_max)*u_t for
    FRONT_AGAINST_DISC, sign(v_max)*u_t for FRONT_WITH_DISC, |u_t| for FRONT_ABSOLUTE."""
    if direction == FRONT_ABSOLUTE:
        return wp.abs(velocity)
    if direction == FRONT_WITH_DISC:
        return disc_sign * velocity
    return -disc_sign * velocity


@wp.func
def crossing_time(level: wp.float64, t_old: wp.float64, w_old: wp.float64, t_new: wp.float64, w_new: wp.float64):
    """First time in [t_old, t_new] at which the linear interpolant of w between two accepted points
    reaches ``level``; requires w_new >= level. t_old when w_old already is at or above it."""
    if w_old >= level:
        return t_old
    return t_old + (t_new - t_old) * (level - w_old) / (w_new - w_old)


@wp.func
def crossing_time_quadratic(
    level: wp.float64, t_old: wp.float64, w_old: wp.float64, c_mid: wp.float64, w_mid: wp.float64,
    t_new: wp.float64, w_new: wp.float64,
):
    """First time in [t_old, t_new] at which the quadratic through (t_old, w_old), (t_old +
    c_mid*h, w_mid) and (t_new, w_new) reaches ``level`` (the middle point: the step's second
    stage), and the difference to the linear interpolant's crossing, an estimate of the crossing's
    time-discretisation error (s). Falls back to the linear crossing where the quadratic has no
    root in the step. Requires w_new >= level or w_mid >= level."""
    h = t_new - t_old
    t_lin = t_new
    if w_new >= level:
        t_lin = crossing_time(level, t_old, w_old, t_new, w_new)
    if w_old >= level:
        return t_old, wp.float64(0.0)
    b = ((w_mid - w_old) - c_mid * (w_new - w_old)) / (c_mid * (c_mid - wp.float64(1.0)))
    a = (w_new - w_old) - b
    tau = wp.float64(-1.0)
    if wp.abs(b) <= wp.float64(1.0e-12) * (wp.abs(a) + wp.abs(w_old - level)):
        if a > wp.float64(0.0):
            tau = (level - w_old) / a
    else:
        disc = a * a - wp.float64(4.0) * b * (w_old - level)
        if disc >= wp.float64(0.0):
            sq = wp.sqrt(disc)
            r1 = (-a - sq) / (wp.float64(2.0) * b)
            r2 = (-a + sq) / (wp.float64(2.0) * b)
            lo = wp.min(r1, r2)
            hi = wp.max(r1, r2)
            if lo >= wp.float64(0.0) and lo <= wp.float64(1.0):
                tau = lo
            elif hi >= wp.float64(0.0) and hi <= wp.float64(1.0):
                tau = hi
    if tau < wp.float64(0.0) or tau > wp.float64(1.0):
        return t_lin, wp.float64(0.0)
    t_quad = t_old + tau * h
    return t_quad, wp.abs(t_quad - t_lin)


# rows of the front-metrics output array (out[row, member]); simulate() names them
FM_NUCLEATION_POSITION = 0
FM_NUCLEATION_EDGE = 1
FM_FIRST_ARRIVAL = 2
FM_LAST_ARRIVAL = 3
FM_ARRIVED_FRACTION = 4
# then start, end, length, speed of the first front's left, middle and right segments, of the whole
# first front and of the whole second front (write_segment's index 0..4)
FM_SEGMENTS = 5
SEGMENT_FIRST = 3
SEGMENT_SECOND = 4
FM_FRONT_COUNT = FM_SEGMENTS + 20
FM_COLLISION_POSITION = FM_SEGMENTS + 21
FM_COLLISION_TIME = FM_SEGMENTS + 22
FM_SECOND_NUCLEATION_POSITION = FM_SEGMENTS + 23
FM_SECOND_FIRST_ARRIVAL = FM_SEGMENTS + 24
N_FRONT_METRICS = FM_SEGMENTS + 25
MODE_WIDTH = 0.0953  # log(1.1): local speeds within 10 % count to the same plateau


@wp.struct
class SegmentSettings:
    min_nodes: wp.int32  # fewest node intervals of a segment
    fast_fraction: wp.float64  # v_fast: the plateau speed among this fastest fraction of the intervals
    speed_ratio: wp.float64  # slow: local speed below v_fast / speed_ratio
    edge_zone_fraction: wp.float64  # nucleation within this fraction of its own L of an edge is at that edge


@wp.func
def median3(a: wp.float64, b: wp.float64, c: wp.float64):
    return wp.max(wp.min(a, b), wp.min(wp.max(a, b), c))


@wp.func
def smooth_pass(sums: wp.array3d(dtype=wp.float64), m: int, src: int, dst: int, a: int, e: int):
    """Running median of three of row ``src`` over intervals a..e-1 into row ``dst`` (the end
    values are kept): removes isolated outliers and keeps steps exactly."""
    for j in range(a, e):
        v = sums[src, j, m]
        if j > a and j < e - 1:
            v = median3(sums[src, j - 1, m], v, sums[src, j + 1, m])
        sums[dst, j, m] = v


@wp.func
def segment_speed(
    arrival: wp.array2d(dtype=wp.float64), sums: wp.array3d(dtype=wp.float64), m: int, a: int, b: int,
    dx: wp.float64, i_first: int,
):
    """Mean front speed (m/s) over the nodes a..b (intervals a..b-1): the segment's length over the
    time the front takes to cross it, |t_a(x_b) - t_a(x_a)|, or, when the nucleation node i_first
    lies inside, the sum of the two branches' times from it. Endpoint times only, so the speed does
    not collect the arrival times' small errors node by node. Where an end never arrived: length
    over the summed |dt| of the usable intervals."""
    t_a = arrival[a, m]
    t_b = arrival[b, m]
    if wp.isfinite(t_a) and wp.isfinite(t_b):
        spent = wp.abs(t_b - t_a)
        if i_first > a and i_first < b:
            t0 = arrival[i_first, m]
            spent = (t_a - t0) + (t_b - t0)
        return wp.float64(b - a) * dx / spent
    s0 = sums[0, b, m] - sums[0, a, m]
    if s0 <= wp.float64(0.0):
        return wp.float64(wp.nan)
    return s0 * dx / (sums[1, b, m] - sums[1, a, m])


@wp.func
def node_position(index: wp.float64, L: wp.float64, dx: wp.float64):
    """x (m) of node ``index`` (a half-integer: midway between two nodes) on [-L/2, L/2]."""
    return -wp.float64(0.5) * L + index * dx


@wp.func
def write_segment(
    out: wp.array2d(dtype=wp.float64), m: int, which: int, a: int, b: int,
    L: wp.float64, dx: wp.float64, speed: wp.float64,
):
    """Start, end, length (m) and mean speed (m/s) of the segment of intervals a..b-1 into out."""
    start = node_position(wp.float64(a), L, dx)
    end = node_position(wp.float64(b), L, dx)
    row = FM_SEGMENTS + 4 * which
    out[row, m] = start
    out[row + 1, m] = end
    out[row + 2, m] = end - start
    out[row + 3, m] = speed


@wp.func
def nucleation(arrival: wp.array2d(dtype=wp.float64), m: int, n: int):
    """The earliest arrival: (its node i_first, -1 where no node arrived; its time t0, s; the number
    of arrived nodes)."""
    t0 = wp.float64(1.0e300)
    i_first = int(-1)
    arrived = int(0)
    for i in range(n):
        ta = arrival[i, m]
        if wp.isfinite(ta):
            arrived += 1
            if ta < t0:
                t0 = ta
                i_first = i
    return i_first, t0, arrived


@wp.func
def front_run(arrival: wp.array2d(dtype=wp.float64), m: int, n: int, i_first: int):
    """The front: the run of arrived nodes lo..hi around the nucleation node i_first; a node beyond a
    node that the front never reached is not part of it (no segment spans an unreached node)."""
    lo = i_first
    while lo > 0:
        if not wp.isfinite(arrival[lo - 1, m]):
            break
        lo -= 1
    hi = i_first
    while hi < n - 1:
        if not wp.isfinite(arrival[hi + 1, m]):
            break
        hi += 1
    return lo, hi


@wp.func
def front_basin(arrival: wp.array2d(dtype=wp.float64), m: int, lo: int, hi: int, i_start: int):
    """The nodes a..b of lo..hi that the front nucleating at i_start reaches before any other: from
    i_start outwards while t_a does not fall. A node whose outer neighbour arrived earlier is a
    meeting point with another front (a maximum of t_a(x)) and belongs to both, as does a flat top of
    equal times there."""
    a = i_start
    while a > lo:
        if arrival[a - 1, m] < arrival[a, m]:
            break
        a -= 1
    b = i_start
    while b < hi:
        if arrival[b + 1, m] < arrival[b, m]:
            break
        b += 1
    return a, b


@wp.func
def count_fronts(arrival: wp.array2d(dtype=wp.float64), m: int, lo: int, hi: int):
    """The number of fronts in lo..hi: the minima of t_a(x), a flat run of equal times counting
    once: a run whose neighbours on both sides arrive later (an end of lo..hi counts as later)."""
    count = int(0)
    i = lo
    while i <= hi:
        t = arrival[i, m]
        j = i
        while j < hi:
            if arrival[j + 1, m] != t:
                break
            j += 1
        left_later = True
        if i > lo:
            left_later = arrival[i - 1, m] > t
        right_later = True
        if j < hi:
            right_later = arrival[j + 1, m] > t
        if left_later and right_later:
            count += 1
        i = j + 1
    return count


@wp.func
def first_front_meeting(
    arrival: wp.array2d(dtype=wp.float64), m: int, lo: int, hi: int, a: int, e: int, L: wp.float64,
    dx: wp.float64, out: wp.array2d(dtype=wp.float64),
):
    """Where and when the first front (the nodes a..e of lo..hi, front_basin) meets another front into
    out: an end of a..e beyond which t_a falls, at the middle of the flat top of equal times there;
    the earlier of its two ends where both are meetings (the right one where they tie); NaN where
    neither is."""
    t_meet = wp.float64(wp.inf)
    x_meet = wp.float64(wp.nan)
    if e < hi:
        if arrival[e + 1, m] < arrival[e, m]:
            p = e
            while p > a:
                if arrival[p - 1, m] != arrival[e, m]:
                    break
                p -= 1
            t_meet = arrival[e, m]
            x_meet = node_position(wp.float64(0.5) * wp.float64(p + e), L, dx)
    if a > lo:
        if arrival[a - 1, m] < arrival[a, m] and arrival[a, m] < t_meet:
            q = a
            while q < e:
                if arrival[q + 1, m] != arrival[a, m]:
                    break
                q += 1
            t_meet = arrival[a, m]
            x_meet = node_position(wp.float64(0.5) * wp.float64(a + q), L, dx)
    if wp.isfinite(t_meet):
        out[FM_COLLISION_POSITION, m] = x_meet
        out[FM_COLLISION_TIME, m] = t_meet


@wp.func
def interval_sums(arrival: wp.array2d(dtype=wp.float64), sums: wp.array3d(dtype=wp.float64), m: int, n: int,
                  dx: wp.float64):
    """Rows of sums: 0, 1 prefix sums of the count of usable intervals and of the time spent |dt|
    (s); 2 the log slowness q = log(|dt|/dx) of interval j (+inf where an end never arrived: such
    intervals count as slow)."""
    sums[0, 0, m] = wp.float64(0.0)
    sums[1, 0, m] = wp.float64(0.0)
    for j in range(n - 1):
        t_l = arrival[j, m]
        t_r = arrival[j + 1, m]
        w = wp.float64(0.0)
        dt = wp.float64(0.0)
        q = wp.float64(wp.inf)
        if wp.isfinite(t_l) and wp.isfinite(t_r):
            w = wp.float64(1.0)
            dt = wp.abs(t_r - t_l)
            q = wp.log(wp.max(dt, wp.float64(1.0e-12) * dx) / dx)  # speeds above 1e12 m/s: simultaneous
        sums[0, j + 1, m] = sums[0, j, m] + w
        sums[1, j + 1, m] = sums[1, j, m] + dt
        sums[2, j, m] = q


@wp.func
def fast_log_slowness(sums: wp.array3d(dtype=wp.float64), m: int, a: int, e: int, fast_fraction: wp.float64):
    """The log slowness of the fast reference speed v_fast over intervals a..e-1: the plateau (mode)
    of the local speeds among the fastest fast_fraction of the usable intervals. q_cut: their
    slowest log slowness (an order statistic); the mode: the q_j with the most such q_i within
    +-MODE_WIDTH, averaged over those neighbours. O(N^2) once per member."""
    n_usable = int(sums[0, e, m] - sums[0, a, m])
    rank = int(wp.floor(fast_fraction * wp.float64(n_usable)))
    rank = wp.min(wp.max(rank, 0), n_usable - 1)
    q_cut = wp.float64(wp.inf)
    for j in range(a, e):
        qj = sums[2, j, m]
        if wp.isfinite(qj):
            below = int(0)
            at_most = int(0)
            for i in range(a, e):
                qi = sums[2, i, m]
                if qi < qj:
                    below += 1
                if qi <= qj:
                    at_most += 1
            if below <= rank and rank < at_most:
                q_cut = qj
    best_count = int(0)
    q_fast = wp.float64(wp.nan)
    for j in range(a, e):
        qj = sums[2, j, m]
        if qj <= q_cut:
            count = int(0)
            total = wp.float64(0.0)
            for i in range(a, e):
                qi = sums[2, i, m]
                if qi <= q_cut and wp.abs(qi - qj) <= wp.float64(MODE_WIDTH):
                    count += 1
                    total += qi
            # ties go to the faster plateau: the choice depends on the speeds only, not on where they
            # lie, so a mirrored front gets the mirrored segments
            if count > best_count or (count == best_count and total / wp.float64(count) < q_fast):
                best_count = count
                q_fast = total / wp.float64(count)
    return q_fast


@wp.func
def slow_end_segments(
    arrival: wp.array2d(dtype=wp.float64), sums: wp.array3d(dtype=wp.float64), m: int, a: int, e: int,
    dx: wp.float64, i_first: int, settings: SegmentSettings, slow_q: wp.float64,
):
    """The slow end segments a..b1 and b2..e (b1 = a, b2 = e: none) from the smoothed log slowness
    (row 4 of sums): the runs of intervals from each end slower than slow_q, each kept when it has
    at least min_nodes intervals, a fast part of as many lies between them and its mean speed is
    at most the middle's / speed_ratio. Returns (b1, b2)."""
    k = settings.min_nodes
    b1 = a
    while b1 < e:
        if sums[4, b1, m] <= slow_q:
            break
        b1 += 1
    b2 = e
    while b2 > b1:
        if sums[4, b2 - 1, m] <= slow_q:
            break
        b2 -= 1
    if b1 - a < k:
        b1 = a
    if e - b2 < k:
        b2 = e
    if b2 - b1 < k:  # no sustained fast part between them: one front
        b1 = a
        b2 = e
    # an end segment must also be markedly slower than the middle on average
    for _pass in range(2):
        v_mid = segment_speed(arrival, sums, m, b1, b2, dx, i_first)
        if b1 > a:
            if not (segment_speed(arrival, sums, m, a, b1, dx, i_first) * settings.speed_ratio <= v_mid):
                b1 = a
        if b2 < e:
            if not (segment_speed(arrival, sums, m, b2, e, dx, i_first) * settings.speed_ratio <= v_mid):
                b2 = e
    return b1, b2


@wp.kernel(enable_backward=False)
def segment_fronts(
    length: wp.array(dtype=wp.float64),
    arrival: wp.array2d(dtype=wp.float64),
    settings: SegmentSettings,
    sums: wp.array3d(dtype=wp.float64),
    out: wp.array2d(dtype=wp.float64),
):
    """Front metrics of each member from its arrival times t_a (s, nodes x members; NaN = never).

    The event is the run of arrived nodes around the nucleation node (the earliest arrival); nodes
    beyond an unreached node are not part of it (detached_fraction still counts every arrived node).
    Other fronts may nucleate elsewhere in the run (count_fronts: the minima of t_a(x)) and meet the
    first at a maximum of t_a(x): the first front is the nodes it reaches first (front_basin), and
    the segments are the first front's; the first front is also reported whole (SEGMENT_FIRST), with
    where and when it meets another (first_front_meeting). The second front is the one that
    nucleates next; its extent and mean speed are reported whole (SEGMENT_SECOND).
    The segmentation works on the intervals between neighbouring nodes of the first front, each
    with its local speed c_j = dx / |t_a(x_{j+1}) - t_a(x_j)|. v_fast is the plateau (mode within
    10 %) of the local speeds among the fastest fast_fraction of the intervals: the sustained speed
    of the fast front, not the unbounded local speed at an interior nucleation point. An interval is slow when its local speed,
    smoothed by two running medians of three, is below v_fast / speed_ratio. The left (right)
    segment is the run of slow intervals from the left (right) end; it exists when it has at least
    min_nodes intervals and its mean speed is at most v_middle / speed_ratio. The middle segment is
    the rest. Absent segments are NaN. Segment speeds are length / time spent (segment_speed)."""
    m = wp.tid()
    n = arrival.shape[0]
    for r in range(N_FRONT_METRICS):
        out[r, m] = wp.float64(wp.nan)
    L = length[m]
    dx = L / wp.float64(n - 1)
    i_first, t0, arrived = nucleation(arrival, m, n)
    out[FM_ARRIVED_FRACTION, m] = wp.float64(arrived) / wp.float64(n)
    if i_first < 0:
        return
    lo, hi = front_run(arrival, m, n, i_first)
    t_last = wp.float64(-1.0e300)
    for i in range(lo, hi + 1):
        t_last = wp.max(t_last, arrival[i, m])
    out[FM_NUCLEATION_POSITION, m] = node_position(wp.float64(i_first), L, dx)
    # the member's own edge zone (edge_zone_fraction * its L, not another member's), in node spacings
    # from each edge, with a relative slack of 1e-9: a node on the zone's boundary counts as the edge
    # on either side (its position from -L/2 + i*dx rounds either way)
    zone_nodes = settings.edge_zone_fraction * L / dx * (wp.float64(1.0) + wp.float64(1.0e-9))
    edge = wp.float64(0.0)
    if wp.float64(i_first) <= zone_nodes:
        edge = wp.float64(-1.0)
    elif wp.float64(n - 1 - i_first) <= zone_nodes:
        edge = wp.float64(1.0)
    out[FM_NUCLEATION_EDGE, m] = edge
    out[FM_FIRST_ARRIVAL, m] = t0
    out[FM_LAST_ARRIVAL, m] = t_last
    out[FM_FRONT_COUNT, m] = wp.float64(count_fronts(arrival, m, lo, hi))
    # rows of sums: 0, 1 the prefix sums, 2 the log slowness (interval_sums); 3, 4 its running medians
    interval_sums(arrival, sums, m, n, dx)
    a, e = front_basin(arrival, m, lo, hi, i_first)  # the first front: intervals a..e-1
    first_front_meeting(arrival, m, lo, hi, a, e, L, dx, out)
    if e > a:
        write_segment(out, m, SEGMENT_FIRST, a, e, L, dx, segment_speed(arrival, sums, m, a, e, dx, i_first))
    # the second front: the earliest arrival outside the first front's nodes
    i_second = int(-1)
    t_second = wp.float64(wp.inf)
    for i in range(lo, hi + 1):
        if (i < a or i > e) and arrival[i, m] < t_second:
            t_second = arrival[i, m]
            i_second = i
    if i_second >= 0:
        a2, e2 = front_basin(arrival, m, lo, hi, i_second)
        out[FM_SECOND_NUCLEATION_POSITION, m] = node_position(wp.float64(i_second), L, dx)
        out[FM_SECOND_FIRST_ARRIVAL, m] = t_second
        write_segment(out, m, SEGMENT_SECOND, a2, e2, L, dx, segment_speed(arrival, sums, m, a2, e2, dx, i_second))
    if e == a:
        return
    q_fast = fast_log_slowness(sums, m, a, e, settings.fast_fraction)
    slow_q = wp.log(settings.speed_ratio) + q_fast  # q above this: slower than v_fast / ratio
    smooth_pass(sums, m, 2, 3, a, e)
    smooth_pass(sums, m, 3, 4, a, e)
    b1, b2 = slow_end_segments(arrival, sums, m, a, e, dx, i_first, settings, slow_q)
    if b1 > a:
        write_segment(out, m, 0, a, b1, L, dx, segment_speed(arrival, sums, m, a, b1, dx, i_first))
    if b2 < e:
        write_segment(out, m, 2, b2, e, L, dx, segment_speed(arrival, sums, m, b2, e, dx, i_first))
    write_segment(out, m, 1, b1, b2, L, dx, segment_speed(arrival, sums, m, b1, b2, dx, i_first))


@wp.kernel(enable_backward=False)
def arrival_from_history(
    times: wp.array(dtype=wp.float64),
    velocity: wp.array3d(dtype=wp.float64),
    disc_sign: wp.array(dtype=wp.float64),
    direction: int,
    threshold: wp.float64,
    arrival: wp.array2d(dtype=wp.float64),
    event_max: wp.array(dtype=wp.float64),
):
    """Arrival times from a sampled pad-velocity history (times (T,) s, velocity (T, nodes,
    members) m/s) by the rule the integrator applies to its accepted steps: a first sweep finds
    the event maximum of the detachment velocity, a second the first crossing of threshold times
    it at each node. Used to test that rule on fields with known fronts; nodes that never cross
    get NaN."""
    m = wp.tid()
    n_t = velocity.shape[0]
    n = velocity.shape[1]
    w_max = wp.float64(-1.0e300)
    for k in range(1, n_t):
        for i in range(n):
            w_max = wp.max(w_max, detachment_velocity(velocity[k, i, m], disc_sign[m], direction))
    event_max[m] = w_max
    level = threshold * w_max
    for i in range(n):
        arrival[i, m] = wp.float64(wp.nan)
        for k in range(1, n_t):
            w_old = detachment_velocity(velocity[k - 1, i, m], disc_sign[m], direction)
            w_new = detachment_velocity(velocity[k, i, m], disc_sign[m], direction)
            if w_new >= level:
                arrival[i, m] = crossing_time(level, times[k - 1], w_old, times[k], w_new)
                break
