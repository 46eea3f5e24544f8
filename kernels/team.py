"""Who works on a member: one thread (the thread-per-member kernel) or a team of ``lanes`` threads
(one Warp tile block per member, the cooperative kernel; docs/model.md, "Time
integration").

In a team, lane k owns the contiguous nodes [first_node, end_node) = [k*N//P, (k+1)*N//P) of its
member (P = lanes <= N/2, so every lane owns at least two nodes) and runs every per-node loop of
the integrator on them alone; what a loop reduces over the nodes (sums, maxima, the error norm) is
combined over the lanes with Warp's tile primitives, which also give the whole team the same value,
so that every lane takes the same decisions (step accepted, Newton converged, ...) and keeps an
identical copy of the member's IntegratorState. A tile operation synchronises the block: the
reductions double as barriers between a lane's writes and its neighbours' reads of halo nodes;
``barrier`` is the explicit one where no reduction falls.

Every reduction ends with ``settle``: a one-element shared tile assignment, which synchronises
before it writes, so that no lane starts the next tile operation while another still reads this
one's result. Without it, Warp's CPU reductions (cooperative fibers) write their flags into the
freed shared memory of the previous result before their first synchronisation, and the lanes of
a team of 2-8 read different sums (found in review: teams of 7 and 8 lanes failed on a lift-off
member; tests/test_team.py checks the sums of every lane).

``make_team(ft, lanes)`` builds the functions; with lanes = 1 they are the identity (``make_solo``: no
tile operation is compiled, the thread-per-member kernel is unchanged bit for bit), else the tile
reductions (``make_tile_reductions``) and the separator exchange of the team's tridiagonal solve
(``make_separator_exchange``). A team needs
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


def make_team(ft, lanes: int):
    """Reductions over a member's team (identity for lanes = 1) and the separator exchange of the
    team's tridiagonal solve."""
    if lanes == 1:
        return make_solo()
    if ft != wp.float64:
        raise ValueError("a team of lanes needs float64")
    return dict(lanes=lanes, **make_tile_reductions(lanes), **make_separator_exchange(lanes))
