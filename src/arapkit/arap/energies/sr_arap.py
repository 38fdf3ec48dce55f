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

A region of interest (``roi``) poses CGAL's problem for a partial ROI. CGAL solves only the
ROI plus its one-ring (the ring held fixed at rest) and keeps rotations only on those
vertices, so a rotation is coupled only to neighbours in that region; its ``1 / deg k``
still counts every neighbour. Positions and the spokes terms are the same whether the
vertices outside the ROI are held fixed inside the problem (arapkit) or left out (CGAL):
a free vertex only sees its neighbours' rotations, and those see only their neighbours'
positions. Only the coupling differs, so ``roi`` keeps the term ``|R_k - R_j|^2`` of the
directed pair (k, j) only when k and j both lie in the ROI or on its one-ring.
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

__all__ = ["DEFAULT_ALPHA", "check_alpha", "check_roi", "sr_arap_energy", "surface_area"]

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


def check_roi(roi, n: int) -> np.ndarray:
    """A region of interest given as vertex ids, as a boolean mask over ``n`` vertices.

    Examples
    --------
    >>> check_roi([0, 2], 4).tolist()
    [True, False, True, False]
    """
    try:
        ids = np.asarray(roi)
        ok = ids.ndim == 1 and len(ids) > 0 and np.issubdtype(ids.dtype, np.integer)
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError("sr_roi must be a non-empty list of vertex ids (integers)")
    bad = ids[(ids < 0) | (ids >= n)]
    if len(bad):
        raise InputError(f"sr_roi: vertex {int(bad[0])} is out of range (the mesh has {n} "
                         "vertices)")
    mask = np.zeros(n, dtype=bool)
    mask[ids] = True
    return mask


def surface_area(graph: EdgeGraph) -> float:
    """Total area of the graph's triangles."""
    V, F = graph.vertices, graph.faces
    return float(0.5 * np.linalg.norm(
        np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum())


def sr_arap_energy(graph: EdgeGraph, w: np.ndarray, alpha: float = DEFAULT_ALPHA,
                   roi: np.ndarray | None = None) -> NeighbourhoodEnergy:
    """SR-ARAP's structure: spokes neighbourhoods plus the rotation coupling.

    ``roi``: boolean mask (the graph's numbering) of CGAL's region of interest; None for
    the whole mesh. See the module's docstring.
    """
    alpha = check_alpha(alpha)
    n = graph.n_vertices
    base = rring_energy(graph, w, np.ones(n, dtype=np.int32))
    adj = graph.adjacency.tocsr()
    adj.sort_indices()
    deg = np.diff(adj.indptr)
    coef = alpha * surface_area(graph) / np.maximum(deg, 1)
    k = np.repeat(np.arange(n), deg)
    j = adj.indices.astype(np.int64)
    rc_w = coef[k].astype(np.float64)
    if roi is not None:
        # CGAL's region of solution: the ROI and its one-ring
        solved = roi | (adj @ roi.astype(np.float64) > 0)
        keep = solved[k] & solved[j]
        k, j, rc_w = k[keep], j[keep], rc_w[keep]
    indptr = np.concatenate([[0], np.cumsum(np.bincount(k, minlength=n))]).astype(np.int64)
    coupling = (indptr, j, rc_w)
    # |R_k - R_j|^2 = 6 - 2 tr(R_k R_j^T): the kernel's trace carries the second part
    rest = base.rest_term + 6.0 * float(rc_w.sum())
    return replace(base, name="sr-arap", rest_term=rest, coupling=coupling,
                   options={"alpha": alpha} if roi is None else
                   {"alpha": alpha, "roi_vertices": int(roi.sum())})


def _build(graph: EdgeGraph, w: np.ndarray, weights_kind, rings, perm: np.ndarray | None,
           alpha: float = DEFAULT_ALPHA, roi=None) -> NeighbourhoodEnergy:
    """The table's builder: ``roi`` given as vertex ids in the caller's numbering."""
    if roi is not None:
        roi = check_roi(roi, graph.n_vertices)
        roi = roi if perm is None else roi[perm]
    return sr_arap_energy(graph, w, alpha, roi)


# the Jacobi sweep over the coupling is not a descent step (see the module docstring)
register_energy(EnergyInfo("sr-arap", _build, descent=False, needs_faces=True,
                           options=("alpha", "roi")))
