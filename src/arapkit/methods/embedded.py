"""Embedded deformation (Sumner, Schmid & Pauly 2007) on a graph sampled on the surface.

A deformation graph of nodes ``g_j`` (vertices picked by farthest-point sampling) carries
an affine map per node, ``x -> A_j (x - g_j) + g_j + t_j``. Each vertex follows its ``k``
nearest nodes,

    v' = sum_j w_j(v) [A_j (v - g_j) + g_j + t_j],
    w_j(v) = (1 - |v - g_j| / d_max)^2, normalised,

with ``d_max`` the distance to the (k+1)-th nearest node (the paper, k = 4). The unknowns
minimise the paper's energy

    w_rot E_rot + w_reg E_reg + w_con E_con,                    (1, 10, 100)

* ``E_rot = sum_j (c1.c2)^2 + (c1.c3)^2 + (c2.c3)^2 + (c1.c1 - 1)^2 + (c2.c2 - 1)^2
  + (c3.c3 - 1)^2`` over the columns of ``A_j`` (how far each map is from a rotation);
* ``E_reg = sum_j sum_{l ~ j} |A_j (g_l - g_j) + g_j + t_j - (g_l + t_l)|^2`` over graph
  edges (nodes that influence a common vertex);
* ``E_con = sum_handles |v'_h - q_h|^2``: soft constraints, as in the paper.

Lengths are measured in units of the mean graph-edge length, so that the paper's weights
mean the same on any mesh scale. The solver is Gauss-Newton on the 12 unknowns per node,
with a sparse Cholesky factor of ``J^T J + mu D`` per iteration (``mu`` a Levenberg-
Marquardt damping that grows until a step lowers the energy), so the energy never rises.
Handles are met to the soft-constraint residual (reported as ``max_handle_error``).
"""

from __future__ import annotations

import copy
import time

import numpy as np
import scipy.sparse as sp

from ..arap.constraints import CholeskyFactor, check_handles, check_targets
from ..arap.loop import Result
from ..errors import InputError
from ..mesh.model import Mesh
from ..validate import iteration_cap, tolerance
from .registry import MethodInfo, MethodOption, register

__all__ = ["DEFAULT_NODES", "EmbeddedDeformation", "check_nodes", "sample_nodes"]

#: default graph size (clamped to the number of vertices)
DEFAULT_NODES = 200

#: nearest nodes per vertex (the paper's k = 4)
K_NEAREST = 4
#: the paper's weights
W_ROT, W_REG, W_CON = 1.0, 10.0, 100.0


def check_nodes(nodes) -> int:
    """A node count >= 2, or a one-line error.

    Examples
    --------
    >>> check_nodes("50")
    50
    """
    try:
        k = int(nodes)
        ok = float(nodes) == k
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(f"nodes must be an integer, got {nodes!r}")
    if k < 2:
        raise InputError(f"nodes must be at least 2, got {k}")
    return k


# Gauss-Newton with a step control that refuses a rising step: a descent method. Handles are
# soft (weight W_CON): 2 % of the bounding-box diagonal is the bound its tests hold on every
# mesh (docs/methods.md)
register(MethodInfo(
    "embedded", "embedded deformation", local_global=False, descent=True, handle_tol=2e-2,
    options={"nodes": MethodOption("nodes", DEFAULT_NODES, check_nodes, "{} nodes")},
    interfaces=frozenset({"library", "cli", "compare", "batch", "editor"}),
    why_not={"torch": "it is not a local/global energy"}))


def sample_nodes(V: np.ndarray, count: int, seed_vertex: int = 0) -> np.ndarray:
    """Farthest-point sample of ``count`` vertex ids (deterministic).

    Examples
    --------
    >>> import numpy as np
    >>> sample_nodes(np.array([[0.0, 0, 0], [1, 0, 0], [0.1, 0, 0], [2, 0, 0]]), 2).tolist()
    [0, 3]
    """
    count = min(count, len(V))
    chosen = np.empty(count, dtype=np.int64)
    chosen[0] = seed_vertex
    d = np.sum((V - V[seed_vertex]) ** 2, axis=1)
    for i in range(1, count):
        chosen[i] = int(np.argmax(d))
        d = np.minimum(d, np.sum((V - V[chosen[i]]) ** 2, axis=1))
    return chosen


def _nearest(V: np.ndarray, G: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Ids of each vertex's k nearest nodes and their normalised weights."""
    from scipy.spatial import cKDTree

    kk = min(k + 1, len(G))
    dist, idx = cKDTree(G).query(V, k=kk)
    dist, idx = np.atleast_2d(dist), np.atleast_2d(idx)
    if kk == k + 1:
        dmax = dist[:, -1:]
        dist, idx = dist[:, :-1], idx[:, :-1]
    else:  # fewer nodes than k + 1: the farthest node still gets some weight
        dmax = 1.0001 * dist[:, -1:] + 1e-300
    w = (1.0 - dist / np.maximum(dmax, 1e-300)) ** 2
    s = w.sum(axis=1, keepdims=True)
    # a vertex equidistant from all its nodes' (k+1)-th: spread evenly
    w = np.where(s > 0, w / np.where(s > 0, s, 1.0), 1.0 / w.shape[1])
    return idx.astype(np.int64), w


class EmbeddedDeformation:
    """Embedded deformation of a mesh with handles (see the module docstring).

    Parameters
    ----------
    mesh : Mesh
    handles : (h,) int
    nodes : int
        Deformation-graph size (default :data:`DEFAULT_NODES`, at most the vertex count).
    tol : float
        Stop when the relative energy decrease of a Gauss-Newton step is below this.
    max_iter : int
        Gauss-Newton iteration cap.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar, bar_bend
    >>> m = bar()
    >>> h, t = bar_bend(m, 60)
    >>> res = EmbeddedDeformation(m, h, nodes=60).solve(t)
    >>> bool(res.converged), res.vertices.shape
    (True, (1154, 3))
    """

    def __init__(self, mesh: Mesh, handles, nodes: int | None = None, *, tol: float = 1e-6,
                 max_iter: int = 100) -> None:
        t0 = time.perf_counter()
        self.mesh = mesh
        self.handles = check_handles(mesh, handles)
        self.tol = tolerance(tol)
        self.max_iter = iteration_cap(max_iter)
        V = mesh.vertices
        count = DEFAULT_NODES if nodes is None else check_nodes(nodes)
        self.node_ids = sample_nodes(V, min(count, mesh.n_vertices))
        self.nodes = V[self.node_ids]
        m = len(self.nodes)
        k = min(K_NEAREST, m)
        self.knn, self.knn_w = _nearest(V, self.nodes, k)
        # graph edges: nodes that influence a common vertex
        a = np.repeat(self.knn, k, axis=1).ravel()
        b = np.tile(self.knn, (1, k)).ravel()
        keep = a < b
        key = np.unique(a[keep] * m + b[keep])
        self.graph_edges = np.stack([key // m, key % m], axis=1)
        if len(self.graph_edges):
            L = np.linalg.norm(self.nodes[self.graph_edges[:, 0]]
                               - self.nodes[self.graph_edges[:, 1]], axis=1)
            self.unit = float(L.mean())
        else:
            self.unit = max(mesh.bounding_box_diagonal, 1e-300)
        self.timings = {"setup_ms": 1e3 * (time.perf_counter() - t0)}
        self._J_lin = None

    # -- the linear residuals (regularisation and constraints) --------------------------
    def _linear_jacobian(self) -> sp.csr_matrix:
        """Jacobian of the regularisation and constraint residuals (constant)."""
        if self._J_lin is not None:
            return self._J_lin
        G = self.nodes / self.unit
        m = len(G)
        rows, cols, vals = [], [], []
        r = 0
        # regularisation, both directions of every graph edge, sqrt(w_reg) times
        s = np.sqrt(W_REG)
        E = np.concatenate([self.graph_edges, self.graph_edges[:, ::-1]])
        d = G[E[:, 1]] - G[E[:, 0]]  # g_l - g_j
        ne = len(E)
        for a in range(3):  # residual component a
            rr = r + 3 * np.arange(ne) + a
            for c in range(3):  # A_j[a, c] * d[c]
                rows.append(rr)
                cols.append(12 * E[:, 0] + 3 * a + c)
                vals.append(s * d[:, c])
            rows += [rr, rr]
            cols += [12 * E[:, 0] + 9 + a, 12 * E[:, 1] + 9 + a]
            vals += [np.full(ne, s), np.full(ne, -s)]
        r += 3 * ne
        # constraints: v'_h = sum_j w [A_j (v - g_j) + g_j + t_j]
        s = np.sqrt(W_CON)
        h = self.handles
        nh = len(h)
        P = self.mesh.vertices[h] / self.unit
        for q in range(self.knn.shape[1]):
            j = self.knn[h, q]
            w = self.knn_w[h, q]
            d = P - G[j]
            for a in range(3):
                rr = r + 3 * np.arange(nh) + a
                for c in range(3):
                    rows.append(rr)
                    cols.append(12 * j + 3 * a + c)
                    vals.append(s * w * d[:, c])
                rows.append(rr)
                cols.append(12 * j + 9 + a)
                vals.append(s * w)
        r += 3 * nh
        J = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(r, 12 * m))
        self._J_lin = J
        self._n_reg = 3 * ne
        return J

    def _linear_rhs(self, T: np.ndarray) -> np.ndarray:
        """Constant part c of the linear residuals r = J_lin x + c."""
        G = self.nodes / self.unit
        E = np.concatenate([self.graph_edges, self.graph_edges[:, ::-1]])
        reg = np.sqrt(W_REG) * (G[E[:, 0]] - G[E[:, 1]])
        h = self.handles
        base = np.zeros((len(h), 3))
        for q in range(self.knn.shape[1]):
            base += self.knn_w[h, q, None] * G[self.knn[h, q]]
        con = np.sqrt(W_CON) * (base - T / self.unit)
        return np.concatenate([reg.ravel(), con.ravel()])

    # -- the rotation residuals ---------------------------------------------------------
    @staticmethod
    def _rot(X: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix]:
        """Residuals (6 per node) and Jacobian of E_rot at X (m, 12)."""
        m = len(X)
        A = X[:, :9].reshape(m, 3, 3)
        c = [A[:, :, i] for i in range(3)]  # columns
        pairs = [(0, 1), (0, 2), (1, 2)]
        res = [np.einsum("ij,ij->i", c[p], c[q]) for p, q in pairs]
        res += [np.einsum("ij,ij->i", c[i], c[i]) - 1.0 for i in range(3)]
        s = np.sqrt(W_ROT)
        res = s * np.stack(res, axis=1)
        rows, cols, vals = [], [], []
        base = 12 * np.arange(m)
        for t, (p, q) in enumerate(pairs):
            for a in range(3):  # d(c_p . c_q) / dA[a, p] = A[a, q]
                rows += [6 * np.arange(m) + t] * 2
                cols += [base + 3 * a + p, base + 3 * a + q]
                vals += [s * A[:, a, q], s * A[:, a, p]]
        for i in range(3):
            for a in range(3):
                rows.append(6 * np.arange(m) + 3 + i)
                cols.append(base + 3 * a + i)
                vals.append(2 * s * A[:, a, i])
        J = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(6 * m, 12 * m))
        return res.ravel(), J

    def _energy_parts(self, X: np.ndarray, J_lin, c_lin) -> tuple[float, float, float]:
        r_lin = J_lin @ X.ravel() + c_lin
        r_rot, _ = self._rot(X)
        nreg = self._n_reg
        return (float(r_rot @ r_rot), float(r_lin[:nreg] @ r_lin[:nreg]),
                float(r_lin[nreg:] @ r_lin[nreg:]))

    # -- solve --------------------------------------------------------------------------
    def deformed(self, X: np.ndarray) -> np.ndarray:
        """Vertex positions for node maps X (m, 12) (in the mesh's units)."""
        V = self.mesh.vertices / self.unit
        G = self.nodes / self.unit
        out = np.zeros_like(V)
        for q in range(self.knn.shape[1]):
            j = self.knn[:, q]
            A = X[j, :9].reshape(-1, 3, 3)
            out += self.knn_w[:, q, None] * (
                np.einsum("nab,nb->na", A, V - G[j]) + G[j] + X[j, 9:])
        return out * self.unit

    def fit_node_maps(self, positions) -> np.ndarray:
        """Node maps X (m, 12) that put every vertex at ``positions``, as the method would.

        Positions alone leave the maps underdetermined (a node's vertices may lie on a
        surface patch), so the fit minimises the method's own energy with every vertex a
        soft handle at its position: ``w_rot E_rot + w_reg E_reg + w_con sum_v |v' -
        p_v|^2``, by the same Gauss-Newton solve from identity maps. A rigid image of the
        rest shape gives that rigid motion's maps (energy 0), the rest shape the identity;
        the shape this object last produced gives back its maps unchanged.

        Examples
        --------
        >>> from arapkit.mesh.shapes import bar
        >>> m = bar(length=2.0, segments=(8, 2, 2))
        >>> ed = EmbeddedDeformation(m, [0], nodes=10)
        >>> X = ed.fit_node_maps(m.vertices + [0.0, 1.0, 0.0])
        >>> bool(np.abs(ed.deformed(X) - (m.vertices + [0.0, 1.0, 0.0])).max() < 1e-9)
        True
        """
        P = np.asarray(positions, dtype=np.float64)
        if P.shape != self.mesh.vertices.shape or not np.isfinite(P).all():
            raise InputError(f"init: expected finite positions of shape "
                             f"{self.mesh.vertices.shape} (or node maps of shape "
                             f"({len(self.nodes)}, 12))")
        last = getattr(self, "node_maps", None)
        if last is not None and np.array_equal(self.deformed(last), P):
            return last.copy()  # a warm start from the previous result: its own maps
        fit = copy.copy(self)  # same graph and skinning, every vertex a handle
        fit.handles = np.arange(self.mesh.n_vertices)
        fit._J_lin = None
        fit.solve(P)
        return fit.node_maps

    def _start(self, init) -> np.ndarray:
        """Node maps to start from: identity, given node maps, or fitted to positions."""
        m = len(self.nodes)
        if init is None:
            X = np.zeros((m, 12))
            X[:, :9] = np.eye(3).ravel()
            return X
        X = np.asarray(init, dtype=np.float64)
        if X.shape == (m, 12) and np.isfinite(X).all():
            return X.copy()
        return self.fit_node_maps(X)

    def solve(self, targets, init=None, tol: float | None = None, max_iter: int | None = None,
              callback=None, accelerate=None) -> Result:
        """Deform so that the handles approach ``targets`` (soft constraints, weight 100).

        ``init`` is None (identity maps), node maps (m, 12) such as a previous solve's
        ``node_maps``, or vertex positions (n, 3), e.g. a previous result: the node maps
        are then fitted to them (:meth:`fit_node_maps`). ``accelerate`` is accepted for
        interface compatibility and ignored.
        """
        t_start = time.perf_counter()
        T = check_targets(self.handles, targets)
        tol = self.tol if tol is None else tolerance(tol)
        max_iter = self.max_iter if max_iter is None else iteration_cap(max_iter)
        m = len(self.nodes)
        X = self._start(init)
        J_lin = self._linear_jacobian()
        c_lin = self._linear_rhs(T)
        JtJ_lin = (J_lin.T @ J_lin).tocsr()
        parts = self._energy_parts(X, J_lin, c_lin)
        E = sum(parts)
        hist: list[float] = []
        converged = False
        mu = 1e-6
        it = 0
        t_fact = 0.0
        floor = 1e-28 * max(1.0, len(self.handles))
        for it in range(1, max_iter + 1):
            r_rot, J_rot = self._rot(X)
            r_lin = J_lin @ X.ravel() + c_lin
            g = J_lin.T @ r_lin + J_rot.T @ r_rot
            H = (JtJ_lin + J_rot.T @ J_rot).tocsr()
            diag = H.diagonal()
            while True:
                t0 = time.perf_counter()
                A = H + sp.diags(mu * np.maximum(diag, 1e-12))
                step = -CholeskyFactor(A, self.mesh.name).solve(g)
                t_fact += time.perf_counter() - t0
                X_new = X + step.reshape(m, 12)
                parts_new = self._energy_parts(X_new, J_lin, c_lin)
                E_new = sum(parts_new)
                if E_new <= E or mu > 1e12:
                    break
                mu *= 10.0  # Levenberg-Marquardt: a shorter, steeper step
            if E_new > E:  # no descent possible at this precision: stop where we are
                converged = True
                hist.append(E * self.unit**2)
                break
            dec = (E - E_new) / max(E, 1e-300)
            X, E, parts = X_new, E_new, parts_new
            mu = max(mu / 10.0, 1e-9)
            hist.append(E * self.unit**2)
            if E <= floor or dec < tol:
                converged = True
            if callback is not None and callback(it, hist[-1], self.deformed(X)):
                break
            if converged:
                break
        P = self.deformed(X)
        timings = {**self.timings, "factorisation_ms": 1e3 * t_fact,
                   "iterations": it, "total_s": time.perf_counter() - t_start,
                   "nodes": m,
                   "e_rot": parts[0], "e_reg": parts[1] * self.unit**2,
                   "e_con": parts[2] * self.unit**2}
        self.node_maps = X
        if not hist:
            hist = []
        energy = hist[-1] if hist else E * self.unit**2

        def vertex_energy() -> np.ndarray:
            return self._vertex_energy(X)

        return Result(P, energy, hist, it, converged, self._vertex_rotations(X), timings,
                      vertex_energy)

    def _node_energy(self, X: np.ndarray) -> np.ndarray:
        """Each node's rotation term plus half of its graph edges' regularisation terms."""
        m = len(X)
        r_rot, _ = self._rot(X)
        e = (r_rot.reshape(m, 6) ** 2).sum(axis=1)
        J_lin = self._linear_jacobian()
        G = self.nodes / self.unit
        E = np.concatenate([self.graph_edges, self.graph_edges[:, ::-1]])
        r = (J_lin[: self._n_reg] @ X.ravel()).reshape(-1, 3) + np.sqrt(W_REG) * (
            G[E[:, 0]] - G[E[:, 1]])
        e_reg = (r**2).sum(axis=1) * self.unit**2
        return e + np.bincount(E[:, 0], e_reg, m)

    def _vertex_energy(self, X: np.ndarray) -> np.ndarray:
        """Node energies spread to the vertices with the skinning weights."""
        en = self._node_energy(X)
        return (self.knn_w * en[self.knn]).sum(axis=1)

    def _vertex_rotations(self, X: np.ndarray) -> np.ndarray:
        """Nearest rotation to each vertex's blended linear map."""
        from ..arap.rotations import fit_rotations

        A = X[:, :9].reshape(-1, 3, 3)
        M = np.einsum("nq,nqab->nab", self.knn_w, A[self.knn])
        # the rotation nearest to M maximises tr(R M^T)
        return fit_rotations(np.ascontiguousarray(np.transpose(M, (0, 2, 1))))
