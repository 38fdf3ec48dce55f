"""Smooth-rotation ARAP, SR-ARAP (Levi & Gotsman 2014), with CGAL's conventions.

Spokes ARAP plus a term that pulls each rotation towards its neighbours':

    E = sum_k [ sum_{j~k} w_kj |(p'_k - p'_j) - R_k (p_k - p_j)|^2
                + (alpha A / deg k) sum_{j~k} |R_k - R_j|_F^2 ],

with A the total surface area (CGAL ``Surface_mesh_deformation<..., SRE_ARAP>``:
``cov += alpha * area * R_j^T / deg`` per neighbour; default alpha = 0.02). The area
factor makes alpha independent of the mesh's scale.

The global step is the spokes ARAP one (the new term does not involve positions). The
local step fits R_k with the neighbours' rotations of the previous iteration, a Jacobi
sweep (CGAL sweeps in vertex order, Gauss-Seidel); both have the same fixed points, so
converged results agree, but neither is a descent method for E: the reported energy (E
with the previous neighbour rotations) can rise between iterations, and Anderson
acceleration is not offered. alpha = 0 is spokes ARAP exactly.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ...errors import InputError
from .base import NeighbourhoodEnergy
from .rring import rring_energy
from .table import EnergyInfo, register_energy

if TYPE_CHECKING:
    from ..graph import EdgeGraph

__all__ = ["DEFAULT_ALPHA", "check_alpha", "sr_arap_energy", "surface_area"]

#: CGAL's default
DEFAULT_ALPHA = 0.02


def check_alpha(alpha) -> float:
    """A finite alpha >= 0, or a one-line error.

    Examples
    --------
    >>> check_alpha("0.5")
    0.5
    """
    try:
        a = float(alpha)
    except (TypeError, ValueError):
        raise InputError(f"sr_alpha must be a number, got {alpha!r}") from None
    if not math.isfinite(a) or a < 0:
        raise InputError(f"sr_alpha must be a finite number >= 0, got {alpha}")
    return a


def surface_area(graph: EdgeGraph) -> float:
    """Total area of the graph's triangles."""
    V, F = graph.vertices, graph.faces
    return float(0.5 * np.linalg.norm(
        np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum())


def sr_arap_energy(graph: EdgeGraph, w: np.ndarray, alpha: float = DEFAULT_ALPHA
                   ) -> NeighbourhoodEnergy:
    """SR-ARAP's structure: spokes neighbourhoods plus the rotation coupling."""
    alpha = check_alpha(alpha)
    n = graph.n_vertices
    base = rring_energy(graph, w, np.ones(n, dtype=np.int32))
    adj = graph.adjacency.tocsr()
    adj.sort_indices()
    deg = np.diff(adj.indptr)
    coef = alpha * surface_area(graph) / np.maximum(deg, 1)
    rc_w = np.repeat(coef, deg).astype(np.float64)
    coupling = (adj.indptr.astype(np.int64), adj.indices.astype(np.int64), rc_w)
    # |R_k - R_j|^2 = 6 - 2 tr(R_k R_j^T): the kernel's trace carries the second part
    rest = base.rest_term + 6.0 * float(rc_w.sum())
    return replace(base, name="sr-arap", rest_term=rest, coupling=coupling,
                   options={"alpha": alpha})


# the Jacobi sweep over the coupling is not a descent step (see the module docstring)
register_energy(EnergyInfo(
    "sr-arap",
    lambda graph, w, weights_kind, rings, alpha=DEFAULT_ALPHA: sr_arap_energy(graph, w, alpha),
    descent=False, needs_faces=True, options=("alpha",)))
