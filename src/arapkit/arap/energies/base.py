"""Energies of the local/global solver: one precomputed neighbourhood structure each.

Every local/global energy here has the form

    E(p', R) = sum_k sum_{e in N(k)} w_ke |(p'_i - p'_j) - R_k (p_i - p_j)|^2  [+ C(R)]

with a neighbourhood ``N(k)`` of edges for every vertex k and a weight ``w_ke`` for each
(k, e) pair. From that alone follow (see :mod:`arapkit.methods.deformer` for the derivation):

* the covariances ``S_k = sum_v c_kv p'_v^T`` and the right-hand side
  ``b_v = sum_k R_k c_kv``, with ``c_kv = sum_{e in N(k), e touches v} s_ev w_ke e_e``;
* the global matrix, the Laplacian of the edge weights ``D_e = sum_k w_ke``;
* the value ``sum_e D_e |e'|^2 + sum_e D_e |e|^2 - 2 sum_k tr(R_k S_k)``.

An energy is therefore data (:class:`NeighbourhoodEnergy`), not code: a backend runs the
same kernels for all of them. The rotations' owners k are the vertices, and may go on past
them: an owner ``k >= n`` is a rotation of its own (a triangle's, in the blended energy of
a coarse mesh, :mod:`arapkit.arap.energies.rring`), centred on a vertex it touches.

``C(R)`` is an optional coupling between neighbouring
rotations, ``sum_k sum_j c_kj |R_k - R_j|_F^2`` (SR-ARAP), which adds ``c_kj R_j^T`` to
``S_k`` (with the neighbours' previous rotations) and a constant to the value.

This module holds that shared structure; each energy is one module that builds it and
registers itself (:mod:`arapkit.arap.energies.table`): ``rring`` (Chen et al. 2017,
:mod:`arapkit.arap.energies.rring`), ``spokes-and-rims``
(:mod:`arapkit.arap.energies.spokes_rims`), ``sr-arap`` (:mod:`arapkit.arap.energies.sr_arap`).
Embedded deformation
(:mod:`arapkit.methods.embedded`) is not a local/global ARAP energy and has its own solver.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numba as nb
import numpy as np

from ..rings import Neighbourhoods

if TYPE_CHECKING:
    from ..graph import EdgeGraph

__all__ = ["NeighbourhoodEnergy", "energy_from_entries", "owner_rows", "rest_term"]


@dataclass(frozen=True, eq=False)
class NeighbourhoodEnergy:
    """Precomputed structure of one local/global energy (internal vertex numbering).

    Attributes
    ----------
    name : str
    nbh : Neighbourhoods
        ``N(k)`` as edge lists (``edge_ptr``, ``edge_idx``) and as disks with the
        coefficients ``c_kv`` (``disk_ptr``, ``disk_idx``, ``disk_coef``).
    entry_w : (nnz,) float64 or None
        ``w_ke`` for each entry of ``edge_idx``; None means ``w_ke = w_e`` (r-ring).
    system_w : (m,) float64
        ``D_e = sum_k w_ke``, the global step's Laplacian weights.
    rest_term : float
        ``sum_e D_e |e|^2`` plus the coupling's constant.
    coupling : (ptr, idx, coef) or None
        ``c_kj`` of the rotation coupling in CSR form.
    options : dict
        The energy's parameters, for reports; an energy rebuilt for a new rigidity map
        keeps them (:meth:`arapkit.arap.problem.ARAPProblem.with_rings`).
    centres : (K - n,) int32 or None
        Where the owners past the vertices have rotations of their own (``nbh``'s rows
        n ... K-1): the vertex each is centred on. None: one rotation per vertex.
    extra_edges : (m2, 2) int64 or None
        Vertex pairs past the graph's m edges that the entries use, as edge ids m ...
        m + m2 - 1 (smooth ARAP's terms couple vertices two rings apart,
        :mod:`arapkit.arap.energies.smooth_arap`); ``system_w`` then has m + m2 weights.
        None: the graph's edges only.
    """

    name: str
    nbh: Neighbourhoods
    entry_w: np.ndarray | None
    system_w: np.ndarray
    rest_term: float
    coupling: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    options: dict[str, Any] = field(default_factory=dict)
    centres: np.ndarray | None = None
    extra_edges: np.ndarray | None = None

    @property
    def rings(self) -> np.ndarray:
        """r per vertex (internal numbering); 1 for the non-r-ring energies."""
        return self.nbh.rings

    @property
    def n_owners(self) -> int:
        """K, the number of rotations: the vertices, and the owners past them."""
        return len(self.nbh.disk_ptr) - 1


@nb.njit(parallel=True, cache=True, nogil=True)
def _weighted_edge_norms(P, edges, dw):
    total = 0.0
    for e in nb.prange(edges.shape[0]):
        i, j = edges[e, 0], edges[e, 1]
        dx, dy, dz = P[i, 0] - P[j, 0], P[i, 1] - P[j, 1], P[i, 2] - P[j, 2]
        total += dw[e] * (dx * dx + dy * dy + dz * dz)
    return total


def rest_term(graph: EdgeGraph, system_w: np.ndarray) -> float:
    """``sum_e D_e |e|^2`` at rest."""
    return float(_weighted_edge_norms(graph.vertices, graph.edges, system_w))


def owner_rows(P: np.ndarray, E: np.ndarray, n_owners: int, k: np.ndarray, e: np.ndarray,
               w_ke: np.ndarray) -> tuple[np.ndarray, ...]:
    """CSR rows of ``n_owners`` neighbourhoods from their (k, e, w_ke) triplets.

    Repeated (k, e) pairs are summed. Returns ``edge_ptr, edge_idx, w, disk_ptr, disk_idx,
    disk_coef`` (see :class:`arapkit.arap.rings.Neighbourhoods`), ``w`` being each entry's
    weight; a disk lists its vertices in increasing order.

    Examples
    --------
    >>> import numpy as np
    >>> rows = owner_rows(np.eye(3), np.array([[0, 1], [1, 2]]), 1, np.array([0, 0]),
    ...                   np.array([0, 1]), np.ones(2))
    >>> rows[4].tolist(), rows[5][:, 0].tolist()  # disk of owner 0: c_0v, x components
    ([0, 1, 2], [1.0, -1.0, 0.0])
    """
    n, m = len(P), len(E)
    key, inv = np.unique(k.astype(np.int64) * m + e, return_inverse=True)
    wk = np.bincount(inv.ravel(), w_ke, len(key))
    kk, ee = key // m, key % m
    edge_ptr = np.zeros(n_owners + 1, dtype=np.int64)
    np.cumsum(np.bincount(kk, minlength=n_owners), out=edge_ptr[1:])
    # disks: each entry touches both ends of its edge with opposite signs
    d = wk[:, None] * (P[E[ee, 0]] - P[E[ee, 1]])
    dk = np.concatenate([kk, kk])
    dv = np.concatenate([E[ee, 0], E[ee, 1]])
    dkey, dinv = np.unique(dk * n + dv, return_inverse=True)
    dinv = dinv.ravel()
    coef = np.stack([np.bincount(dinv, np.concatenate([d[:, a], -d[:, a]]), len(dkey))
                     for a in range(3)], axis=1)
    disk_ptr = np.zeros(n_owners + 1, dtype=np.int64)
    np.cumsum(np.bincount(dkey // n, minlength=n_owners), out=disk_ptr[1:])
    return (edge_ptr, ee.astype(np.int32), wk, disk_ptr, (dkey % n).astype(np.int32),
            np.ascontiguousarray(coef))


def energy_from_entries(name: str, graph: EdgeGraph, k: np.ndarray, e: np.ndarray,
                        w_ke: np.ndarray, **kw) -> NeighbourhoodEnergy:
    """Build an energy from its (k, e, w_ke) triplets (repeated pairs are summed).

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.arap.graph import EdgeGraph
    >>> g = EdgeGraph(np.eye(3), np.array([[0, 1], [1, 2]]))
    >>> en = energy_from_entries("demo", g, np.array([0, 1, 1]), np.array([0, 0, 1]),
    ...                          np.ones(3))
    >>> en.system_w.tolist(), en.nbh.sizes.tolist()
    ([2.0, 1.0], [1, 2, 0])
    """
    n, E, P = graph.n_vertices, graph.edges, graph.vertices
    m = len(E)
    edge_ptr, ee, wk, disk_ptr, disk_idx, coef = owner_rows(P, E, n, k, e, w_ke)
    system_w = np.bincount(ee, wk, m)
    nbh = Neighbourhoods(
        rings=np.ones(n, dtype=np.int32), edge_ptr=edge_ptr, edge_idx=ee,
        edge_layer=np.ones(len(ee), dtype=np.int8), disk_ptr=disk_ptr,
        disk_idx=disk_idx, disk_coef=coef, edge_count=np.bincount(ee, minlength=m),
    )
    return NeighbourhoodEnergy(name, nbh, wk, system_w, rest_term(graph, system_w), **kw)
