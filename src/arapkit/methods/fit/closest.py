"""Closest points on a target surface: compiled kernels for triangles and for oriented disks.

The fit's data term is the squared distance from each template vertex to the target surface
``S``. A mesh's ``S`` is its triangles; a point cloud's ``S`` is the union of small oriented
disks (surfels), one per point, centred on it, in the plane of its normal, with a radius that
reaches its neighbours. The distance to either is a distance to a point of ``S``, so for any
``q`` on ``S`` found at the last iterate, ``|x - q|^2 >= dist(x, S)^2``: that is what makes
the fit's correspondence step a majorise-minimise step (see :mod:`arapkit.methods.fit.solver`).

Each query searches a few starting elements (from a k-d tree, or just the element it matched
last time) and then walks greedily over the elements' neighbour graph to the closest one.
The element matched last time is always a candidate, so the distance found never exceeds the
distance to the last match: the energy decrease within a stage holds exactly.

Besides the point, each query reports whether its closest point lies on the surface's
border (a boundary edge or vertex of the mesh; the rim of a boundary point's disk), which the
fit uses to reject matches of template parts the scan does not show.

Examples
--------
>>> import numpy as np
>>> q, region = closest_on_triangle(np.array([0.2, 0.2, 1.0]), np.zeros(3),
...                                 np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
>>> np.round(q, 12).tolist(), int(region)
([0.2, 0.2, 0.0], 0)
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["closest_on_triangle", "match_disks", "match_triangles", "boundary_points"]

#: queries from which the matching kernels use threads: below, a parallel region's start
#: (a scheduler time slice per thread on a shared machine) can cost what it saves (measured
#: on 2 shared cores: no difference at 845 or 13,750 queries)
PARALLEL_QUERIES = 20_000

#: where a triangle's closest point lies: the interior, one of its corners, one of its edges
INTERIOR, CORNER_A, CORNER_B, CORNER_C, EDGE_AB, EDGE_AC, EDGE_BC = range(7)


@nb.njit(cache=True, nogil=True)
def _closest_tri(px, py, pz, a, b, c):
    """Closest point on triangle (a, b, c) to p, and its region (Ericson 2005, 5.1.5)."""
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    apx, apy, apz = px - a[0], py - a[1], pz - a[2]
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return a[0], a[1], a[2], CORNER_A
    bpx, bpy, bpz = px - b[0], py - b[1], pz - b[2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return b[0], b[1], b[2], CORNER_B
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a[0] + v * abx, a[1] + v * aby, a[2] + v * abz, EDGE_AB
    cpx, cpy, cpz = px - c[0], py - c[1], pz - c[2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return c[0], c[1], c[2], CORNER_C
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a[0] + w * acx, a[1] + w * acy, a[2] + w * acz, EDGE_AC
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return (b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2]),
                EDGE_BC)
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return (a[0] + abx * v + acx * w, a[1] + aby * v + acy * w, a[2] + abz * v + acz * w,
            INTERIOR)


def closest_on_triangle(p: np.ndarray, a: np.ndarray, b: np.ndarray,
                        c: np.ndarray) -> tuple[np.ndarray, int]:
    """The point of triangle (a, b, c) closest to ``p`` and its region code.

    Region 0 is the interior, 1-3 the corners a, b, c and 4-6 the edges ab, ac, bc.
    """
    x, y, z, region = _closest_tri(float(p[0]), float(p[1]), float(p[2]),
                                   np.asarray(a, float), np.asarray(b, float),
                                   np.asarray(c, float))
    return np.array([x, y, z]), region


@nb.njit(cache=True, nogil=True, inline="always")
def _tri_d2(X, i, V, F, f, tmp):
    a, b, c = V[F[f, 0]], V[F[f, 1]], V[F[f, 2]]
    x, y, z, reg = _closest_tri(X[i, 0], X[i, 1], X[i, 2], a, b, c)
    tmp[0], tmp[1], tmp[2] = x, y, z
    dx, dy, dz = X[i, 0] - x, X[i, 1] - y, X[i, 2] - z
    return dx * dx + dy * dy + dz * dz, reg


@nb.njit(cache=True, nogil=True, inline="always")
def _settled(i, X, start, prev, anchor, slack, owner):
    """Whether the walk from ``prev[i]`` would stay there (see :func:`match_disks`)."""
    if start.shape[1] != 0 or prev[i] < 0 or owner[i] != prev[i]:
        return False
    dx, dy, dz = X[i, 0] - anchor[i, 0], X[i, 1] - anchor[i, 1], X[i, 2] - anchor[i, 2]
    return 4.0 * (dx * dx + dy * dy + dz * dz) < slack[i] * slack[i]


@nb.njit(cache=True, nogil=True, inline="always")
def _remember(i, X, best, second, settled, bf, anchor, slack, owner):
    """Where the walk settled, on which element, and the margin to its neighbours."""
    anchor[i, 0], anchor[i, 1], anchor[i, 2] = X[i, 0], X[i, 1], X[i, 2]
    owner[i] = bf
    slack[i] = np.sqrt(second) - np.sqrt(best) if settled else 0.0


@nb.njit(cache=True, nogil=True, inline="always")
def _match_triangle(i, X, V, F, nbr_ptr, nbr_idx, start, prev, border_edge, border_vertex,
                    max_steps, q, elem, d2, on_border, tmp, anchor, slack, owner):
    best = np.inf
    bf = -1
    breg = 0
    bq0 = bq1 = bq2 = 0.0
    for t in range(start.shape[1] + 1):
        f = prev[i] if t == start.shape[1] else start[i, t]
        if f < 0:
            continue
        dd, reg = _tri_d2(X, i, V, F, f, tmp)
        if dd < best:
            best, bf, breg = dd, f, reg
            bq0, bq1, bq2 = tmp[0], tmp[1], tmp[2]
    if not _settled(i, X, start, prev, anchor, slack, owner):
        settled = False
        second = np.inf
        for _ in range(max_steps):
            moved = False
            second = np.inf
            cur = bf
            for t in range(nbr_ptr[cur], nbr_ptr[cur + 1]):
                f = nbr_idx[t]
                dd, reg = _tri_d2(X, i, V, F, f, tmp)
                if dd < best:
                    best, bf, breg = dd, f, reg
                    bq0, bq1, bq2 = tmp[0], tmp[1], tmp[2]
                    moved = True
                elif dd < second:
                    second = dd
            if not moved:
                settled = True
                break
        _remember(i, X, best, second, settled, bf, anchor, slack, owner)
    q[i, 0], q[i, 1], q[i, 2] = bq0, bq1, bq2
    elem[i] = bf
    d2[i] = best
    border = False
    if breg == EDGE_AB:
        border = border_edge[bf, 0]
    elif breg == EDGE_AC:
        border = border_edge[bf, 1]
    elif breg == EDGE_BC:
        border = border_edge[bf, 2]
    elif breg != INTERIOR:
        border = border_vertex[F[bf, breg - CORNER_A]]
    on_border[i] = border


@nb.njit(parallel=True, cache=True, nogil=True)
def _match_triangles_parallel(X, V, F, nbr_ptr, nbr_idx, start, prev, border_edge,
                              border_vertex, max_steps, q, elem, d2, on_border, anchor, slack,
                              owner):
    for i in nb.prange(X.shape[0]):
        _match_triangle(i, X, V, F, nbr_ptr, nbr_idx, start, prev, border_edge, border_vertex,
                        max_steps, q, elem, d2, on_border, np.empty(3), anchor, slack, owner)


@nb.njit(cache=True, nogil=True)
def _match_triangles_serial(X, V, F, nbr_ptr, nbr_idx, start, prev, border_edge,
                            border_vertex, max_steps, q, elem, d2, on_border, anchor, slack,
                            owner):
    tmp = np.empty(3)
    for i in range(X.shape[0]):
        _match_triangle(i, X, V, F, nbr_ptr, nbr_idx, start, prev, border_edge, border_vertex,
                        max_steps, q, elem, d2, on_border, tmp, anchor, slack, owner)


def match_triangles(X, V, F, nbr_ptr, nbr_idx, start, prev, border_edge, border_vertex,
                    max_steps, q, elem, d2, on_border, anchor, slack, owner):
    """Closest point on a triangle mesh for every row of X.

    Candidates: ``start[i]`` (from a k-d tree; -1 entries skipped) and ``prev[i]`` (the last
    match, -1 if none); then a greedy walk over ``nbr`` (faces sharing a vertex) while the
    distance drops, at most ``max_steps`` moves. ``on_border[i]`` is True when the closest
    point lies on a boundary edge (``border_edge[f, e]``, e = ab, ac, bc) or a boundary
    vertex. Threads from :data:`PARALLEL_QUERIES` queries on. ``anchor``, ``slack`` and
    ``owner`` are the walk's memory (see :func:`match_disks`).
    """
    kernel = (_match_triangles_parallel if len(X) >= PARALLEL_QUERIES
              else _match_triangles_serial)
    kernel(X, V, F, nbr_ptr, nbr_idx, start, prev, border_edge, border_vertex, max_steps, q,
           elem, d2, on_border, anchor, slack, owner)


@nb.njit(cache=True, nogil=True, inline="always")
def _disk_d2(x0, x1, x2, P, N, radius, j):
    """Squared distance from x to disk j, and whether its closest point is on the rim."""
    dx, dy, dz = x0 - P[j, 0], x1 - P[j, 1], x2 - P[j, 2]
    h = dx * N[j, 0] + dy * N[j, 1] + dz * N[j, 2]
    t2 = dx * dx + dy * dy + dz * dz - h * h  # squared distance within the disk's plane
    r = radius[j]
    if t2 > r * r:  # beyond the disk: the closest point is on its rim
        e = np.sqrt(t2) - r
        return h * h + e * e, True
    return h * h, False


@nb.njit(cache=True, nogil=True)
def _disk_point(x0, x1, x2, P, N, radius, j, q, i):
    """The closest point of disk j to x, into row i of q (for the match found only)."""
    dx, dy, dz = x0 - P[j, 0], x1 - P[j, 1], x2 - P[j, 2]
    h = dx * N[j, 0] + dy * N[j, 1] + dz * N[j, 2]
    tx, ty, tz = dx - h * N[j, 0], dy - h * N[j, 1], dz - h * N[j, 2]
    t2 = tx * tx + ty * ty + tz * tz
    r = radius[j]
    if t2 > r * r:
        s = r / np.sqrt(t2)
        tx, ty, tz = tx * s, ty * s, tz * s
    q[i, 0], q[i, 1], q[i, 2] = P[j, 0] + tx, P[j, 1] + ty, P[j, 2] + tz


@nb.njit(cache=True, nogil=True, inline="always")
def _match_disk(i, X, P, N, radius, nbr_ptr, nbr_idx, start, prev, border_point, max_steps,
                q, elem, d2, on_border, anchor, slack, owner):
    # distances only while searching: the closest point is made once, for the winner
    x0, x1, x2 = X[i, 0], X[i, 1], X[i, 2]
    best = np.inf
    bj = -1
    brim = False
    for t in range(start.shape[1] + 1):
        j = prev[i] if t == start.shape[1] else start[i, t]
        if j < 0:
            continue
        dd, rim = _disk_d2(x0, x1, x2, P, N, radius, j)
        if dd < best:
            best, bj, brim = dd, j, rim
    if not _settled(i, X, start, prev, anchor, slack, owner):
        settled = False
        second = np.inf
        for _ in range(max_steps):
            moved = False
            second = np.inf
            cur = bj
            for t in range(nbr_ptr[cur], nbr_ptr[cur + 1]):
                j = nbr_idx[t]
                dd, rim = _disk_d2(x0, x1, x2, P, N, radius, j)
                if dd < best:
                    best, bj, brim = dd, j, rim
                    moved = True
                elif dd < second:
                    second = dd
            if not moved:
                settled = True
                break
        _remember(i, X, best, second, settled, bj, anchor, slack, owner)
    _disk_point(x0, x1, x2, P, N, radius, bj, q, i)
    elem[i] = bj
    d2[i] = best
    on_border[i] = brim and border_point[bj]


@nb.njit(parallel=True, cache=True, nogil=True)
def _match_disks_parallel(X, P, N, radius, nbr_ptr, nbr_idx, start, prev, border_point,
                          max_steps, q, elem, d2, on_border, anchor, slack, owner):
    for i in nb.prange(X.shape[0]):
        _match_disk(i, X, P, N, radius, nbr_ptr, nbr_idx, start, prev, border_point,
                    max_steps, q, elem, d2, on_border, anchor, slack, owner)


@nb.njit(cache=True, nogil=True)
def _match_disks_serial(X, P, N, radius, nbr_ptr, nbr_idx, start, prev, border_point,
                        max_steps, q, elem, d2, on_border, anchor, slack, owner):
    for i in range(X.shape[0]):
        _match_disk(i, X, P, N, radius, nbr_ptr, nbr_idx, start, prev, border_point,
                    max_steps, q, elem, d2, on_border, anchor, slack, owner)


def match_disks(X, P, N, radius, nbr_ptr, nbr_idx, start, prev, border_point, max_steps,
                q, elem, d2, on_border, anchor, slack, owner):
    """Closest point on a union of oriented disks (one per cloud point) for every row of X.

    As :func:`match_triangles`; ``on_border[i]`` is True when the closest point is on the
    rim of a boundary point's disk (x lies beyond the scan's edge).

    The walk's memory: where query i last settled (``anchor[i]``, on element ``owner[i]``)
    and by how much every neighbour of that element was farther (``slack[i]``, a
    distance). A distance to a fixed set moves by at most as much as the query, so a query
    that has moved less than ``slack / 2`` since, and starts from that element without a
    k-d search, would find every neighbour still farther: the walk would stay, and is
    skipped (the same answer, one distance instead of a neighbourhood's). Updated in place.
    """
    kernel = _match_disks_parallel if len(X) >= PARALLEL_QUERIES else _match_disks_serial
    kernel(X, P, N, radius, nbr_ptr, nbr_idx, start, prev, border_point, max_steps, q, elem,
           d2, on_border, anchor, slack, owner)


@nb.njit(parallel=True, cache=True, nogil=True)
def boundary_points(P, N, knn, max_gap):
    """Points on the border of a cloud: the largest angle between consecutive neighbours
    around the normal exceeds ``max_gap`` (radians; PCL's angle criterion)."""
    n, k = knn.shape
    out = np.zeros(n, dtype=np.bool_)
    for i in nb.prange(n):
        nx, ny, nz = N[i, 0], N[i, 1], N[i, 2]
        # a tangent basis (u, v) of the point's plane
        if abs(nx) < 0.9:
            ux, uy, uz = 0.0, -nz, ny
        else:
            ux, uy, uz = nz, 0.0, -nx
        s = np.sqrt(ux * ux + uy * uy + uz * uz)
        ux, uy, uz = ux / s, uy / s, uz / s
        vx, vy, vz = ny * uz - nz * uy, nz * ux - nx * uz, nx * uy - ny * ux
        ang = np.empty(k)
        m = 0
        for t in range(k):
            j = knn[i, t]
            if j == i or j < 0 or j >= n:
                continue
            dx, dy, dz = P[j, 0] - P[i, 0], P[j, 1] - P[i, 1], P[j, 2] - P[i, 2]
            a = dx * ux + dy * uy + dz * uz
            b = dx * vx + dy * vy + dz * vz
            if a == 0.0 and b == 0.0:
                continue
            ang[m] = np.arctan2(b, a)
            m += 1
        if m < 3:
            out[i] = True
            continue
        a = np.sort(ang[:m])
        gap = a[0] + 2.0 * np.pi - a[m - 1]
        for t in range(1, m):
            gap = max(gap, a[t] - a[t - 1])
        out[i] = gap > max_gap
    return out
