"""r-ring ARAP deformation: local/global iterations with one reused Cholesky factor.

Energy (Chen et al. 2017, eq. 1)::

    E(p', R) = sum_k sum_{e=(i,j) in N(k, r_k)} w_e |(p'_i - p'_j) - R_k (p_i - p_j)|^2

Global step (derived from eq. 1 itself; the paper's eq. 5 has a stray factor 2). Setting
dE/dp'_i = 0 gives, with d_e the number of neighbourhoods that contain edge e,

    sum_{j~i} d_ij w_ij (p'_i - p'_j) = sum_k R_k c_ki,

i.e. ``A p' = b`` with ``A`` the Laplacian of the edge weights ``d_e w_e``. For r = 1,
d_e = 2 and this is Sorkine & Alexa's ``sum_j w_ij (p'_i - p'_j) =
sum_j w_ij / 2 (R_i + R_j)(p_i - p_j)`` times 2. Handles (and vertices of components without
a handle) are eliminated, so the reduced matrix is symmetric positive definite; it is
factorised once per handle set and reused for every iteration and every new set of targets.

Local step: ``R_k = argmax_R tr(R S_k)`` with ``S_k = sum_e w_e e_e e'_e^T`` (see
:mod:`arapkit.rotations`). Each step minimises E exactly over its block of unknowns, so the
energy never increases.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field

import numba as nb
import numpy as np
import scipy.sparse as sp

from .errors import InputError
from .mesh import Mesh
from .rings import Neighbourhoods, build_neighbourhoods, check_rings
from .rotations import rotation_from_covariance
from .weights import edge_weights

__all__ = ["Deformer", "Result", "check_handles", "anchor_components", "laplacian_matrix"]

INITS = ("identity", "laplacian")


# -- compiled kernels ---------------------------------------------------------------


@nb.njit(parallel=True, cache=True)
def local_step(P, disk_ptr, disk_idx, disk_coef, R, trRS):
    """Fit every R_k to ``S_k = sum_v c_kv (p'_v - p'_k)^T``; store ``tr(R_k S_k)``.

    Subtracting p'_k is exact (the c_kv of a neighbourhood sum to zero) and keeps the sums
    well conditioned for meshes far from the origin.
    """
    n = P.shape[0]
    n_chunks = min(n, 8 * nb.get_num_threads())
    size = (n + n_chunks - 1) // n_chunks
    for c in nb.prange(n_chunks):
        S = np.empty((3, 3))
        for k in range(c * size, min(n, (c + 1) * size)):
            s00 = s01 = s02 = s10 = s11 = s12 = s20 = s21 = s22 = 0.0
            px, py, pz = P[k, 0], P[k, 1], P[k, 2]
            for t in range(disk_ptr[k], disk_ptr[k + 1]):
                v = disk_idx[t]
                dx, dy, dz = P[v, 0] - px, P[v, 1] - py, P[v, 2] - pz
                c0, c1, c2 = disk_coef[t, 0], disk_coef[t, 1], disk_coef[t, 2]
                s00 += c0 * dx
                s01 += c0 * dy
                s02 += c0 * dz
                s10 += c1 * dx
                s11 += c1 * dy
                s12 += c1 * dz
                s20 += c2 * dx
                s21 += c2 * dy
                s22 += c2 * dz
            S[0, 0], S[0, 1], S[0, 2] = s00, s01, s02
            S[1, 0], S[1, 1], S[1, 2] = s10, s11, s12
            S[2, 0], S[2, 1], S[2, 2] = s20, s21, s22
            Rk = R[k]
            rotation_from_covariance(S, Rk)
            tr = 0.0
            for a in range(3):
                for b in range(3):
                    tr += Rk[a, b] * S[b, a]
            trRS[k] = tr


@nb.njit(parallel=True, cache=True)
def rotated_rhs(R, vdisk_ptr, vdisk_k, vdisk_coef, b):
    """``b_v = sum_k R_k c_kv`` for every vertex (the global step's right-hand side)."""
    for v in nb.prange(b.shape[0]):
        b0 = b1 = b2 = 0.0
        for t in range(vdisk_ptr[v], vdisk_ptr[v + 1]):
            k = vdisk_k[t]
            c0, c1, c2 = vdisk_coef[t, 0], vdisk_coef[t, 1], vdisk_coef[t, 2]
            b0 += R[k, 0, 0] * c0 + R[k, 0, 1] * c1 + R[k, 0, 2] * c2
            b1 += R[k, 1, 0] * c0 + R[k, 1, 1] * c1 + R[k, 1, 2] * c2
            b2 += R[k, 2, 0] * c0 + R[k, 2, 1] * c1 + R[k, 2, 2] * c2
        b[v, 0] = b0
        b[v, 1] = b1
        b[v, 2] = b2


@nb.njit(parallel=True, cache=True)
def weighted_edge_norms(P, edges, dw):
    """``sum_e dw_e |p_i - p_j|^2``."""
    total = 0.0
    for e in nb.prange(edges.shape[0]):
        i, j = edges[e, 0], edges[e, 1]
        dx, dy, dz = P[i, 0] - P[j, 0], P[i, 1] - P[j, 1], P[i, 2] - P[j, 2]
        total += dw[e] * (dx * dx + dy * dy + dz * dz)
    return total


@nb.njit(parallel=True, cache=True)
def neighbourhood_energies(P, P0, edges, w, edge_ptr, edge_idx, R, out):
    """Each neighbourhood's term of eq. (1), summed edge by edge (no cancellation)."""
    for k in nb.prange(out.shape[0]):
        acc = 0.0
        for t in range(edge_ptr[k], edge_ptr[k + 1]):
            e = edge_idx[t]
            i, j = edges[e, 0], edges[e, 1]
            for a in range(3):
                d = (P[i, a] - P[j, a]) - (
                    R[k, a, 0] * (P0[i, 0] - P0[j, 0])
                    + R[k, a, 1] * (P0[i, 1] - P0[j, 1])
                    + R[k, a, 2] * (P0[i, 2] - P0[j, 2])
                )
                acc += w[e] * d * d
        out[k] = acc


# -- helpers shared with Laplacian editing ---------------------------------------------


def check_handles(mesh: Mesh, handles) -> np.ndarray:
    """Validate handle vertex indices (integers, unique, in range) and return them as int64.

    Examples
    --------
    >>> from arapkit.shapes import bar
    >>> check_handles(bar(), [0, 5]).tolist()
    [0, 5]
    """
    h = np.asarray(handles)
    if h.ndim != 1:
        h = h.reshape(-1)
    if len(h) == 0:
        raise InputError(f"{mesh.name}: no handle vertices given")
    if not np.issubdtype(h.dtype, np.integer):
        hf = np.asarray(h, dtype=np.float64)
        if not np.all(hf == np.round(hf)):
            raise InputError(f"{mesh.name}: handle indices must be integers")
    h = h.astype(np.int64)
    bad = np.flatnonzero((h < 0) | (h >= mesh.n_vertices))
    if len(bad):
        raise InputError(
            f"{mesh.name}: handle {bad[0]} is vertex {h[bad[0]]}, out of range "
            f"(mesh has {mesh.n_vertices} vertices)"
        )
    uniq, counts = np.unique(h, return_counts=True)
    if (counts > 1).any():
        raise InputError(f"{mesh.name}: vertex {uniq[counts > 1][0]} is listed twice as a handle")
    return h


def check_targets(handles: np.ndarray, targets, name: str = "targets") -> np.ndarray:
    """Validate handle targets: shape (len(handles), 3), finite."""
    T = np.asarray(targets, dtype=np.float64)
    if T.shape != (len(handles), 3):
        raise InputError(f"{name}: expected shape ({len(handles)}, 3), got {T.shape}")
    bad = np.flatnonzero(~np.isfinite(T).all(axis=1))
    if len(bad):
        raise InputError(f"{name}: handle {bad[0]} (vertex {handles[bad[0]]}) target is not finite")
    return T


def anchor_components(mesh: Mesh, handles: np.ndarray, policy: str = "fix"):
    """Vertices that must be held fixed because their component has no handle.

    Without a handle such a component can translate freely and the system is singular.

    Parameters
    ----------
    policy : {"fix", "error"}
        ``"fix"`` keeps those components at rest; ``"error"`` refuses.

    Returns
    -------
    fixed : (f,) int64
        Vertices to hold at their rest positions.
    notes : list of str
        What was done, naming the components.

    Examples
    --------
    >>> from arapkit.shapes import bar
    >>> anchor_components(bar(), [0])[0].size
    0
    """
    labels = mesh.component_labels
    anchored = np.zeros(mesh.n_components, dtype=bool)
    anchored[labels[handles]] = True
    if anchored.all():
        return np.empty(0, dtype=np.int64), []
    missing = np.flatnonzero(~anchored)
    sizes = np.bincount(labels, minlength=mesh.n_components)[missing]
    firsts = [int(np.flatnonzero(labels == c)[0]) for c in missing[:3]]
    single = int((sizes == 1).sum())
    desc = (
        f"{len(missing)} connected component(s) without a handle ("
        + ", ".join(f"{s} vertices incl. vertex {f}" for s, f in zip(sizes[:3], firsts))
        + (", ..." if len(missing) > 3 else "")
        + (f"; {single} of them isolated vertices" if single else "")
        + ")"
    )
    if policy == "error":
        raise InputError(f"{mesh.name}: {desc}; add a handle there or use free_components='fix'")
    if policy != "fix":
        raise InputError(f"unknown free_components policy '{policy}' (use 'fix' or 'error')")
    fixed = np.flatnonzero(~anchored[labels]).astype(np.int64)
    return fixed, [f"{desc} are held fixed at rest"]


def laplacian_matrix(n: int, edges: np.ndarray, w: np.ndarray) -> sp.csr_matrix:
    """Symmetric graph Laplacian ``sum_e w_e (e_i - e_j)(e_i - e_j)^T``.

    Examples
    --------
    >>> import numpy as np
    >>> laplacian_matrix(2, np.array([[0, 1]]), np.array([2.0])).toarray().tolist()
    [[2.0, -2.0], [-2.0, 2.0]]
    """
    i, j = edges[:, 0], edges[:, 1]
    rows = np.concatenate([i, j, i, j])
    cols = np.concatenate([j, i, i, j])
    vals = np.concatenate([-w, -w, w, w])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


@contextmanager
def _quiet_stderr():
    """Silence C-level stderr (CHOLMOD prints warnings before raising)."""
    try:
        fd = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(fd, 2)
        os.close(fd)


class CholeskyFactor:
    """Sparse Cholesky factor (CHOLMOD via cholespy) of a symmetric positive definite matrix.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> f = CholeskyFactor(sp.csr_matrix(np.array([[4.0, 1.0], [1.0, 3.0]])), "demo")
    >>> np.round(f.solve(np.array([[1.0], [2.0]])).ravel(), 6).tolist()
    [0.090909, 0.636364]
    """

    def __init__(self, A: sp.spmatrix, what: str, remedy: str = "") -> None:
        from cholespy import CholeskySolverD, MatrixType

        A = sp.coo_matrix(A)
        self.n = A.shape[0]
        try:
            with _quiet_stderr():
                self._solver = CholeskySolverD(
                    self.n,
                    A.row.astype(np.int32),
                    A.col.astype(np.int32),
                    A.data.astype(np.float64),
                    MatrixType.COO,
                )
        except ValueError:
            raise InputError(
                f"{what}: the system matrix is not positive definite{remedy}"
            ) from None

    def solve(self, B: np.ndarray) -> np.ndarray:
        """Solve ``A X = B`` for a (n,) or (n, k) right-hand side."""
        B = np.ascontiguousarray(B, dtype=np.float64)
        X = np.empty_like(B)
        self._solver.solve(B, X)
        return X


# -- results and the deformer ------------------------------------------------------


@dataclass
class Result:
    """Outcome of :meth:`Deformer.solve`.

    Attributes
    ----------
    vertices : (n, 3) deformed positions.
    energy : final energy (eq. 1), summed neighbourhood by neighbourhood.
    history : energy after each iteration.
    iterations : number of local/global iterations run.
    converged : whether the relative-decrease test held (rather than ``max_iter`` or a stop).
    vertex_energy : (n,) each neighbourhood's term of eq. 1.
    rotations : (n, 3, 3) fitted R_k.
    timings : neighbourhood_ms, factorisation_ms, global_ms_per_iter, local_ms_per_iter,
        iterations, total_s.
    """

    vertices: np.ndarray
    energy: float
    history: list[float]
    iterations: int
    converged: bool
    vertex_energy: np.ndarray
    rotations: np.ndarray
    timings: dict[str, float] = field(default_factory=dict)


class Deformer:
    """r-ring ARAP deformer with controllable, spatially varying rigidity.

    Parameters
    ----------
    mesh : Mesh
    handles : (h,) int
        Vertices with positional constraints.
    rings : int or (n,) int
        Neighbourhood size r per vertex (1 = standard ARAP; larger = stiffer).
    weights : {"cotan", "cotan-clamped", "uniform"}
        Edge weights (see :mod:`arapkit.weights`).
    tol : float
        Stop when ``(E_{t-1} - E_t) / E_{t-1} < tol`` (the paper's test, gamma = 1e-3).
    max_iter : int
        Iteration cap.
    init : {"identity", "laplacian"}
        Start from identity rotations (the paper) or from Laplacian editing (the report).
    free_components : {"fix", "error"}
        What to do with connected components that hold no handle.

    Examples
    --------
    >>> from arapkit.shapes import bar, bar_bend
    >>> mesh = bar()
    >>> h, t = bar_bend(mesh, 90)
    >>> res = Deformer(mesh, h, rings=2).solve(t)
    >>> bool(res.converged), bool(res.energy >= 0)
    (True, True)
    """

    def __init__(
        self,
        mesh: Mesh,
        handles,
        rings=1,
        weights: str = "cotan",
        *,
        tol: float = 1e-3,
        max_iter: int = 1000,
        init: str = "identity",
        free_components: str = "fix",
    ) -> None:
        self.mesh = mesh
        self.weights_kind = weights
        self.w = edge_weights(mesh, weights)
        self.tol = float(tol)
        self.max_iter = int(max_iter)
        if init not in INITS:
            raise InputError(f"unknown init '{init}' (use {' or '.join(INITS)})")
        self.init = init
        self.free_components = free_components
        self.timings: dict[str, float] = {}
        self._nb: Neighbourhoods | None = None
        self._factor: CholeskyFactor | None = None
        self._laplacian_editor = None
        self.set_handles(handles)
        self.set_rings(rings)

    # -- configuration (lazy refactorisation, as CGAL) -----------------------------
    def set_handles(self, handles) -> None:
        """Use a new handle set; the factorisation is redone at the next solve."""
        self.handles = check_handles(self.mesh, handles)
        extra, self.notes = anchor_components(self.mesh, self.handles, self.free_components)
        self._fixed_extra = extra
        self._constrained = np.concatenate([self.handles, extra])
        free = np.ones(self.mesh.n_vertices, dtype=bool)
        free[self._constrained] = False
        self._free = np.flatnonzero(free)
        self._factor = None
        self._laplacian_editor = None

    def set_rings(self, rings) -> None:
        """Use a new rigidity map (int or per-vertex); rebuilds neighbourhoods and the factor."""
        r = check_rings(rings, self.mesh.n_vertices)
        t0 = time.perf_counter()
        self._nb = build_neighbourhoods(self.mesh, self.w, r)
        self.timings["neighbourhood_ms"] = 1e3 * (time.perf_counter() - t0)
        self._dw = self._nb.edge_count * self.w
        P0 = self.mesh.vertices
        self._rest_term = weighted_edge_norms(P0, self.mesh.edges, self._dw)
        self._factor = None

    @property
    def rings(self) -> np.ndarray:
        """r per vertex."""
        return self._nb.rings

    @property
    def neighbourhoods(self) -> Neighbourhoods:
        """The r-ring neighbourhoods in use."""
        return self._nb

    def _factorise(self) -> None:
        t0 = time.perf_counter()
        A = laplacian_matrix(self.mesh.n_vertices, self.mesh.edges, self._dw)
        Af = A[self._free]
        self._A_fc = Af[:, self._constrained].tocsr()
        remedy = (
            " (obtuse triangles give negative cotangent weights); "
            "use weights='cotan-clamped' or weights='uniform'"
            if self.weights_kind == "cotan"
            else ""
        )
        if len(self._free):
            self._factor = CholeskyFactor(Af[:, self._free], self.mesh.name, remedy)
        self.timings["factorisation_ms"] = 1e3 * (time.perf_counter() - t0)

    # -- the two steps ----------------------------------------------------------
    def global_step(self, R: np.ndarray, fixed_rhs: np.ndarray, P: np.ndarray) -> None:
        """Solve for the free vertices given rotations R (in place in P)."""
        nb_ = self._nb
        b = np.empty_like(P)
        rotated_rhs(R, nb_.vdisk_ptr, nb_.vdisk_k, nb_.vdisk_coef, b)
        if len(self._free):
            P[self._free] = self._factor.solve(b[self._free] - fixed_rhs)

    def local_step(self, P: np.ndarray, R: np.ndarray) -> float:
        """Fit rotations to P (in place in R) and return the energy E(P, R)."""
        nb_ = self._nb
        trRS = np.empty(len(P))
        local_step(P, nb_.disk_ptr, nb_.disk_idx, nb_.disk_coef, R, trRS)
        quad = weighted_edge_norms(P, self.mesh.edges, self._dw)
        return float(quad + self._rest_term - 2.0 * trRS.sum())

    def vertex_energy(self, P: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Each neighbourhood's term of eq. (1) for positions P and rotations R."""
        out = np.empty(len(P))
        nb_ = self._nb
        neighbourhood_energies(P, self.mesh.vertices, self.mesh.edges, self.w, nb_.edge_ptr,
                               nb_.edge_idx, R, out)
        return out

    def _initial_positions(self, targets: np.ndarray, init) -> np.ndarray | None:
        if init is not None and not isinstance(init, str):
            P = np.array(init, dtype=np.float64)
            if P.shape != self.mesh.vertices.shape or not np.isfinite(P).all():
                raise InputError(
                    f"init: expected finite positions of shape {self.mesh.vertices.shape}"
                )
            return P
        mode = self.init if init is None else init
        if mode not in INITS:
            raise InputError(f"unknown init '{mode}' (use {' or '.join(INITS)})")
        if mode == "identity":
            return None
        if self._laplacian_editor is None:
            from .laplacian import LaplacianEditor

            self._laplacian_editor = LaplacianEditor(self.mesh, self._constrained, "uniform")
        return self._laplacian_editor.solve(self._constrained_targets(targets))

    def _constrained_targets(self, targets: np.ndarray) -> np.ndarray:
        return np.concatenate([targets, self.mesh.vertices[self._fixed_extra]])

    # -- the solve loop ------------------------------------------------------------
    def solve(
        self,
        targets,
        init=None,
        tol: float | None = None,
        max_iter: int | None = None,
        callback: Callable[[int, float, np.ndarray], bool | None] | None = None,
    ) -> Result:
        """Deform so that the handles reach ``targets``.

        Parameters
        ----------
        targets : (h, 3)
            Positions of the handles, in the order of ``handles``.
        init : None, "identity", "laplacian" or (n, 3) array
            Starting point; an array is a warm start (e.g. the previous result).
        tol, max_iter : optional overrides of the constructor's values.
        callback : callable(iteration, energy, vertices) -> bool, optional
            Called after every iteration; returning True stops the loop.

        Returns
        -------
        Result
        """
        t_start = time.perf_counter()
        T = check_targets(self.handles, targets)
        tol = self.tol if tol is None else float(tol)
        max_iter = self.max_iter if max_iter is None else int(max_iter)
        if self._factor is None:
            self._factorise()
        n = self.mesh.n_vertices
        C = self._constrained_targets(T)
        fixed_rhs = self._A_fc @ C if len(self._free) else np.zeros((0, 3))
        R = np.empty((n, 3, 3))
        P0 = self._initial_positions(T, init)
        E_prev = None
        t_global = t_local = 0.0
        if P0 is None:
            P = self.mesh.vertices.copy()
            R[:] = np.eye(3)
        else:
            P = P0
            t0 = time.perf_counter()
            E_prev = self.local_step(P, R)
            t_local += time.perf_counter() - t0
        P[self._constrained] = C
        history: list[float] = []
        converged = False
        # relative decrease is meaningless at round-off level: treat that as converged
        floor = 1e-24 * max(self._rest_term, 1e-300)
        it = 0
        for it in range(1, max_iter + 1):
            t0 = time.perf_counter()
            self.global_step(R, fixed_rhs, P)
            t1 = time.perf_counter()
            E = self.local_step(P, R)
            t_local += time.perf_counter() - t1
            t_global += t1 - t0
            history.append(E)
            if E <= floor or (E_prev is not None and (E_prev - E) / E_prev < tol):
                converged = True
            E_prev = E
            if callback is not None and callback(it, E, P):
                break
            if converged:
                break
        ve = self.vertex_energy(P, R)
        timings = {
            "neighbourhood_ms": self.timings.get("neighbourhood_ms", 0.0),
            "factorisation_ms": self.timings.get("factorisation_ms", 0.0),
            "global_ms_per_iter": 1e3 * t_global / max(it, 1),
            "local_ms_per_iter": 1e3 * t_local / max(it, 1),
            "iterations": it,
            "total_s": time.perf_counter() - t_start,
        }
        return Result(P, float(ve.sum()), history, it, converged, ve, R, timings)
