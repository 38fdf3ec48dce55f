"""Laplacian surface editing (differential coordinates), hard or soft constraints.

Minimises ``sum_i |L(q)_i - L(p)_i|^2`` over the deformed positions q, where L is the
uniform Laplacian ``q_i - mean of neighbours`` or the cotangent Laplacian
``(1/A_i) sum_j w_ij (q_i - q_j)`` (A_i the mixed Voronoi area), subject to

* hard constraints ``q_c = c`` (the handles are eliminated), or
* soft constraints ``+ omega^2 sum_c |q_c - c|^2`` (lecture notes: rows ``omega q_c = omega c``).

The normal equations ``L^T L`` are factorised once per handle set and reused for any targets.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..arap.constraints import Elimination, anchor_components, check_handles, check_targets
from ..errors import InputError
from ..mesh.model import Mesh, as_mesh
from ..mesh.weights import DEFAULT_WEIGHTS, edge_weights, voronoi_areas
from .registry import MethodInfo, register

__all__ = ["LaplacianEditor", "laplacian_edit", "differential_operator"]

# one linear solve, no iterations: the library offers it as its own class (LaplacianEditor,
# not through Deformer), the editor as a solver-panel method
# its operator reads Voronoi areas and cotangents of triangles
register(MethodInfo("laplacian", "Laplacian editing", local_global=False, descent=True,
                    interfaces=frozenset({"editor"}), needs_faces=True,
                    why_not={"torch": "it is not a local/global energy"}))


def differential_operator(mesh: Mesh, weights: str = DEFAULT_WEIGHTS) -> sp.csr_matrix:
    """The matrix L with ``L p = delta`` (differential coordinates).

    Rows of vertices without neighbours are zero.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> L = differential_operator(bar(), "uniform")
    >>> bool(abs(L.sum(axis=1)).max() < 1e-12)
    True
    """
    n = mesh.n_vertices
    E = mesh.edges
    w = edge_weights(mesh, weights)
    W = sp.coo_matrix((np.concatenate([w, w]), (np.concatenate([E[:, 0], E[:, 1]]),
                                               np.concatenate([E[:, 1], E[:, 0]]))),
                      shape=(n, n)).tocsr()
    deg = np.asarray(W.sum(axis=1)).ravel()
    if weights == "uniform":
        scale = np.divide(1.0, deg, out=np.zeros(n), where=deg != 0)
    else:
        area = voronoi_areas(mesh)
        scale = np.divide(1.0, area, out=np.zeros(n), where=area > 0)
    return (sp.diags(scale) @ (sp.diags(deg) - W)).tocsr()


class LaplacianEditor:
    """Factor-once Laplacian editing.

    Parameters
    ----------
    mesh : Mesh
    handles : (h,) int
    weights : {"cotan", "cotan-clamped", "cotan-clamped-each", "uniform"}
    omega : float, optional
        Soft-constraint weight; ``None`` (default) means hard constraints.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar, bar_bend
    >>> m = bar()
    >>> h, t = bar_bend(m, 90)
    >>> V = LaplacianEditor(m, h, "uniform").solve(t)
    >>> bool(abs(V[h] - t).max() < 1e-12)
    True
    """

    def __init__(self, mesh: Mesh, handles, weights: str = DEFAULT_WEIGHTS,
                 omega: float | None = None) -> None:
        self.mesh = mesh = as_mesh(mesh)
        self.handles = check_handles(mesh, handles)
        if omega is not None and not (np.isfinite(omega) and omega > 0):
            raise InputError(f"omega must be a positive number, got {omega}")
        self.omega = omega
        L = differential_operator(mesh, weights)
        self.delta = L @ mesh.vertices
        self._Lt = L.T.tocsr()
        Q = (self._Lt @ L).tocsr()
        extra, self.notes = anchor_components(mesh, self.handles, "fix")
        self._extra = extra
        hard = extra if omega is not None else np.concatenate([self.handles, extra])
        self._hard = hard
        if omega is not None:
            Q = Q + sp.coo_matrix((np.full(len(self.handles), omega**2),
                                   (self.handles, self.handles)), shape=Q.shape)
        el = Elimination.from_matrix(Q, hard, mesh.name)
        self._free = el.free
        self._Q_fc = el.A_fc
        self._factor = el.factor

    def solve(self, targets) -> np.ndarray:
        """Deformed positions for the given handle targets (h, 3)."""
        T = check_targets(self.handles, targets)
        n = self.mesh.n_vertices
        q = self.mesh.vertices.copy()
        rhs = self._Lt @ self.delta
        if self.omega is not None:
            rhs[self.handles] += self.omega**2 * T
        else:
            q[self.handles] = T
        q[self._extra] = self.mesh.vertices[self._extra]
        if self._factor is not None:
            rhs_f = rhs[self._free] - self._Q_fc @ q[self._hard]
            q[self._free] = self._factor.solve(rhs_f)
        assert q.shape == (n, 3)
        return q


def laplacian_edit(mesh: Mesh, handles, targets, weights: str = DEFAULT_WEIGHTS,
                   omega: float | None = None) -> np.ndarray:
    """One-shot Laplacian surface editing; see :class:`LaplacianEditor`.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar, bar_bend
    >>> m = bar()
    >>> h, t = bar_bend(m, 45)
    >>> laplacian_edit(m, h, t, omega=10.0).shape
    (1154, 3)
    """
    return LaplacianEditor(mesh, handles, weights, omega).solve(targets)
