"""r-ring neighbourhoods N(k, r) (Chen et al. 2017, sec. 3.1).

An edge ``(i, j)`` belongs to ``N(k, r)`` when a path of at most ``r`` edges starting at
``k`` can traverse it, i.e. when ``min(dist(k, i), dist(k, j)) <= r - 1`` in the edge
graph. ``r = 1`` gives the spokes of standard ARAP.

The neighbourhoods are stored in CSR form, ordered by breadth-first search, so that
``N(k, r')`` for every ``r' <= r_k`` is a prefix of ``N(k, r_k)`` (the ``layer`` of an
entry is the smallest ``r`` whose neighbourhood contains it). Alongside, every
neighbourhood's *disk* (the vertices its edges touch) carries the coefficient vectors

    c_kv = sum_{e in N(k), e touches v} s_ev w_e (p_i - p_j),   s_ev = +1 if v = i else -1,

with which the local-step covariance is ``S_k = sum_v c_kv p'_v^T`` and the global
right-hand side is ``b_v = sum_k R_k c_kv``: both are sparse products over the same
structure, not Python loops. The solver scatters ``b`` from the per-k order, so no copy
grouped by v is kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from ..mesh.model import Mesh
from ..mesh.topology import vertex_adjacency
from ..validate import MAX_RINGS, ring_sizes

__all__ = [
    "MAX_RINGS",
    "Neighbourhoods",
    "build_neighbourhoods",
    "check_rings",
    "neighbourhoods_from_arrays",
    "rings_summary",
    "vertex_adjacency",
]


#: r per vertex, checked: the one rule of :func:`arapkit.validate.ring_sizes` (int32)
check_rings = ring_sizes


@nb.njit(cache=True, nogil=True)
def _bfs(k, r, adj_ptr, adj_nbr, adj_eid, vstamp, depth, estamp, queue, vout, eout, lout):
    """BFS from k; write disk vertices to vout and (edge, layer) to eout/lout; return counts.

    With ``vout`` of length 0 only counts are returned.
    """
    write = len(vout) > 0
    vstamp[k] = k
    depth[k] = 0
    queue[0] = k
    head, tail, ne = 0, 1, 0
    while head < tail:
        u = queue[head]
        head += 1
        d = depth[u]
        if d >= r:
            continue
        for t in range(adj_ptr[u], adj_ptr[u + 1]):
            e = adj_eid[t]
            if estamp[e] != k:
                estamp[e] = k
                if write:
                    eout[ne] = e
                    lout[ne] = d + 1
                ne += 1
            v = adj_nbr[t]
            if vstamp[v] != k:
                vstamp[v] = k
                depth[v] = d + 1
                queue[tail] = v
                tail += 1
    if write:
        for t in range(tail):
            vout[t] = queue[t]
    return tail, ne


@nb.njit(parallel=True, cache=True, nogil=True)
def _count(n, n_edges, rings, adj_ptr, adj_nbr, adj_eid, n_chunks):
    nv = np.zeros(n, dtype=np.int64)
    ne = np.zeros(n, dtype=np.int64)
    size = (n + n_chunks - 1) // n_chunks
    for c in nb.prange(n_chunks):
        vstamp = np.full(n, -1, dtype=np.int32)
        estamp = np.full(n_edges, -1, dtype=np.int32)
        depth = np.empty(n, dtype=np.int32)
        queue = np.empty(n, dtype=np.int32)
        dummy_i = np.empty(0, dtype=np.int32)
        dummy_l = np.empty(0, dtype=np.int8)
        for k in range(c * size, min(n, (c + 1) * size)):
            a, b = _bfs(k, rings[k], adj_ptr, adj_nbr, adj_eid, vstamp, depth, estamp, queue,
                        dummy_i, dummy_i, dummy_l)
            nv[k] = a
            ne[k] = b
    return nv, ne


@nb.njit(parallel=True, cache=True, nogil=True)
def _fill(n, rings, adj_ptr, adj_nbr, adj_eid, edges, W, vptr, eptr, n_chunks,
          disk_idx, disk_coef, edge_idx, edge_layer):
    size = (n + n_chunks - 1) // n_chunks
    n_edges = len(edges)
    for c in nb.prange(n_chunks):
        vstamp = np.full(n, -1, dtype=np.int32)
        estamp = np.full(n_edges, -1, dtype=np.int32)
        depth = np.empty(n, dtype=np.int32)
        queue = np.empty(n, dtype=np.int32)
        slot = np.empty(n, dtype=np.int64)
        for k in range(c * size, min(n, (c + 1) * size)):
            v0, v1 = vptr[k], vptr[k + 1]
            e0, e1 = eptr[k], eptr[k + 1]
            _bfs(k, rings[k], adj_ptr, adj_nbr, adj_eid, vstamp, depth, estamp, queue,
                 disk_idx[v0:v1], edge_idx[e0:e1], edge_layer[e0:e1])
            for t in range(v0, v1):
                slot[disk_idx[t]] = t
                disk_coef[t, 0] = 0.0
                disk_coef[t, 1] = 0.0
                disk_coef[t, 2] = 0.0
            for t in range(e0, e1):
                e = edge_idx[t]
                si = slot[edges[e, 0]]
                sj = slot[edges[e, 1]]
                for a in range(3):
                    disk_coef[si, a] += W[e, a]
                    disk_coef[sj, a] -= W[e, a]


@dataclass
class Neighbourhoods:
    """CSR storage of N(k, r_k) for every vertex and the coefficients ``c_kv``.

    Attributes
    ----------
    rings : (n,) int32
        r_k per vertex.
    edge_ptr, edge_idx, edge_layer :
        ``edge_idx[edge_ptr[k]:edge_ptr[k+1]]`` are the ids (into ``mesh.edges``) of the
        edges of N(k, r_k) in BFS order; ``edge_layer`` the smallest r containing each.
    disk_ptr, disk_idx, disk_coef :
        vertices touched by N(k, r_k) (k first) and their coefficients ``c_kv`` (3 each).
    edge_count : (E,) int
        d_e, the number of neighbourhoods containing each edge.
    """

    rings: np.ndarray
    edge_ptr: np.ndarray
    edge_idx: np.ndarray
    edge_layer: np.ndarray
    disk_ptr: np.ndarray
    disk_idx: np.ndarray
    disk_coef: np.ndarray
    edge_count: np.ndarray

    def edges_of(self, k: int, r: int | None = None) -> np.ndarray:
        """Edge ids of N(k, r) (default r = r_k).

        Examples
        --------
        >>> from arapkit.mesh.shapes import bar
        >>> from arapkit.mesh.weights import edge_weights
        >>> m = bar()
        >>> nb = build_neighbourhoods(m, edge_weights(m), 1)
        >>> len(nb.edges_of(0)) == m.adjacency[0].nnz
        True
        """
        s = slice(self.edge_ptr[k], self.edge_ptr[k + 1])
        ids, layer = self.edge_idx[s], self.edge_layer[s]
        return ids if r is None else ids[layer <= r]

    @property
    def sizes(self) -> np.ndarray:
        """|N(k, r_k)|: number of edges in each neighbourhood."""
        return np.diff(self.edge_ptr)


def _chunks(n: int) -> int:
    return max(1, min(n, 4 * nb.get_num_threads()))


def build_neighbourhoods(mesh: Mesh, weights: np.ndarray, rings) -> Neighbourhoods:
    """Breadth-first search of N(k, r_k) for every vertex, compiled and parallel.

    Parameters
    ----------
    mesh : Mesh
    weights : (E,) float
        Weight of each edge of ``mesh.edges``.
    rings : int or (n,) int
        Neighbourhood size per vertex (>= 1).

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> from arapkit.mesh.weights import edge_weights
    >>> m = bar()
    >>> nb = build_neighbourhoods(m, edge_weights(m), 2)
    >>> int(nb.sizes.min()) > 6
    True
    """
    n = mesh.n_vertices
    return neighbourhoods_from_arrays(n, mesh.edges, mesh.vertices, weights,
                                      check_rings(rings, n))


def neighbourhoods_from_arrays(
    n: int, edges: np.ndarray, P: np.ndarray, weights: np.ndarray, rings: np.ndarray
) -> Neighbourhoods:
    """:func:`build_neighbourhoods` on raw arrays (any vertex numbering, e.g. a reordering).

    ``edges`` need not be sorted; edge ids in the result index its rows.

    Examples
    --------
    >>> import numpy as np
    >>> nb = neighbourhoods_from_arrays(3, np.array([[0, 1], [1, 2]]), np.eye(3),
    ...                                 np.ones(2), np.ones(3, dtype=np.int32))
    >>> nb.sizes.tolist()
    [1, 2, 1]
    """
    E = np.asarray(edges)
    r = np.asarray(rings, dtype=np.int32)
    ptr, nbr, eid = vertex_adjacency(n, E)
    nch = _chunks(n)
    nv, ne = _count(n, len(E), r, ptr, nbr, eid, nch)
    vptr = np.zeros(n + 1, dtype=np.int64)
    eptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(nv, out=vptr[1:])
    np.cumsum(ne, out=eptr[1:])
    W = np.ascontiguousarray(weights[:, None] * (P[E[:, 0]] - P[E[:, 1]]))
    disk_idx = np.empty(vptr[-1], dtype=np.int32)
    disk_coef = np.empty((vptr[-1], 3), dtype=np.float64)
    edge_idx = np.empty(eptr[-1], dtype=np.int32)
    edge_layer = np.empty(eptr[-1], dtype=np.int8)
    _fill(n, r, ptr, nbr, eid, E, W, vptr, eptr, nch, disk_idx, disk_coef, edge_idx,
          edge_layer)
    count = np.bincount(edge_idx, minlength=len(E))
    return Neighbourhoods(r, eptr, edge_idx, edge_layer, vptr, disk_idx, disk_coef, count)


def rings_summary(rings: np.ndarray) -> dict[str, object]:
    """Compact description of a rigidity map for reports.

    Examples
    --------
    >>> rings_summary(np.array([2, 2, 6]))
    {'min': 2, 'max': 6, 'counts': {'2': 2, '6': 1}}
    """
    values, counts = np.unique(np.asarray(rings), return_counts=True)
    return {
        "min": int(values.min()),
        "max": int(values.max()),
        "counts": {str(int(v)): int(c) for v, c in zip(values, counts, strict=True)},
    }
