"""r-ring ARAP (Chen et al. 2017, eq. 1): the neighbourhood of k is every edge within r_k rings.

    E(p', R) = sum_k sum_{e in N(k, r_k)} w_e |(p'_i - p'_j) - R_k (p_i - p_j)|^2

so ``w_ke = w_e`` and ``N(k, r_k)`` comes from the compiled breadth-first search of
:mod:`arapkit.arap.rings`. r = 1 everywhere is Sorkine & Alexa's spokes ARAP. Each step
minimises E exactly over its block: a descent method.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..rings import neighbourhoods_from_arrays
from .base import NeighbourhoodEnergy, rest_term
from .table import EnergyInfo, register_energy

if TYPE_CHECKING:
    from ..graph import EdgeGraph

__all__ = ["rring_energy"]


def rring_energy(graph: EdgeGraph, w: np.ndarray, rings) -> NeighbourhoodEnergy:
    """r-ring ARAP's structure: ``N(k, r_k)``, ``w_ke = w_e``.

    ``rings`` is in the graph's numbering (already checked).

    Examples
    --------
    >>> from arapkit.arap.graph import EdgeGraph
    >>> g = EdgeGraph(np.eye(3), np.array([[0, 1], [1, 2]]))
    >>> rring_energy(g, np.ones(2), np.ones(3, dtype=np.int32)).system_w.tolist()
    [2.0, 2.0]
    """
    nbh = neighbourhoods_from_arrays(graph.n_vertices, graph.edges, graph.vertices, w, rings)
    dw = nbh.edge_count * w
    return NeighbourhoodEnergy("rring", nbh, None, dw, rest_term(graph, dw))


register_energy(EnergyInfo(
    "rring", lambda graph, w, weights_kind, rings, perm: rring_energy(graph, w, rings),
    descent=True, rigidity_map=True))
