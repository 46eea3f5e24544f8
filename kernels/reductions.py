"""In-kernel reductions over time: memory independent of the number of steps.

mu_s (SPEC section 7) is the maximum over time of mu(t) = sign(v_max) * int tau_f dx / int sigma_n dx.
Sampling mu only at accepted steps would miss the peak by O(h^2 * mu''); each time the middle of
the last three accepted points is a local maximum, the parabola through the three points is
maximised instead (docs/model.md, "Outputs").
"""


import warp as wp

from .params import FRONT_ABSOLUTE, FRONT_WITH_DISC, IntegratorState


@wp.func
def record_friction_point(st: IntegratorState, t: wp.float64, mu: wp.float64):
    """Fold the accepted point (t, mu) into the running maximum of ``st`` and return ``st``."""
    if mu > st.mu_s:  # mu_s starts at -inf (set by the host)
        st.mu_s = mu
        st.mu_s_time = t
    if st.npts >= 2 and st.mu1 >= st.mu2 and st.mu1 >= mu and t > st.t1 and st.t1 > st.t2:
        d1 = (st.mu1 - st.mu2) / (st.t1 - st.t2)
        d2 = (mu - st.mu1) / (t - st.t1)
        curv = (d2 - d1) / (t - st.t2)
        if curv < wp.float64(0.0):
            t_peak = wp.float64(0.5) * (st.t1 + st.t2) - d1 / (wp.float64(2.0) * curv)
            if t_peak >= st.t2 and t_peak <= t:
                mu_peak = st.mu2 + d1 * (t_peak - st.t2) + curv * (t_peak - st.t2) * (t_peak - st.t1)
                if mu_peak > st.mu_s:
                    st.mu_s = mu_peak
                    st.mu_s_time = t_peak
    st.t2 = st.t1
    st.mu2 = st.mu1
    st.t1 = t
    st.mu1 = mu
    st.mu_final = mu
    st.npts = st.npts + 1
    return st


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


# rows of the front-metrics output array (out[row, member]); simulate() names them
FM_NUCLEATION_POSITION = 0
FM_NUCLEATION_EDGE = 1
FM_FIRST_ARRIVAL = 2
FM_LAST_ARRIVAL = 3
FM_ARRIVED_FRACTION = 4
FM_SEGMENTS = 5  # then start, end, length, speed for left, middle, right
N_FRONT_METRICS = FM_SEGMENTS + 12


@wp.struct
class SegmentSettings:
    min_nodes: wp.int32  # fewest node intervals of a segment
    speed_ratio: wp.float64  # an end segment is a separate (slow) front when v_middle >= ratio * v_end
    edge_zone: wp.float64  # m; nucleation within this distance of an edge counts as that edge


@wp.func
def level_misfit(sums: wp.array3d(dtype=wp.float64), m: int, a: int, b: int):
    """Squared residual of the best constant fit to the log slowness over intervals a..b-1
    (prefix-sum rows: count, q, q^2)."""
    s0 = sums[0, b, m] - sums[0, a, m]
    s1 = sums[1, b, m] - sums[1, a, m]
    s2 = sums[2, b, m] - sums[2, a, m]
    if s0 <= wp.float64(0.0):
        return wp.float64(0.0)
    return wp.max(s2 - s1 * s1 / s0, wp.float64(0.0))


@wp.func
def segment_speed(sums: wp.array3d(dtype=wp.float64), m: int, a: int, b: int, dx: wp.float64):
    """Mean front speed (m/s) over intervals a..b-1: their length over the time the front spends
    crossing them, sum |t_a(x_{j+1}) - t_a(x_j)| (a length-weighted harmonic mean of the local
    speeds, also right for a front that spreads both ways from inside the segment)."""
    s0 = sums[0, b, m] - sums[0, a, m]
    spent = sums[3, b, m] - sums[3, a, m]
    if s0 <= wp.float64(0.0):
        return wp.float64(wp.nan)
    return s0 * dx / spent


@wp.func
def write_segment(
    out: wp.array2d(dtype=wp.float64), m: int, which: int, a: int, b: int,
    L: wp.float64, dx: wp.float64, speed: wp.float64,
):
    """Start, end, length (m) and mean speed (m/s) of the segment of intervals a..b-1 into out."""
    start = -wp.float64(0.5) * L + wp.float64(a) * dx
    end = -wp.float64(0.5) * L + wp.float64(b) * dx
    row = FM_SEGMENTS + 4 * which
    out[row, m] = start
    out[row + 1, m] = end
    out[row + 2, m] = end - start
    out[row + 3, m] = speed


@wp.kernel
def segment_fronts(
    length: wp.array(dtype=wp.float64),
    arrival: wp.array2d(dtype=wp.float64),
    settings: SegmentSettings,
    sums: wp.array3d(dtype=wp.float64),
    out: wp.array2d(dtype=wp.float64),
):
    """Front metrics of each member from its arrival times t_a (s, nodes x members; NaN = never).

    Works on the intervals between neighbouring nodes from the first to the last arrived node, each
    with its local speed c_j = dx / |t_a(x_{j+1}) - t_a(x_j)|. The two breakpoints minimise the
    squared misfit of a piecewise-constant fit to log(1/c_j) (scale-free change-point detection)
    over the admissible splits: no split, a left end segment, a right one, or both, each segment
    >= min_nodes intervals and each end segment markedly slower than the middle one
    (v_middle >= speed_ratio * v_end). Absent segments are NaN. Segment speeds are
    length / time spent (segment_speed)."""
    m = wp.tid()
    n = arrival.shape[0]
    for r in range(N_FRONT_METRICS):
        out[r, m] = wp.float64(wp.nan)
    L = length[m]
    dx = L / wp.float64(n - 1)
    lo = int(-1)
    hi = int(-1)
    t0 = wp.float64(1.0e300)
    t_last = wp.float64(-1.0e300)
    i_first = int(0)
    arrived = int(0)
    for i in range(n):
        ta = arrival[i, m]
        if wp.isfinite(ta):
            if lo < 0:
                lo = i
            hi = i
            arrived += 1
            if ta < t0:
                t0 = ta
                i_first = i
            t_last = wp.max(t_last, ta)
    out[FM_ARRIVED_FRACTION, m] = wp.float64(arrived) / wp.float64(n)
    if lo < 0:
        return
    x_first = -wp.float64(0.5) * L + wp.float64(i_first) * dx
    out[FM_NUCLEATION_POSITION, m] = x_first
    edge = wp.float64(0.0)
    if x_first <= -wp.float64(0.5) * L + settings.edge_zone:
        edge = wp.float64(-1.0)
    elif x_first >= wp.float64(0.5) * L - settings.edge_zone:
        edge = wp.float64(1.0)
    out[FM_NUCLEATION_EDGE, m] = edge
    out[FM_FIRST_ARRIVAL, m] = t0
    out[FM_LAST_ARRIVAL, m] = t_last
    # prefix sums over intervals j = (node j, node j+1) with both ends arrived:
    # rows count, q = log slowness, q^2, |dt|
    for r in range(4):
        sums[r, 0, m] = wp.float64(0.0)
    for j in range(n - 1):
        t_l = arrival[j, m]
        t_r = arrival[j + 1, m]
        w = wp.float64(0.0)
        q = wp.float64(0.0)
        dt = wp.float64(0.0)
        if wp.isfinite(t_l) and wp.isfinite(t_r):
            w = wp.float64(1.0)
            dt = wp.abs(t_r - t_l)
            q = wp.log(wp.max(dt, wp.float64(1.0e-12) * dx) / dx)  # speeds above 1e12 m/s: simultaneous
        sums[0, j + 1, m] = sums[0, j, m] + w
        sums[1, j + 1, m] = sums[1, j, m] + w * q
        sums[2, j + 1, m] = sums[2, j, m] + w * q * q
        sums[3, j + 1, m] = sums[3, j, m] + dt
    if hi == lo:
        return
    a = lo
    e = hi  # intervals lo..hi-1
    k = settings.min_nodes
    # candidates: i1 = a (no left segment) or a+k.., i2 = e (no right segment) or ..e-k; the middle
    # keeps >= k intervals; a present end segment must be markedly slower than the middle
    b1 = a
    b2 = e
    best = level_misfit(sums, m, a, e)
    n_first = e - a - 2 * k + 1  # i1 in a+k .. e-2k when both ends are present
    for c1 in range(-1, wp.max(n_first, 0) + k):
        i1 = a + k + c1
        if c1 < 0:
            i1 = a
        if i1 > e - k:
            break
        q_l = level_misfit(sums, m, a, i1)
        for c2 in range(-1, e - k - (i1 + k) + 1):
            i2 = i1 + k + c2
            if c2 < 0:
                i2 = e
            if i1 == a and i2 == e:
                continue
            v_mid = segment_speed(sums, m, i1, i2, dx)
            ok = True
            if i1 > a:
                ok = ok and segment_speed(sums, m, a, i1, dx) * settings.speed_ratio <= v_mid
            if i2 < e:
                ok = ok and segment_speed(sums, m, i2, e, dx) * settings.speed_ratio <= v_mid
            if ok:
                q = q_l + level_misfit(sums, m, i1, i2) + level_misfit(sums, m, i2, e)
                if q < best:
                    best = q
                    b1 = i1
                    b2 = i2
    has_left = int(0)
    has_right = int(0)
    if b1 > a:
        has_left = 1
    if b2 < e:
        has_right = 1
    mid_a = a
    mid_b = e
    if has_left == 1:
        mid_a = b1
        write_segment(out, m, 0, a, b1, L, dx, segment_speed(sums, m, a, b1, dx))
    if has_right == 1:
        mid_b = b2
        write_segment(out, m, 2, b2, e, L, dx, segment_speed(sums, m, b2, e, dx))
    write_segment(out, m, 1, mid_a, mid_b, L, dx, segment_speed(sums, m, mid_a, mid_b, dx))


@wp.kernel
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
