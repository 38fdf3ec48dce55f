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

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

import numba as nb
import numpy as np

from ..mesh.model import Mesh
from ..mesh.topology import vertex_adjacency
from ..validate import MAX_RINGS, ring_sizes
from .ringcost import RingCost, check_ring_memory

__all__ = [
    "MAX_RINGS",
    "BuildCancelled",
    "Neighbourhoods",
    "build_neighbourhoods",
    "check_rings",
    "edge_counts",
    "neighbourhoods_from_arrays",
    "ring_progress",
    "rings_summary",
    "vertex_adjacency",
]


#: r per vertex, checked: the one rule of :func:`arapkit.validate.ring_sizes` (int32)
check_rings = ring_sizes


@nb.njit(cache=True, nogil=True)
def _bfs(k, stamp_k, r, adj_ptr, adj_nbr, adj_eid, stamp, depth, pos, queue, vout, eout,
         lout):
    """BFS from k; write disk vertices to vout and (edge, layer) to eout/lout; return counts.

    With ``vout`` of length 0 only counts are returned. ``stamp_k`` marks what this search
    visited (distinct per search, so the thread's scratch needs no clearing). An edge is
    recorded from whichever end leaves the queue first (``pos``: place in the queue), with
    layer ``1 + depth`` of that end: no per-edge scratch.
    """
    write = len(vout) > 0
    stamp[k] = stamp_k
    depth[k] = 0
    pos[k] = 0
    queue[0] = k
    head, tail, ne = 0, 1, 0
    while head < tail:
        u = queue[head]
        pu = head
        head += 1
        d = depth[u]
        if d >= r:
            continue
        for t in range(adj_ptr[u], adj_ptr[u + 1]):
            v = adj_nbr[t]
            if stamp[v] != stamp_k:
                stamp[v] = stamp_k
                depth[v] = d + 1
                pos[v] = tail
                queue[tail] = v
                tail += 1
            elif pos[v] < pu:  # v left the queue first: the edge is recorded already
                continue
            if write:
                eout[ne] = adj_eid[t]
                lout[ne] = d + 1
            ne += 1
    if write:
        for t in range(tail):
            vout[t] = queue[t]
    return tail, ne


@nb.njit(parallel=True, cache=True, nogil=True)
def _count(lo, hi, rings, adj_ptr, adj_nbr, adj_eid, scratch, nv, ne):
    """Ring sizes of vertices lo..hi-1 into ``nv`` (disk) and ``ne`` (edges)."""
    n_chunks = 4 * scratch.shape[1]
    size = (hi - lo + n_chunks - 1) // n_chunks
    dummy_i = np.empty(0, dtype=np.int32)
    dummy_l = np.empty(0, dtype=np.int8)
    for c in nb.prange(n_chunks):
        t = nb.get_thread_id()
        for k in range(lo + c * size, min(hi, lo + (c + 1) * size)):
            a, b = _bfs(k, k, rings[k], adj_ptr, adj_nbr, adj_eid, scratch[0, t],
                        scratch[1, t], scratch[2, t], scratch[3, t], dummy_i, dummy_i, dummy_l)
            nv[k] = a
            ne[k] = b


@nb.njit(parallel=True, cache=True, nogil=True)
def _fill(lo, hi, rings, adj_ptr, adj_nbr, adj_eid, edges, W, vptr, eptr, scratch,
          disk_idx, disk_coef, edge_idx, edge_layer):
    """Write the rings of vertices lo..hi-1 and their coefficients ``c_kv``."""
    n = len(rings)
    n_chunks = 4 * scratch.shape[1]
    size = (hi - lo + n_chunks - 1) // n_chunks
    for c in nb.prange(n_chunks):
        t = nb.get_thread_id()
        slot = scratch[4, t]  # a disk vertex's place in its disk
        for k in range(lo + c * size, min(hi, lo + (c + 1) * size)):
            v0, v1 = vptr[k], vptr[k + 1]
            e0, e1 = eptr[k], eptr[k + 1]
            # stamps past the counting pass's (k): this search starts from clean marks
            _bfs(k, n + k, rings[k], adj_ptr, adj_nbr, adj_eid, scratch[0, t], scratch[1, t],
                 scratch[2, t], scratch[3, t], disk_idx[v0:v1], edge_idx[e0:e1],
                 edge_layer[e0:e1])
            for q in range(v0, v1):
                slot[disk_idx[q]] = q - v0
                disk_coef[q, 0] = 0.0
                disk_coef[q, 1] = 0.0
                disk_coef[q, 2] = 0.0
            for q in range(e0, e1):
                e = edge_idx[q]
                si = v0 + slot[edges[e, 0]]
                sj = v0 + slot[edges[e, 1]]
                for a in range(3):
                    disk_coef[si, a] += W[e, a]
                    disk_coef[sj, a] -= W[e, a]


@nb.njit(cache=True, nogil=True)
def edge_counts(edge_idx, m):
    """d_e: how many neighbourhoods hold each edge of ``edge_idx`` (ids below ``m``).

    ``np.bincount`` would first copy ``edge_idx`` to int64 (4.3 GiB for r = 100 on a
    13K-vertex mesh); this counts in place.

    Examples
    --------
    >>> edge_counts(np.array([0, 2, 2], dtype=np.int32), 3).tolist()
    [1, 0, 2]
    """
    out = np.zeros(m, dtype=np.int64)
    for q in range(len(edge_idx)):
        out[edge_idx[q]] += 1
    return out


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


def build_neighbourhoods(mesh: Mesh, weights: np.ndarray, rings) -> Neighbourhoods:
    """Breadth-first search of N(k, r_k) for every vertex, compiled and parallel.

    Refused in one line where the estimated memory exceeds what is available
    (:func:`arapkit.arap.ringcost.check_ring_memory`); reports progress to the callback of
    :func:`ring_progress`.

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
                                      check_rings(rings, n), name=mesh.name)


class BuildCancelled(Exception):
    """A ring build stopped because its progress callback asked it to (nothing was kept)."""


#: the progress callback of ring builds in this thread (see :func:`ring_progress`)
_PROGRESS: ContextVar[Callable[[float, RingCost], bool | None] | None] = ContextVar(
    "arapkit_ring_progress", default=None)
#: builds estimated shorter than this run in one piece, without progress reports
PROGRESS_FROM_S = 0.5
#: the share of a build's time its counting pass takes (measured: 0.2-0.3)
_COUNT_SHARE = 0.25


@contextmanager
def ring_progress(callback: Callable[[float, RingCost], bool | None]) -> Iterator[None]:
    """Report the progress of the ring builds run inside the block (this thread only).

    ``callback(fraction, cost)`` is called with the fraction done (0 at the start, 1 at
    the end) and the build's :class:`~arapkit.arap.ringcost.RingCost`, a few times a
    second, for builds estimated at :data:`PROGRESS_FROM_S` or longer; a true return value
    cancels the build (:class:`BuildCancelled`). The command line shows a tqdm bar with it,
    the editor its progress bar.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> from arapkit.mesh.weights import edge_weights
    >>> m = bar()
    >>> seen = []
    >>> with ring_progress(lambda f, cost: seen.append(f)):
    ...     _ = build_neighbourhoods(m, edge_weights(m), 3)
    >>> seen  # a build this short runs in one piece
    []
    """
    token = _PROGRESS.set(callback)
    try:
        yield
    finally:
        _PROGRESS.reset(token)


def _blocks(n: int, seconds: float) -> np.ndarray:
    """Vertex ranges of about a tenth of a second each (one range for a short build)."""
    count = 1 if seconds < PROGRESS_FROM_S else int(min(n, max(4, seconds / 0.1), 2000))
    return np.linspace(0, n, count + 1).astype(np.int64)


def neighbourhoods_from_arrays(
    n: int, edges: np.ndarray, P: np.ndarray, weights: np.ndarray, rings: np.ndarray,
    *, name: str = "graph", cost: RingCost | None = None,
) -> Neighbourhoods:
    """:func:`build_neighbourhoods` on raw arrays (any vertex numbering, e.g. a reordering).

    ``edges`` need not be sorted; edge ids in the result index its rows. ``cost``: the
    estimate already checked by the caller (:func:`arapkit.arap.ringcost.check_ring_memory`);
    without it the build checks its own, naming ``name`` in a refusal.

    The build holds the finished structure, the per-vertex counts and one scratch row per
    thread, no more: it counts every ring first, then writes each into its place.

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
    if cost is None:
        cost = check_ring_memory(n, E, r, name)
    ptr, nbr, eid = vertex_adjacency(n, E)
    threads = nb.get_num_threads()
    scratch = np.empty((5, threads, n), dtype=np.int32)
    scratch[0] = -1  # stamps: a search marks what it visited with its own number
    blocks = _blocks(n, cost.seconds)
    report = _PROGRESS.get() if len(blocks) > 2 else None

    def step(fraction: float) -> None:
        if report is not None and report(fraction, cost):
            raise BuildCancelled(f"{name}: the r-ring build was cancelled")

    step(0.0)
    nv = np.empty(n, dtype=np.int64)
    ne = np.empty(n, dtype=np.int64)
    for b in range(len(blocks) - 1):
        _count(blocks[b], blocks[b + 1], r, ptr, nbr, eid, scratch, nv, ne)
        step(_COUNT_SHARE * blocks[b + 1] / n)
    vptr = np.zeros(n + 1, dtype=np.int64)
    eptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(nv, out=vptr[1:])
    np.cumsum(ne, out=eptr[1:])
    del nv, ne
    W = np.ascontiguousarray(weights[:, None] * (P[E[:, 0]] - P[E[:, 1]]))
    disk_idx = np.empty(vptr[-1], dtype=np.int32)
    disk_coef = np.empty((vptr[-1], 3), dtype=np.float64)
    edge_idx = np.empty(eptr[-1], dtype=np.int32)
    edge_layer = np.empty(eptr[-1], dtype=np.int8)
    for b in range(len(blocks) - 1):
        _fill(blocks[b], blocks[b + 1], r, ptr, nbr, eid, E, W, vptr, eptr, scratch,
              disk_idx, disk_coef, edge_idx, edge_layer)
        # the fill's share by entries written: a per-vertex map's large rings take longer
        done = eptr[blocks[b + 1]] / max(int(eptr[-1]), 1)
        step(_COUNT_SHARE + (1.0 - _COUNT_SHARE) * done)
    del scratch
    count = edge_counts(edge_idx, len(E))
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
