"""r-ring ARAP (Chen et al. 2017, eq. 1): the neighbourhood of k is every edge within r_k rings.

    E(p', R) = sum_k sum_{e in N(k, r_k)} w_e |(p'_i - p'_j) - R_k (p_i - p_j)|^2

so ``w_ke = w_e`` and ``N(k, r_k)`` comes from the compiled breadth-first search of
:mod:`arapkit.arap.rings`. r = 1 everywhere is Sorkine & Alexa's spokes ARAP. Each step
minimises E exactly over its block: a descent method.

Rings counted on another mesh (``ring_scale``)
-----------------------------------------------
A coarse mesh (the proxy of :mod:`arapkit.methods.multires`) stands for a finer one whose
edges are ``s`` times its own; the rigidity map is the fine mesh's. An r-ring's stiffness
against bending grows as the square of its radius (a rotation fitted over a patch of radius
``rho`` leaves a residual of order ``kappa rho^2`` per edge on a surface bent by curvature
``kappa``), so the coarse mesh takes ``r_c = max(1, rint(r s))`` rings, and where even one
of its rings is wider than the fine mesh's r-ring (``r s < 1``) the one-ring term is blended
with a membrane term that has no bending stiffness at all, a rotation per triangle (on a
point cloud's graph, which has none, a rotation per edge: a spring, which also resists
stretch and not bending):

    E = sum_k a_k E_k(N(k, 1)) + sum_t 2 (1 - a_t) sum_{e in t} w_te |e' - R_t e|^2,

with ``a_k = min(1, (r_k s)^2)``, ``a_t`` the mean over t's corners and ``w_te`` the share of
``w_e`` that t holds (in proportion to the clamped cotangent of t's angle opposite e, evenly
where both are 0). Where ``a`` is uniform the global matrix is the plain one-ring's,
``2 w_e`` per edge, and the stiffness against bending is the fine mesh's r-ring's. On the
437K scan under a 20K proxy (``s = 0.21``, ``a = 0.045``) the proxy's minimum lies within
0.43 % (p95) / 1.3 % (max) of the bounding-box diagonal of the full mesh's, against 1.7 % /
4.0 % with the plain one-ring (``docs/studies/interactive-at-scale.md``). Every step
still minimises E exactly over its block (the triangles' rotations are fitted as the
vertices' are), so the energy is a descent method's.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ...mesh.weights import corner_cotangents
from ...validate import MAX_RINGS, number
from ..ringcost import check_ring_memory
from ..rings import Neighbourhoods, edge_counts, neighbourhoods_from_arrays
from .base import NeighbourhoodEnergy, owner_rows, rest_term
from .table import EnergyInfo, register_energy

if TYPE_CHECKING:
    from ..graph import EdgeGraph

__all__ = ["check_ring_scale", "ring_blend", "rring_energy"]


def check_ring_scale(value) -> float:
    """A ring scale: a finite number > 0 (1 means the rings are this mesh's own).

    Examples
    --------
    >>> check_ring_scale("0.25")
    0.25
    """
    return number(value, "ring_scale", lo=0.0, lo_open=True)


def ring_blend(rings: np.ndarray, ring_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Rings counted on a mesh ``ring_scale`` times finer: (rings searched here, one-ring
    share ``a``); ``a < 1`` where one ring here is already stiffer than the r asked for.

    Examples
    --------
    >>> r, a = ring_blend(np.array([1, 2, 10]), 0.25)
    >>> r.tolist(), a.tolist()
    ([1, 1, 2], [0.0625, 0.25, 1.0])
    """
    reach = np.asarray(rings, dtype=np.float64) * ring_scale
    searched = np.clip(np.rint(reach), 1, MAX_RINGS).astype(np.int32)
    return searched, np.minimum(1.0, reach * reach)


def _face_shares(graph: EdgeGraph, w: np.ndarray) -> np.ndarray:
    """``w_te`` for each face edge ``(F[t, c], F[t, c + 1])``: the share of ``w_e`` that
    face t holds, by the clamped cotangent of its angle opposite e (evenly where all the
    edge's are 0). The shares of an edge sum to ``w_e``."""
    F, FE = graph.faces, graph.face_edges
    # corner c faces edge (c+1, c+2): face edge c = (c, c+1) faces corner c+2
    cot = np.maximum(np.roll(corner_cotangents(graph.vertices, F), 1, axis=1), 0.0)
    m = len(graph.edges)
    total = np.bincount(FE.ravel(), cot.ravel(), m)
    count = np.bincount(FE.ravel(), minlength=m)
    even = total[FE] <= 0.0
    share = np.where(even, 1.0 / np.maximum(count[FE], 1), cot / np.where(even, 1.0, total[FE]))
    return w[FE] * share


def _membrane(graph: EdgeGraph, w: np.ndarray, a: np.ndarray):
    """The membrane's owners: a rotation per triangle, each edge's weight shared by its
    triangles (``2 (1 - a_t) w_te``); on a graph without triangles (a point cloud's) a
    rotation per edge (``2 (1 - a_e) w_e``, ``a_e`` its ends' mean), a spring: like a
    triangle's, it resists stretch and not bending. Returns the owners' rows
    (:func:`owner_rows`) and each owner's lowest vertex."""
    E = graph.edges
    if graph.faces is None:
        membrane = 1.0 - a[E].mean(axis=1)
        order = np.argsort(E.min(axis=1), kind="stable")  # by lowest end, as triangles
        order = order[membrane[order] > 0.0]
        t = len(order)
        rows = owner_rows(graph.vertices, E, t, np.arange(t), order,
                          2.0 * membrane[order] * w[order])
        return rows, E[order].min(axis=1)
    F, FE = graph.faces, graph.face_edges
    membrane = 1.0 - a[F].mean(axis=1)
    # triangles by their lowest corner: a chunk of them scatters into a narrow window of
    # the bandwidth-ordered vertices (the CPU backend's layout)
    order = np.argsort(F.min(axis=1), kind="stable")
    order = order[membrane[order] > 0.0]
    t = len(order)
    coef = (2.0 * membrane[order, None] * _face_shares(graph, w)[order]).ravel()
    rows = owner_rows(graph.vertices, E, t, np.repeat(np.arange(t), 3), FE[order].ravel(),
                      coef)
    return rows, F[order].min(axis=1)


def _blended(graph: EdgeGraph, w: np.ndarray, nbh: Neighbourhoods, a: np.ndarray,
             rings: np.ndarray, options: dict) -> NeighbourhoodEnergy:
    """The vertices' rings weighted by ``a``, and the membrane (:func:`_membrane`) for the
    rest."""
    E = graph.edges
    sizes = np.diff(nbh.edge_ptr)
    entry_w = np.repeat(a, sizes) * w[nbh.edge_idx]
    disk_coef = nbh.disk_coef  # scaled in place: the fresh structure is this energy's own
    disk_coef *= np.repeat(a, np.diff(nbh.disk_ptr))[:, None]
    (fe_ptr, fe_idx, fe_w, fd_ptr, fd_idx, fd_coef), lowest = _membrane(graph, w, a)
    edge_idx = np.concatenate([nbh.edge_idx, fe_idx])
    entry_w = np.concatenate([entry_w, fe_w])
    system_w = np.bincount(edge_idx, entry_w, len(E))
    both = Neighbourhoods(
        rings=rings,
        edge_ptr=np.concatenate([nbh.edge_ptr, nbh.edge_ptr[-1] + fe_ptr[1:]]),
        edge_idx=edge_idx,
        edge_layer=np.concatenate([nbh.edge_layer, np.ones(len(fe_idx), dtype=np.int8)]),
        disk_ptr=np.concatenate([nbh.disk_ptr, nbh.disk_ptr[-1] + fd_ptr[1:]]),
        disk_idx=np.concatenate([nbh.disk_idx, fd_idx]),
        disk_coef=np.ascontiguousarray(np.concatenate([disk_coef, fd_coef])),
        edge_count=edge_counts(edge_idx, len(E)),
    )
    centres = lowest.astype(np.int32)
    return NeighbourhoodEnergy("rring", both, entry_w, system_w, rest_term(graph, system_w),
                               options=options, centres=centres)


def rring_energy(graph: EdgeGraph, w: np.ndarray, rings,
                 ring_scale: float = 1.0) -> NeighbourhoodEnergy:
    """r-ring ARAP's structure: ``N(k, r_k)``, ``w_ke = w_e``.

    ``rings`` is in the graph's numbering (already checked). With ``ring_scale`` (the fine
    mesh's edge length over this one's) r is counted on that finer mesh (see the module's
    docstring); ``rings`` stays the map as given.

    Examples
    --------
    >>> from arapkit.arap.graph import EdgeGraph
    >>> g = EdgeGraph(np.eye(3), np.array([[0, 1], [1, 2]]))
    >>> rring_energy(g, np.ones(2), np.ones(3, dtype=np.int32)).system_w.tolist()
    [2.0, 2.0]
    """
    options = {} if ring_scale == 1.0 else {"ring_scale": ring_scale}
    searched, a = ring_blend(rings, ring_scale)
    # estimated, and refused where it would not fit, before anything is built; a refusal
    # names the caller's r (not the rings searched here)
    cost = check_ring_memory(graph.n_vertices, graph.edges, rings, graph.name,
                             depth_of=lambda r: ring_blend(r, ring_scale)[0],
                             blended=bool((a < 1.0).any()))
    nbh = neighbourhoods_from_arrays(graph.n_vertices, graph.edges, graph.vertices, w,
                                     searched, cost=cost)
    nbh.rings = np.asarray(rings, dtype=np.int32)
    if (a < 1.0).any():
        return _blended(graph, w, nbh, a, nbh.rings, options)
    dw = nbh.edge_count * w
    return NeighbourhoodEnergy("rring", nbh, None, dw, rest_term(graph, dw), options=options)


def _build(graph, w, weights_kind, rings, perm, ring_scale=1.0):
    return rring_energy(graph, w, rings, check_ring_scale(ring_scale))


def _faces_for(options: dict) -> bool:
    """Triangles are read only where a ring scale below 1 may blend in their membrane."""
    return check_ring_scale(options.get("ring_scale", 1.0)) < 1.0


register_energy(EnergyInfo("rring", _build, descent=True, rigidity_map=True,
                           needs_faces=_faces_for, options=("ring_scale",),
                           without_faces=True))
