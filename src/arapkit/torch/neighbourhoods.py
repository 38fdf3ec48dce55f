"""The neighbourhoods of the graph ARAP loss: a kNN or given graph, its weights, r-rings.

:func:`knn_graph` finds each point's k nearest neighbours (scipy's ``cKDTree``);
:func:`graph_neighbourhoods` turns a graph into :class:`GraphNeighbourhoods`, the flat
list of the energy's terms ``(k, i, j, w)``: owner ``k`` (whose rotation ``R_k`` the term
uses), edge ``(i, j)`` and weight. Two kinds:

* an undirected graph (the symmetrised kNN graph, or the caller's edges): the terms of
  ``N(k, r_k)``, the r-ring neighbourhoods of arapkit's engine
  (:func:`arapkit.arap.rings.neighbourhoods_from_arrays`, defined on any edge graph), so the
  loss is the engine's r-ring energy on that graph;
* a directed kNN graph (``symmetric=False``): point k's terms are its own k nearest
  neighbours ``(j, k)`` only, as in Dynamic 3D Gaussians' rigidity loss (r = 1 only).

The terms use an internal numbering of the points, the engine's bandwidth-reducing order
(:func:`arapkit.arap.graph.bandwidth_order`): neighbours are then near each other in
memory, which made the compiled loss a third cheaper on 100K random points. Everything
here is numpy; the loss (:mod:`arapkit.torch.graph_loss`) moves it to tensors. Memory is
O(number of terms): for r = 1 about ``2 k n`` (symmetrised) or ``k n`` (directed).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..arap.graph import EdgeGraph, bandwidth_order, check_graph
from ..arap.rings import check_rings, neighbourhoods_from_arrays
from ..errors import InputError

__all__ = ["GraphNeighbourhoods", "edge_weights_of", "graph_neighbourhoods", "knn_graph",
           "rest_points"]

#: the named weightings; a callable of the squared rest lengths or an array also work
WEIGHTS = ("gaussian", "uniform")


def rest_points(points, name: str) -> np.ndarray:
    """Points as a finite ``(n, 3)`` float64 array, else a one-line :class:`InputError`.

    Examples
    --------
    >>> rest_points([[0, 0, 0], [1, 0, 0]], "pts").shape
    (2, 3)
    """
    if hasattr(points, "detach"):  # a torch tensor, on any device
        points = points.detach().cpu().numpy()
    try:
        P = np.array(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: points must be numbers of shape (n, 3)") from None
    if P.ndim != 2 or P.shape[1] != 3 or len(P) == 0:
        raise InputError(f"{name}: points must have shape (n, 3), got {P.shape}")
    bad = ~np.isfinite(P).all(axis=1)
    if bad.any():
        raise InputError(f"{name}: point {int(np.argmax(bad))} is not finite")
    return P


def knn_graph(points: np.ndarray, k: int, name: str = "points") -> tuple[np.ndarray, np.ndarray]:
    """Each point's ``k`` nearest other points (scipy's ``cKDTree``), nearest first.

    Returns ``(nbr, d2)``, both ``(n, k)``: neighbour indices and squared distances. A point
    is never its own neighbour, even among duplicates.

    Examples
    --------
    >>> nbr, d2 = knn_graph(np.array([[0.0, 0, 0], [1, 0, 0], [3, 0, 0]]), 1)
    >>> nbr.ravel().tolist(), d2.ravel().tolist()
    ([1, 0, 1], [1.0, 1.0, 4.0])
    """
    from scipy.spatial import cKDTree

    n = len(points)
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise InputError(f"{name}: k must be a positive integer, got {k!r}")
    if k >= n:
        raise InputError(f"{name}: k = {k} needs at least {k + 1} points, got {n}")
    d, idx = cKDTree(points).query(points, k + 1, workers=-1)
    # drop the point itself wherever it landed (duplicates tie with it at distance 0);
    # rows where it did not land drop their farthest candidate instead
    other = idx != np.arange(n)[:, None]
    other[other.all(axis=1), -1] = False
    keep = np.argsort(~other, axis=1, kind="stable")[:, :k]
    nbr = np.take_along_axis(idx, keep, axis=1).astype(np.int64)
    d2 = np.take_along_axis(d, keep, axis=1) ** 2
    return nbr, d2


def symmetric_edges(nbr: np.ndarray) -> np.ndarray:
    """The undirected edges ``(m, 2)`` of a kNN graph, each once (``i < j``).

    Examples
    --------
    >>> symmetric_edges(np.array([[1], [0], [1]])).tolist()
    [[0, 1], [1, 2]]
    """
    n, k = nbr.shape
    a = np.repeat(np.arange(n, dtype=np.int64), k)
    b = nbr.ravel()
    key = np.sort(np.minimum(a, b) * n + np.maximum(a, b))
    # sorted, then the first of each run: numpy 2's hashing np.unique took 1.3 s here
    key = key[np.concatenate([[True], key[1:] != key[:-1]])]
    return np.stack([key // n, key % n], axis=1)


def edge_weights_of(weights, d2: np.ndarray, name: str) -> np.ndarray:
    """Weights of edges with squared rest lengths ``d2`` (any shape), checked.

    ``weights`` is ``"uniform"`` (1), ``"gaussian"`` (``exp(-d2 / h^2)`` with ``h`` the mean
    edge length: scale-free), a callable of ``d2`` (a float64 tensor when torch is there,
    e.g. ``lambda d2: torch.exp(-2000 * d2)``) or an array of ``d2``'s shape. They must be
    finite and >= 0.

    Examples
    --------
    >>> edge_weights_of("gaussian", np.array([1.0, 4.0]), "w").round(4).tolist()
    [0.6412, 0.169]
    """
    if isinstance(weights, str):
        if weights == "uniform":
            w = np.ones_like(d2)
        elif weights == "gaussian":
            h = float(np.sqrt(d2).mean()) if d2.size else 0.0
            w = np.exp(-d2 / h**2) if h > 0 else np.ones_like(d2)
        else:
            raise InputError(f"{name}: unknown weights {weights!r} (use "
                             f"{' or '.join(map(repr, WEIGHTS))}, a function of the squared "
                             "rest lengths, or one weight per edge)")
    elif callable(weights):
        w = _call_weights(weights, d2, name)
    else:
        try:
            w = np.array(weights.detach().cpu() if hasattr(weights, "detach") else weights,
                         dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"{name}: weights must be numbers, one per edge") from None
        if w.shape != d2.shape:
            raise InputError(f"{name}: weights must have shape {d2.shape} (one per edge), got "
                             f"{w.shape}")
    bad = ~np.isfinite(w) | (w < 0)
    if bad.any():
        t = int(np.argmax(bad.ravel()))
        raise InputError(f"{name}: weight {t} is {float(w.ravel()[t])!r} (weights must be "
                         "finite and >= 0)")
    return w


def _call_weights(f: Callable, d2: np.ndarray, name: str) -> np.ndarray:
    """``f(d2)`` on a float64 tensor (numpy when torch cannot be imported), as numpy."""
    try:
        import torch

        arg = torch.from_numpy(d2)
    except ImportError:  # the helpers are numpy; the loss itself needs torch anyway
        arg = d2
    out = f(arg)
    if hasattr(out, "detach"):
        out = out.detach().cpu().numpy()
    w = np.asarray(out, dtype=np.float64)
    if w.shape != d2.shape:
        raise InputError(f"{name}: the weight function returned shape {w.shape} for "
                         f"{d2.shape} squared lengths")
    return w


@dataclass(frozen=True)
class GraphNeighbourhoods:
    """The terms of the graph ARAP energy, grouped by owner (CSR), and their transpose.

    Term ``t`` of owner ``k`` (``ptr[k] <= t < ptr[k + 1]``) is
    ``w[t] |(x_i - x_j) - R_k (p_i - p_j)|^2`` with ``i = ei[t]``, ``j = ej[t]``.
    ``ti_ptr``/``ti_idx`` list, for each point v, the terms with ``ei = v`` (and ``tj_*``
    those with ``ej = v``), so that the gradient is gathered per point without races.
    Points are numbered internally: internal point ``a`` is the caller's ``perm[a]``.

    Attributes
    ----------
    n : int
    perm : (n,) int64
        Internal -> caller numbering.
    ptr : (n + 1,) int64
    ei, ej : (M,) int32
    w : (M,) float64
    ti_ptr, ti_idx, tj_ptr, tj_idx : int64 / int32
    edges : (m, 2) int64 or None
        The undirected graph, caller numbering (None for a directed kNN graph).
    edge_w : (m,) float64 or None
        Its weights.
    rings : (n,) int32
        r per point, caller numbering.
    """

    n: int
    perm: np.ndarray
    ptr: np.ndarray
    ei: np.ndarray
    ej: np.ndarray
    w: np.ndarray
    ti_ptr: np.ndarray
    ti_idx: np.ndarray
    tj_ptr: np.ndarray
    tj_idx: np.ndarray
    edges: np.ndarray | None
    edge_w: np.ndarray | None
    rings: np.ndarray

    @property
    def n_terms(self) -> int:
        """M, the number of terms (the divisor of ``reduction="mean"``)."""
        return len(self.w)

    @property
    def owner(self) -> np.ndarray:
        """Owner ``k`` of each term, ``(M,)`` int64."""
        return np.repeat(np.arange(self.n, dtype=np.int64), np.diff(self.ptr))


def _transpose(idx: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR of the terms by the point ``idx[t]`` they touch (terms in increasing order)."""
    order = np.argsort(idx, kind="stable").astype(np.int32)
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(idx, minlength=n), out=ptr[1:])
    return ptr, order


def graph_neighbourhoods(points: np.ndarray, k: int | None = None, edges=None, weights="gaussian",
                         rings=1, symmetric: bool = True,
                         name: str = "GraphARAPLoss") -> GraphNeighbourhoods:
    """The terms of the loss on ``points`` (checked, ``(n, 3)`` float64).

    The graph is ``edges`` (undirected, each once) when given, else the kNN graph: its
    edges symmetrised (``symmetric=True``: the engine's graph, r-rings apply) or each
    point's own ``k`` neighbours (``symmetric=False``, r = 1). Weights: see
    :func:`edge_weights_of` (of the squared lengths at ``points``).

    Examples
    --------
    >>> P = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> nb = graph_neighbourhoods(P, 2)
    >>> len(nb.edges), nb.n_terms  # 5 undirected edges, each in the rings of both ends
    (5, 10)
    >>> graph_neighbourhoods(P, 2, symmetric=False).n_terms
    8
    """
    n = len(points)
    if edges is None:
        if k is None:
            raise InputError(f"{name}: give k (a kNN graph) or edges")
        nbr, d2 = knn_graph(points, k, name)
        E = symmetric_edges(nbr)
        if not isinstance(weights, str) and not callable(weights):
            raise InputError(f"{name}: per-edge weights need edges=; with a kNN graph use "
                             f"{' or '.join(map(repr, WEIGHTS))} or a function")
        if not symmetric:
            r = check_rings(rings, n)
            if (r != 1).any():
                raise InputError(f"{name}: rings > 1 need the symmetric kNN graph (the "
                                 "r-rings of an undirected graph); use symmetric=True")
            w = edge_weights_of(weights, d2, name).ravel()
            perm, iperm = _order(points, E)
            # internal owner a holds its k terms (neighbour, a), in the caller's kNN order
            ei = iperm[nbr[perm]].ravel().astype(np.int32)
            ej = np.repeat(np.arange(n, dtype=np.int32), k)
            ptr = np.arange(0, n * k + 1, k, dtype=np.int64)
            return GraphNeighbourhoods(n, perm, ptr, ei, ej, w.reshape(n, k)[perm].ravel(),
                                       *_transpose(ei, n), *_transpose(ej, n), None, None, r)
    else:
        if not symmetric:
            raise InputError(f"{name}: symmetric=False is for kNN graphs; given edges are "
                             "undirected")
        given = np.asarray(edges)
        _, E, _ = check_graph(points, given, np.zeros(given.shape[0] if given.ndim else 0),
                              name)
    d2 = ((points[E[:, 0]] - points[E[:, 1]]) ** 2).sum(axis=1)
    w = edge_weights_of(weights, d2, name)
    r = check_rings(rings, n)
    perm, iperm = _order(points, E)
    Ei = iperm[E]
    nbh = neighbourhoods_from_arrays(n, Ei, points[perm], w, r[perm])
    eid = nbh.edge_idx
    ei = Ei[eid, 0].astype(np.int32)
    ej = Ei[eid, 1].astype(np.int32)
    return GraphNeighbourhoods(n, perm, nbh.edge_ptr.astype(np.int64), ei, ej, w[eid],
                               *_transpose(ei, n), *_transpose(ej, n), E, w, r)


def _order(points: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The engine's bandwidth-reducing order of the graph (internal -> caller) and its
    inverse."""
    n = len(points)
    perm = bandwidth_order(EdgeGraph(points, edges)) if n > 1 else np.arange(n)
    iperm = np.empty(n, dtype=np.int64)
    iperm[perm] = np.arange(n)
    return perm.astype(np.int64), iperm
