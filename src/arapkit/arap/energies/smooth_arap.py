"""Smooth ARAP (Oehri, Herholz, Sorkine-Hornung 2025): ARAP plus rotated Laplacian vectors.

ARAP pulls a spike when a single vertex is dragged: nothing in its energy sees more than
one edge at a time, so the handle's ring stretches instead of the surface bending. Smooth
ARAP adds a term that keeps each vertex's Laplacian vector, turned by the vertex's
rotation:

    E(p', R) = (1 - lam) E_r(p', R) + lam A sum_k |(L p')_k - R_k (L p)_k|^2 / M_k

with ``E_r`` r-ring ARAP (:mod:`arapkit.arap.energies.rring`; r = 1 is the paper's
spokes ARAP), ``L`` the Laplacian of the same edge weights ``w`` (``(L p)_k = sum_j
w_kj (p_k - p_j)``: the cotangent Laplacian, clamped as the weights are, by default
``cotan-clamped``), ``M_k`` the mixed Voronoi area of vertex k (libigl's default lumped
mass) and ``A`` the surface area. The paper's term has no ``A``: its ARAP term has units
of length^2 and its Laplacian term none, so without ``A`` the same ``lam`` would mean
another balance for the same shape in other units; with ``A`` (as SR-ARAP's alpha,
:mod:`arapkit.arap.energies.sr_arap`) ``lam`` is unitless, and on a mesh of unit area the
energy is the paper's. ``lam = 0`` is r-ring ARAP.

The form of the solver
----------------------
Write ``d_j = (p'_k - p'_j) - R_k (p_k - p_j)`` for the spokes of k and ``a_j = w_kj``,
``W_k = sum_j a_j``. Then ``(L p')_k - R_k (L p)_k = sum_j a_j d_j`` and, for any vectors,

    |sum_j a_j d_j|^2 = W_k sum_j a_j |d_j|^2 - sum_{j<l} a_j a_l |d_j - d_l|^2,

where ``d_j - d_l = (p'_l - p'_j) - R_k (p_l - p_j)`` is the residual of the pair (j, l)
under k's rotation. So Smooth ARAP is exactly an energy of the shared form
(:mod:`arapkit.arap.energies.base`), ``sum_k sum_e w_ke |e' - R_k e|^2``, with entries

* ``(1 - lam) w_e`` for every edge of N(k, r_k) (the r-ring term);
* ``c_k W_k w_kj`` for each spoke (k, j) and ``-c_k w_kj w_kl`` for each pair (j, l) of
  k's neighbours, ``c_k = lam A / M_k`` (the Laplacian term),

on the mesh's edges and the pairs two rings apart (:attr:`NeighbourhoodEnergy.extra_edges`).
Everything the loop needs follows from that form, as for every energy (negative entries
are allowed: the sum is the square above, so E >= 0):

* **Local step.** For fixed p', E is minimised over R_k alone by the best rotation of
  ``S_k = sum_v c_kv p'_v^T``, whose coefficients work out to
  ``c_kv = (1 - lam) c^ARAP_kv + c_k L_kv (L p)_k``: the cross-covariance of both terms,
  ``(1 - lam) S^ARAP_k + c_k (L p)_k (L p')_k^T``. The step is exact, so E never rises.
* **Global step.** The matrix is the Laplacian of the summed entry weights, which is
  ``(1 - lam) L_D + lam A L^T M^-1 L`` (``L_D`` the r-ring matrix): it does not depend on
  R, so it is factorised once per handle set; the right-hand side is ``sum_k R_k c_kv``.
  Each global step is the exact minimiser over the free positions: Smooth ARAP is a
  descent method, and Anderson acceleration's energy safeguard applies.

Where the paper differs: its summary speaks of fitting the rotations to the edges (the
ARAP covariance) for speed and stability; here each local step fits R_k to the whole
energy, which is what makes every iteration lower E (``tests/test_smooth_arap.py``
checks it). The rigidity map acts on the ARAP term only: a larger r makes a region
stiffer against stretching and bending, as in r-ring ARAP, while the Laplacian term stays
on each vertex's own ring.
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from ...mesh.weights import voronoi_areas
from ...validate import number
from ..graph import EdgeGraph
from .base import NeighbourhoodEnergy, energy_from_entries
from .rring import rring_energy
from .table import EnergyInfo, register_energy

__all__ = ["DEFAULT_LAMBDA", "check_smooth_lambda", "neighbour_pairs", "smooth_arap_energy"]

#: the paper's choice: the Laplacian term dominates, the ARAP term keeps the metric
DEFAULT_LAMBDA = 0.99


def check_smooth_lambda(value) -> float:
    """A weight ``lam`` in [0, 1): 0 is ARAP; at 1 the rotations would see one vector each.

    Examples
    --------
    >>> check_smooth_lambda("0.9")
    0.9
    >>> check_smooth_lambda(1)
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: smooth_lambda: must be below 1 (at 1 no edge fixes a rotation), got 1
    """
    lam = number(value, "smooth_lambda", lo=0.0, hi=1.0)
    if lam == 1.0:
        raise InputError(f"smooth_lambda: must be below 1 (at 1 no edge fixes a rotation), "
                         f"got {value!r}")
    return lam


def neighbour_pairs(ptr: np.ndarray, nbr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every pair of entries of one CSR row: (first, second) entry positions, first < second.

    Examples
    --------
    >>> a, b = neighbour_pairs(np.array([0, 3, 4]), np.array([5, 6, 7, 8]))
    >>> a.tolist(), b.tolist()
    ([0, 0, 1], [1, 2, 2])
    """
    t = np.arange(len(nbr))
    row_end = np.repeat(ptr[1:], np.diff(ptr))
    count = row_end - t - 1
    first = np.repeat(t, count)
    start = np.repeat(np.cumsum(count) - count, count)
    second = first + 1 + (np.arange(len(first)) - start)
    return first, second


def _edge_ids(n: int, edges: np.ndarray, a: np.ndarray, b: np.ndarray):
    """Ids of the pairs (a, b): a graph edge's own id, else a new id past the m edges.

    Returns the ids and the new pairs (each once, in the order of their ids).
    """
    m = len(edges)
    key = np.minimum(edges[:, 0], edges[:, 1]) * np.int64(n) + np.maximum(edges[:, 0],
                                                                           edges[:, 1])
    order = np.argsort(key)
    sk = key[order]
    want = np.minimum(a, b).astype(np.int64) * n + np.maximum(a, b)
    pos = np.minimum(np.searchsorted(sk, want), max(m - 1, 0))
    found = sk[pos] == want if m else np.zeros(len(want), dtype=bool)
    ids = np.empty(len(want), dtype=np.int64)
    ids[found] = order[pos[found]]
    new_keys, inv = np.unique(want[~found], return_inverse=True)
    ids[~found] = m + inv.ravel()
    extra = np.stack([new_keys // n, new_keys % n], axis=1)
    return ids, extra


def smooth_arap_energy(graph: EdgeGraph, w: np.ndarray, rings,
                       lam: float = DEFAULT_LAMBDA) -> NeighbourhoodEnergy:
    """Smooth ARAP's structure on a triangle mesh's edge graph (see the module docstring).

    ``rings`` is r per vertex in the graph's numbering (already checked).

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar(segments=(4, 2, 2))
    >>> g = EdgeGraph.from_mesh(m)
    >>> en = smooth_arap_energy(g, np.ones(len(m.edges)), np.ones(m.n_vertices, np.int32))
    >>> en.name, len(en.system_w) == len(m.edges) + len(en.extra_edges)
    ('smooth-arap', True)
    """
    lam = check_smooth_lambda(lam)
    n, E = graph.n_vertices, graph.edges
    rings = np.asarray(rings, dtype=np.int32)
    arap = rring_energy(graph, w, rings)
    # the r-ring term's entries (k, e, w_e), scaled by 1 - lam
    k_r = np.repeat(np.arange(n), np.diff(arap.nbh.edge_ptr))
    e_r = arap.nbh.edge_idx.astype(np.int64)
    w_r = (1.0 - lam) * w[e_r]
    # the Laplacian term: spokes (k, j) and pairs (j, l) of k's neighbours
    adj = graph.adjacency.tocsr()
    adj.sort_indices()
    ptr, nbr = adj.indptr.astype(np.int64), adj.indices.astype(np.int64)
    k_s = np.repeat(np.arange(n), np.diff(ptr))
    spoke_ids, _ = _edge_ids(n, E, k_s, nbr)
    a = w[spoke_ids]                                  # w_kj for each spoke
    W = np.bincount(k_s, a, n)
    M = voronoi_areas(graph)  # they sum to the surface area A
    # a vertex on no triangle has no spokes either: its term is 0, not 0/0
    c = np.where(M > 0, lam * M.sum() / np.where(M > 0, M, 1.0), 0.0)
    first, second = neighbour_pairs(ptr, nbr)
    pair_ids, extra = _edge_ids(n, E, nbr[first], nbr[second])
    k_p = k_s[first]
    k = np.concatenate([k_r, k_s, k_p])
    e = np.concatenate([e_r, spoke_ids, pair_ids])
    w_ke = np.concatenate([w_r, c[k_s] * W[k_s] * a, -c[k_p] * a[first] * a[second]])
    wide = EdgeGraph(graph.vertices, np.concatenate([E, extra]), graph.name)
    en = energy_from_entries("smooth-arap", wide, k, e, w_ke,
                             options={"smooth_lambda": lam}, extra_edges=extra)
    en.nbh.rings = rings
    return en


def _build(graph: EdgeGraph, w: np.ndarray, weights_kind, rings, perm,
           smooth_lambda: float = DEFAULT_LAMBDA) -> NeighbourhoodEnergy:
    return smooth_arap_energy(graph, w, rings, smooth_lambda)


# every step minimises E exactly over its block (see the module docstring): a descent method
register_energy(EnergyInfo("smooth-arap", _build, descent=True, rigidity_map=True,
                           needs_faces=True, options=("smooth_lambda",)))
