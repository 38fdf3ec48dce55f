"""The neighbourhood graph of a point cloud: symmetrised k nearest neighbours, or a radius.

r-ring ARAP is defined on any edge graph (Chen et al. 2017, eq. 1); a point cloud has no
edges of its own, so it gets one here. :func:`knn_edges` links every point to its ``k``
nearest others and keeps each link once whichever end found it (the *symmetrised* kNN
graph: an edge when i is among j's k nearest **or** j among i's), so every point has at
least ``k`` neighbours and the graph of a surface sample is connected where the sample is
dense. :func:`radius_edges` links every pair closer than a radius instead (a point with no
other point that near is left alone: its own component). :func:`check_edges` is the rule
for a graph given by the caller.

Why ``k = 10`` (:data:`DEFAULT_NEIGHBOURS`): on clouds sampled from four meshes (the
cactus, CGAL's cow, elephant and homer, twice as many points as vertices), the RMS
distance of the cloud's deformation from the mesh's own ARAP result for the same handles
fell from k = 6 to k = 10 (0.42 -> 0.23 % of the diagonal on the cactus, 0.82 -> 0.42 %
on the cow) and little beyond, while an iteration costs in proportion to the edges
(``docs/clouds.md`` has the table and the command).

Examples
--------
>>> import numpy as np
>>> P = np.array([[0.0, 0, 0], [1, 0, 0], [3, 0, 0]])
>>> knn_edges(P, 1).tolist()
[[0, 1], [1, 2]]
>>> radius_edges(P, 1.5).tolist()
[[0, 1]]
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..validate import integer, number
from .topology import unique_edges

__all__ = ["DEFAULT_NEIGHBOURS", "MAX_NEIGHBOURS", "check_edges", "edge_lengths",
           "knn_edges", "radius_edges"]

#: neighbours per point of the default graph (see the module's docstring for why 10)
DEFAULT_NEIGHBOURS = 10
#: most neighbours per point: beyond this a typo (k = 1000) would build a graph of
#: 10^3 n edges and exhaust memory before any solve
MAX_NEIGHBOURS = 256
#: points queried at once (the query's arrays: 16 bytes per point and neighbour)
_QUERY_ROWS = 1 << 18


def _pairs_to_edges(i: np.ndarray, j: np.ndarray, n: int) -> np.ndarray:
    """Each undirected pair once, as ``(lo, hi)`` rows sorted lexicographically."""
    he = np.stack([i, j], axis=1).astype(np.int64)
    keys = unique_edges(np.ascontiguousarray(he), n)[0]  # one compiled counting sort
    return np.stack([keys // n, keys % n], axis=1)


def knn_edges(points: np.ndarray, k: int = DEFAULT_NEIGHBOURS, tree=None) -> np.ndarray:
    """The symmetrised k-nearest-neighbour graph of ``points`` (m, 2), ``i < j``, sorted.

    A point's own index is left out even where other points coincide with it (then the
    query may list one of them first). With fewer than ``k + 1`` points every pair is an
    edge.

    Parameters
    ----------
    points : (n, 3) float
    k : int
        Neighbours per point (1..:data:`MAX_NEIGHBOURS`).
    tree : scipy.spatial.cKDTree, optional
        A tree of ``points`` already built.

    Examples
    --------
    >>> P = np.array([[0.0, 0, 0], [0, 0, 0], [5, 0, 0]])  # two points coincide
    >>> knn_edges(P, 1).tolist()
    [[0, 1], [1, 2]]
    """
    from scipy.spatial import cKDTree

    k = integer(k, "neighbours", lo=1, hi=MAX_NEIGHBOURS)
    P = np.ascontiguousarray(points, dtype=np.float64)
    n = len(P)
    if n < 2:
        return np.zeros((0, 2), dtype=np.int64)
    kk = min(k, n - 1)
    tree = cKDTree(P) if tree is None else tree
    src, dst = [], []
    for a in range(0, n, _QUERY_ROWS):
        b = min(n, a + _QUERY_ROWS)
        idx = tree.query(P[a:b], k=kk + 1, workers=-1)[1].reshape(b - a, kk + 1)
        own = np.arange(a, b)[:, None]
        other = idx != own
        # where coincident points pushed the point itself out of its own list, the last
        # of the k + 1 is one too many
        full = other.all(axis=1)
        other[full, -1] = False
        src.append(np.broadcast_to(own, idx.shape)[other])
        dst.append(idx[other])
    return _pairs_to_edges(np.concatenate(src), np.concatenate(dst), n)


def radius_edges(points: np.ndarray, radius: float, tree=None) -> np.ndarray:
    """Every pair of ``points`` closer than ``radius`` (m, 2), ``i < j``, sorted.

    Examples
    --------
    >>> P = np.array([[0.0, 0, 0], [0.5, 0, 0], [0.9, 0, 0]])
    >>> radius_edges(P, 0.6).tolist()
    [[0, 1], [1, 2]]
    """
    from scipy.spatial import cKDTree

    radius = number(radius, "radius", lo=0.0, lo_open=True)
    P = np.ascontiguousarray(points, dtype=np.float64)
    if len(P) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    tree = cKDTree(P) if tree is None else tree
    pairs = tree.query_pairs(radius, output_type="ndarray")
    # query_pairs' distance test is <= r; "closer than" the radius, as documented
    d = np.linalg.norm(P[pairs[:, 0]] - P[pairs[:, 1]], axis=1) if len(pairs) else np.zeros(0)
    pairs = pairs[d < radius]
    if len(pairs) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    return _pairs_to_edges(pairs[:, 0], pairs[:, 1], len(P))


def edge_lengths(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Length of every edge.

    Examples
    --------
    >>> edge_lengths(np.array([[0.0, 0, 0], [3, 4, 0]]), np.array([[0, 1]])).tolist()
    [5.0]
    """
    E = np.asarray(edges, dtype=np.int64)
    return np.linalg.norm(points[E[:, 0]] - points[E[:, 1]], axis=1)


def check_edges(edges, n: int, name: str) -> np.ndarray:
    """A caller's edge list as (m, 2) int64: integers in ``0..n-1``, no loops, each
    undirected edge once (row order and orientation are kept: edge ids are row numbers).

    Examples
    --------
    >>> check_edges([[1, 0], [1, 2]], 3, "g").tolist()
    [[1, 0], [1, 2]]
    >>> check_edges([[0, 1], [1, 0]], 3, "g")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: g: edge 1 [1, 0] repeats edge 0 (each edge once)
    """
    try:
        E = np.asarray(edges)
    except (ValueError, TypeError):
        raise InputError(f"{name}: edges must be an (m, 2) integer array") from None
    if E.size == 0:
        E = E.reshape(0, 2)
    if E.ndim != 2 or E.shape[1] != 2:
        raise InputError(f"{name}: edges must be an (m, 2) integer array, got shape {E.shape}")
    if E.dtype.kind == "f":
        if not np.isfinite(E).all() or (E != np.round(E)).any():
            raise InputError(f"{name}: edges must be integer vertex indices")
    elif E.dtype.kind not in "iu" and len(E):
        raise InputError(f"{name}: edges must be integer vertex indices, got {E.dtype} values")
    big = (np.abs(E.astype(np.float64)) >= 2.0**62).any(axis=1) if len(E) else np.zeros(0, bool)
    E = np.where(big[:, None], -1, E).astype(np.int64)
    bad = np.flatnonzero(((E < 0) | (E >= n)).any(axis=1))
    if len(bad):
        raise InputError(f"{name}: edge {bad[0]} references a vertex outside 0..{n - 1}")
    loop = np.flatnonzero(E[:, 0] == E[:, 1])
    if len(loop):
        raise InputError(f"{name}: edge {loop[0]} joins vertex {E[loop[0], 0]} to itself")
    key = np.minimum(E[:, 0], E[:, 1]) * n + np.maximum(E[:, 0], E[:, 1])
    order = np.argsort(key, kind="stable")
    same = np.flatnonzero(key[order[1:]] == key[order[:-1]])
    if len(same):
        first, again = sorted((int(order[same[0]]), int(order[same[0] + 1])))
        raise InputError(f"{name}: edge {again} {E[again].tolist()} repeats edge {first} "
                         "(each edge once)")
    return np.ascontiguousarray(E)
