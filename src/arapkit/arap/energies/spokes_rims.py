"""Spokes-and-rims ARAP (Chao et al. 2010; libigl ``ARAP_ENERGY_TYPE_SPOKES_AND_RIMS``).

The rotation of vertex k is fitted to every edge of every triangle around k: its spokes
(edges at k) and its rims (the opposite edges). As in libigl and CGAL, each triangle t
contributes its three edges to the neighbourhoods of its three corners,

    E = sum_t sum_{k in t} sum_{e in t} c_te |(p'_i - p'_j) - R_k (p_i - p_j)|^2,

with ``c_te = cot(angle of t opposite e) / 2`` for ``weights="cotan"`` (libigl's
``cotmatrix_entries`` and CGAL's ``SPOKES_AND_RIMS``, which does not clamp; an interior
edge's two halves add up to its cotangent weight), ``max(cot, 0) / 2`` for
``weights="cotan-clamped-each"``.
For any other weighting the edge weight ``w_e`` is split evenly between the edge's
triangles, so ``uniform`` gives ``c_te = 1/2`` on an interior edge.

Each local and global step minimises E exactly over its block, so E never rises.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ...mesh.weights import corner_cotangents
from .base import NeighbourhoodEnergy, energy_from_entries
from .table import EnergyInfo, register_energy

if TYPE_CHECKING:
    from ..graph import EdgeGraph

__all__ = ["face_edge_weights", "spokes_and_rims_energy"]


def face_edge_weights(graph: EdgeGraph, w: np.ndarray, weights_kind: str | None) -> np.ndarray:
    """``c_te`` for each face edge ``(F[t, c], F[t, c + 1])``, shape (f, 3).

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit import Mesh
    >>> from arapkit.arap.graph import EdgeGraph
    >>> g = EdgeGraph.from_mesh(Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]))
    >>> np.round(face_edge_weights(g, None, "cotan"), 6).tolist()  # edge (1,2) faces 90 deg
    [[0.5, 0.0, 0.5]]
    """
    F, FE = graph.faces, graph.face_edges
    if weights_kind in ("cotan", "cotan-clamped-each"):
        cots = corner_cotangents(graph.vertices, F)
        if weights_kind == "cotan-clamped-each":
            cots = np.maximum(cots, 0.0)
        # corner c faces edge (c+1, c+2): face edge c = (c, c+1) faces corner c+2
        return 0.5 * np.roll(cots, 1, axis=1)
    faces_per_edge = np.bincount(FE.ravel(), minlength=len(graph.edges))
    return w[FE] / faces_per_edge[FE]


def spokes_and_rims_energy(graph: EdgeGraph, w: np.ndarray,
                           weights_kind: str | None) -> NeighbourhoodEnergy:
    """The spokes-and-rims energy's structure on a triangle mesh's edge graph."""
    F, FE = graph.faces, graph.face_edges
    C = face_edge_weights(graph, w, weights_kind)
    # every corner k of face t takes all three edges of t
    k = np.repeat(F, 3, axis=1).ravel()          # (t, corner, edge) -> corner vertex
    e = np.tile(FE, (1, 3)).ravel()              # ... -> edge id
    c = np.tile(C, (1, 3)).ravel()
    return energy_from_entries("spokes-and-rims", graph, k, e, c)


register_energy(EnergyInfo(
    "spokes-and-rims",
    lambda graph, w, weights_kind, rings, perm: spokes_and_rims_energy(graph, w, weights_kind),
    descent=True, needs_faces=True))
