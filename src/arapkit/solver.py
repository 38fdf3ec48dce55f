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

import math
import os
import sys
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field

import numba as nb
import numpy as np
import scipy.sparse as sp

from .accel import Anderson
from .errors import InputError
from .mesh import Mesh
from .rings import (
    Neighbourhoods,
    build_neighbourhoods,
    check_rings,
    neighbourhoods_from_arrays,
)
from .rotations import fit_rotation_range
from .validate import (
    handle_indices,
    integer,
    iteration_cap,
    real_array,
    target_positions,
    tolerance,
)
from .weights import DEFAULT_WEIGHTS, edge_weights

__all__ = ["Deformer", "Result", "check_handles", "anchor_components", "laplacian_matrix"]

INITS = ("identity", "laplacian")


# -- compiled kernels ---------------------------------------------------------------


@nb.njit(parallel=True, cache=True)
def local_step(P, chunk_ptr, disk_ptr, disk_idx, disk_coef, up_ptr, up_idx, up_w, S, R, buf,
               win_lo, win_off, partial):
    """Fused local step: covariances, rotations and the scatter of the next right-hand side.

    Per chunk of consecutive k (one parallel region per iteration: on a shared machine
    every extra region is a chance to wait for a descheduled thread):

    1. ``S_k = sum_v c_kv (p'_v - p'_k)^T``. Subtracting p'_k is exact (the c_kv of a
       neighbourhood sum to zero) and keeps the sums well conditioned far from the origin.
       The upper Laplacian row of k adds its share of ``sum_e d_e w_e |e'|^2`` while those
       vertices are in cache.
    2. ``R_k`` for the chunk at once (the vectorised kernel of :mod:`arapkit.rotations`).
    3. ``tr(R_k S_k)`` and ``b_v += R_k c_kv``. Scattering from k needs no transposed copy
       of the coefficients; each chunk adds into its own window
       ``[win_lo[c], win_lo[c] + len)`` of ``buf`` (no races), and with a bandwidth-reducing
       vertex order the windows barely overlap.

    ``partial[c] = (sum tr(R_k S_k), quadratic term)`` for chunk c.
    """
    for c in nb.prange(chunk_ptr.shape[0] - 1):
        k0, k1 = chunk_ptr[c], chunk_ptr[c + 1]
        quad = 0.0
        for k in range(k0, k1):
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
            for t in range(up_ptr[k], up_ptr[k + 1]):
                j = up_idx[t]
                dx, dy, dz = P[j, 0] - px, P[j, 1] - py, P[j, 2] - pz
                quad += up_w[t] * (dx * dx + dy * dy + dz * dz)
            S[k, 0, 0], S[k, 0, 1], S[k, 0, 2] = s00, s01, s02
            S[k, 1, 0], S[k, 1, 1], S[k, 1, 2] = s10, s11, s12
            S[k, 2, 0], S[k, 2, 1], S[k, 2, 2] = s20, s21, s22
        fit_rotation_range(S, R, k0, k1)
        off = win_off[c] - win_lo[c]
        for q in range(win_off[c], win_off[c + 1]):
            buf[q, 0] = 0.0
            buf[q, 1] = 0.0
            buf[q, 2] = 0.0
        tr = 0.0
        for k in range(k0, k1):
            r00, r01, r02 = R[k, 0, 0], R[k, 0, 1], R[k, 0, 2]
            r10, r11, r12 = R[k, 1, 0], R[k, 1, 1], R[k, 1, 2]
            r20, r21, r22 = R[k, 2, 0], R[k, 2, 1], R[k, 2, 2]
            for a in range(3):
                tr += R[k, a, 0] * S[k, 0, a] + R[k, a, 1] * S[k, 1, a] + R[k, a, 2] * S[k, 2, a]
            for t in range(disk_ptr[k], disk_ptr[k + 1]):
                q = off + disk_idx[t]
                c0, c1, c2 = disk_coef[t, 0], disk_coef[t, 1], disk_coef[t, 2]
                buf[q, 0] += r00 * c0 + r01 * c1 + r02 * c2
                buf[q, 1] += r10 * c0 + r11 * c1 + r12 * c2
                buf[q, 2] += r20 * c0 + r21 * c1 + r22 * c2
        partial[c, 0] = tr
        partial[c, 1] = quad


# Serial on purpose: these are light O(n) passes, and on a shared machine a parallel region
# costs a scheduler time slice whenever another process holds one of the cores.
@nb.njit(cache=True)
def gather_rhs(buf, win_lo, win_off, chunk_ptr, cover_ptr, cover_idx, slot, fixed_rhs, rhs):
    """``rhs[slot[v]] = b_v - (A_fc C)_v`` for free v, summing the windows that cover v."""
    for c in range(chunk_ptr.shape[0] - 1):
        for v in range(chunk_ptr[c], chunk_ptr[c + 1]):
            s = slot[v]
            if s < 0:
                continue
            b0 = -fixed_rhs[s, 0]
            b1 = -fixed_rhs[s, 1]
            b2 = -fixed_rhs[s, 2]
            for t in range(cover_ptr[c], cover_ptr[c + 1]):
                d = cover_idx[t]
                q = v - win_lo[d]
                if q >= 0 and q < win_off[d + 1] - win_off[d]:
                    q += win_off[d]
                    b0 += buf[q, 0]
                    b1 += buf[q, 1]
                    b2 += buf[q, 2]
            rhs[s, 0] = b0
            rhs[s, 1] = b1
            rhs[s, 2] = b2


@nb.njit(cache=True)
def scatter_rows(X, idx, P):
    """``P[idx[i]] = X[i]``."""
    for i in range(idx.shape[0]):
        v = idx[i]
        P[v, 0] = X[i, 0]
        P[v, 1] = X[i, 1]
        P[v, 2] = X[i, 2]


@nb.njit(cache=True)
def _windows(chunk_ptr, disk_ptr, disk_idx):
    """Smallest index range each chunk's disks touch."""
    n_chunks = chunk_ptr.shape[0] - 1
    lo = np.empty(n_chunks, dtype=np.int64)
    hi = np.empty(n_chunks, dtype=np.int64)
    for c in range(n_chunks):
        a, b = 1 << 62, -1
        for t in range(disk_ptr[chunk_ptr[c]], disk_ptr[chunk_ptr[c + 1]]):
            v = disk_idx[t]
            a = min(a, v)
            b = max(b, v)
        lo[c], hi[c] = (a, b + 1) if b >= 0 else (chunk_ptr[c], chunk_ptr[c])
    return lo, hi


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

    A boolean array of one value per vertex is read as a mask. The rule is
    :func:`arapkit.validate.handle_indices`.

    Examples
    --------
    >>> from arapkit.shapes import bar
    >>> check_handles(bar(), [0, 5]).tolist()
    [0, 5]
    """
    return handle_indices(handles, mesh.n_vertices, mesh.name)


def check_targets(handles: np.ndarray, targets, name: str = "targets") -> np.ndarray:
    """Validate handle targets: real, shape (len(handles), 3), finite."""
    return target_positions(handles, targets, name)


def unit_scale(vertices: np.ndarray, name: str) -> float:
    """The power of two ``s`` with ``extent / s`` in [0.5, 1): the solver works in ``V / s``.

    Dividing by a power of two is exact, so a mesh scaled by ``2**k`` gives bit-identical
    iterations; any other scale changes nothing beyond round-off. Every tolerance inside
    the solve (convergence floor, cotangent caps) is then relative to the mesh's own size,
    and squared lengths neither overflow nor underflow for extents anywhere in the double
    range.

    Examples
    --------
    >>> import numpy as np
    >>> unit_scale(np.array([[0.0, 0, 0], [3, 0, 0]]), "m")
    4.0
    """
    V = np.asarray(vertices, dtype=np.float64)
    if len(V) < 2:
        return 1.0
    with np.errstate(over="ignore", invalid="ignore"):
        extent = float(np.max(V.max(axis=0) - V.min(axis=0)))
    if not math.isfinite(extent):
        raise InputError(
            f"{name}: coordinates span more than double precision can hold "
            f"(from {V.min():.3g} to {V.max():.3g}); rescale the mesh"
        )
    if extent == 0:
        return 1.0
    return math.ldexp(1.0, math.frexp(extent)[1])


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


def _flush_c_stdio() -> None:
    """Flush the C library's stdio buffers (CHOLMOD's printf output sits there)."""
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # no libc symbols on this platform: nothing to flush
        pass


@contextmanager
def _quiet_c_output():
    """Silence C-level stdout and stderr: CHOLMOD prints a warning before cholespy raises.

    stdout must carry results only (the command line pipes it), so the warning is flushed
    into /dev/null before the streams are restored.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            os.dup2(null.fileno(), 2)
            try:
                yield
            finally:
                _flush_c_stdio()
    finally:
        for fd, target in zip(saved, (1, 2)):
            os.dup2(fd, target)
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

    #: factorisations done by all instances (lets tests prove that new targets never refactorise)
    count = 0

    def __init__(self, A: sp.spmatrix, what: str, remedy: str = "") -> None:
        from cholespy import CholeskySolverD, MatrixType

        A = sp.coo_matrix(A)
        self.n = A.shape[0]
        CholeskyFactor.count += 1
        try:
            with _quiet_c_output():
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

    def solve(self, B: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Solve ``A X = B`` for a (n,) or (n, k) right-hand side (into ``out`` if given)."""
        B = np.ascontiguousarray(B, dtype=np.float64)
        X = np.empty_like(B) if out is None else out
        self._solver.solve(B, X)
        return X


# -- results and the deformer ------------------------------------------------------


@dataclass
class Result:
    """Outcome of :meth:`Deformer.solve`.

    Attributes
    ----------
    vertices : (n, 3) deformed positions.
    energy : final energy (eq. 1), the last entry of ``history``.
    history : energy after each iteration.
    iterations : number of local/global iterations run.
    converged : whether the relative-decrease test held (rather than ``max_iter`` or a stop).
    rotations : (n, 3, 3) fitted R_k.
    timings : neighbourhood_ms, factorisation_ms, global_ms_per_iter, local_ms_per_iter,
        iterations, total_s.
    vertex_energy : (n,) each neighbourhood's term of eq. 1, summed edge by edge. Computed
        on first access: interactive callers that discard superseded results skip its cost.
    """

    vertices: np.ndarray
    energy: float
    history: list[float]
    iterations: int
    converged: bool
    rotations: np.ndarray
    timings: dict[str, float] = field(default_factory=dict)
    _vertex_energy: np.ndarray | Callable[[], np.ndarray] | None = field(default=None,
                                                                          repr=False)

    @property
    def vertex_energy(self) -> np.ndarray:
        """Each neighbourhood's term of eq. (1) (computed once, on first access)."""
        if callable(self._vertex_energy):
            self._vertex_energy = self._vertex_energy()
        return self._vertex_energy


DEVICES = ("cpu", "auto")


def _check_device(device: str) -> str:
    """Resolve ``device``; only the CPU path exists (the GPU path is not built)."""
    dev = str(device).lower()
    if dev in DEVICES:
        return "cpu"
    if dev in ("cuda", "gpu") or dev.startswith("cuda:"):
        raise InputError(
            f"device='{device}': no GPU solver is available in this build of arapkit "
            "(the CUDA path is not implemented); use device='cpu' or device='auto'"
        )
    raise InputError(f"unknown device '{device}' (use 'cpu' or 'auto')")


def bandwidth_order(mesh: Mesh) -> np.ndarray:
    """Reverse Cuthill-McKee order of the vertices (new -> old).

    Consecutive vertices are then close on the surface, so a neighbourhood's vertices
    lie near each other in memory and the per-thread scatter windows barely overlap.

    Examples
    --------
    >>> from arapkit.shapes import bar
    >>> m = bar()
    >>> sorted(bandwidth_order(m).tolist()) == list(range(m.n_vertices))
    True
    """
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    return reverse_cuthill_mckee(mesh.adjacency.tocsr(), symmetric_mode=True).astype(np.int64)


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
    accelerate : bool
        Anderson acceleration (Peng et al. 2018) of the local/global iteration with an
        energy safeguard: an accelerated iterate is kept only when it lowers the energy,
        otherwise the plain iterate is used, so the history stays monotone. Off by default
        so that iterations (and the paper's stopping test) mean plain local/global steps;
        see ``docs/benchmarks.md`` for when it pays.
    history : int
        Anderson history size m.
    reorder : bool
        Work internally in a bandwidth-reducing vertex order (results are returned in the
        mesh's order and agree with ``reorder=False`` to round-off).
    device : {"cpu", "auto"}
        Where to solve. Only the CPU path exists; "cuda" raises :class:`InputError`.

    Examples
    --------
    >>> from arapkit.shapes import bar, bar_bend
    >>> mesh = bar()
    >>> h, t = bar_bend(mesh, 90)
    >>> res = Deformer(mesh, h, rings=2).solve(t)
    >>> bool(res.converged), bool(res.energy >= 0)
    (True, True)
    >>> fast = Deformer(mesh, h, rings=2, accelerate=True).solve(t, tol=1e-6)
    >>> bool(fast.energy <= res.energy)
    True
    """

    def __init__(
        self,
        mesh: Mesh,
        handles,
        rings=1,
        weights: str = DEFAULT_WEIGHTS,
        *,
        tol: float = 1e-3,
        max_iter: int = 1000,
        init: str = "identity",
        free_components: str = "fix",
        accelerate: bool = False,
        history: int = 5,
        reorder: bool = True,
        device: str = "cpu",
    ) -> None:
        self.device = _check_device(device)
        self.mesh = mesh
        self.weights_kind = weights
        self.tol = tolerance(tol)
        self.max_iter = iteration_cap(max_iter)
        if init not in INITS:
            raise InputError(f"unknown init '{init}' (use {' or '.join(INITS)})")
        self.init = init
        self.free_components = free_components
        self.accelerate = bool(accelerate)
        self.history = integer(history, "history", lo=1, hi=1000)
        self.timings: dict[str, float] = {}
        self._nb: Neighbourhoods | None = None
        self._nb_public: Neighbourhoods | None = None
        self._factor: CholeskyFactor | None = None
        self._laplacian_editor = None
        self.factorisations = 0
        t0 = time.perf_counter()
        self.w = edge_weights(mesh, weights)
        n = mesh.n_vertices
        if reorder and n > 1:
            self._perm = bandwidth_order(mesh)
        else:
            self._perm = np.arange(n, dtype=np.int64)
        self._iperm = np.empty(n, dtype=np.int64)
        self._iperm[self._perm] = np.arange(n)
        self._E = self._iperm[mesh.edges]  # same edge ids, internal vertex numbers
        # internal unit: a power of two near the extent (exact), see unit_scale
        self._scale = unit_scale(mesh.vertices, mesh.name)
        self._P0 = np.ascontiguousarray(mesh.vertices[self._perm] / self._scale)
        self._setup_ms = 1e3 * (time.perf_counter() - t0)
        self.set_handles(handles)
        self.set_rings(rings)

    # -- configuration (lazy refactorisation, as CGAL) -----------------------------
    def set_handles(self, handles) -> None:
        """Use a new handle set; the factorisation is redone at the next solve."""
        self.handles = check_handles(self.mesh, handles)
        extra, self._component_notes = anchor_components(self.mesh, self.handles,
                                                         self.free_components)
        self._fixed_extra = extra
        self._constrained = np.concatenate([self.handles, extra])
        free = np.ones(self.mesh.n_vertices, dtype=bool)
        free[self._constrained] = False
        self._free = np.flatnonzero(free)
        self._factor = None
        self._laplacian_editor = None

    def set_rings(self, rings) -> None:
        """Use a new rigidity map (int or per-vertex); rebuilds neighbourhoods and the factor."""
        n = self.mesh.n_vertices
        r = check_rings(rings, n)
        t0 = time.perf_counter()
        nbh = neighbourhoods_from_arrays(n, self._E, self._P0, self.w, r[self._perm],
                                         transpose=False)
        self._rings = r
        self._nb = nbh
        self._nb_public = None
        self._dw = nbh.edge_count * self.w
        self._rest_term = weighted_edge_norms(self._P0, self._E, self._dw)
        if not math.isfinite(self._rest_term * self._scale * self._scale):
            raise InputError(
                f"{self.mesh.name}: coordinates too large for double precision (extent about "
                f"{self._scale:.3g}: the deformation energy overflows); rescale the mesh"
            )
        # upper rows of the Laplacian of d_e w_e, for the quadratic term of the energy
        a, b = self._E.min(axis=1), self._E.max(axis=1)
        order = np.argsort(a, kind="stable")
        self._up_ptr = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(np.bincount(a, minlength=n), out=self._up_ptr[1:])
        self._up_idx = b[order].astype(np.int32)
        self._up_w = self._dw[order]
        # A P0 = sum_k I c_kv: the right-hand side for identity rotations
        self._b_rest = np.zeros((n, 3))
        dP = self._dw[:, None] * (self._P0[a] - self._P0[b])
        for ax in range(3):
            self._b_rest[:, ax] = np.bincount(a, dP[:, ax], n) - np.bincount(b, dP[:, ax], n)
        self._make_chunks()
        self._weight_notes = self._check_rest_is_minimum()
        self.timings["neighbourhood_ms"] = 1e3 * (time.perf_counter() - t0) + self._setup_ms
        self._setup_ms = 0.0
        self._factor = None

    def _check_rest_is_minimum(self) -> list[str]:
        """Say so when negative weights make the rest shape a non-minimum of eq. (1).

        With all weights >= 0 every rest covariance is positive semi-definite, its best
        rotation is the identity and the energy at rest is 0. Negative cotangent weights
        (obtuse triangles) can make the best-fit energy at rest negative: the shape then
        drifts even when every handle stays in place.
        """
        if (self.w >= 0).all():
            return []
        R = np.empty((self.mesh.n_vertices, 3, 3))
        E_rest = self._local(self._P0.copy(), R)
        if E_rest >= -1e-9 * abs(self._rest_term):
            return []
        bad = int(np.count_nonzero(np.abs(R - np.eye(3)).max(axis=(1, 2)) > 1e-6))
        return [
            f"{int((self.w < 0).sum())} edges have negative cotangent weights and the rest "
            f"shape is not an energy minimum ({bad} neighbourhoods prefer a rotation at rest): "
            "the shape can drift even where handles stay put; use weights='cotan-clamped'"
        ]

    @property
    def notes(self) -> list[str]:
        """What the deformer did about the input: fixed components, problematic weights."""
        return self._component_notes + self._weight_notes

    def _make_chunks(self) -> None:
        """Split k into chunks of equal work and give each a private scatter window."""
        nbh = self._nb
        n = self.mesh.n_vertices
        threads = nb.get_num_threads()
        work = np.diff(nbh.disk_ptr) + 16  # + the rotation fit
        cum = np.concatenate([[0], np.cumsum(work)])
        n_chunks = max(1, min(8 * threads, n // 256))
        while True:
            cuts = np.searchsorted(cum, np.linspace(0, cum[-1], n_chunks + 1))
            cuts[0], cuts[-1] = 0, n
            chunk_ptr = np.unique(cuts).astype(np.int64)
            lo, hi = _windows(chunk_ptr, nbh.disk_ptr, nbh.disk_idx)
            total = int((hi - lo).sum())
            # a poor vertex order makes windows span the mesh: fewer chunks bound the memory
            if total <= 3 * n or n_chunks <= threads:
                break
            n_chunks = max(threads, n_chunks // 2)
        win_off = np.zeros(len(lo) + 1, dtype=np.int64)
        np.cumsum(hi - lo, out=win_off[1:])
        cover = [np.flatnonzero((lo < chunk_ptr[c + 1]) & (hi > chunk_ptr[c]))
                 for c in range(len(lo))]
        self._chunk_ptr = chunk_ptr
        self._win_lo = lo
        self._win_off = win_off
        self._cover_ptr = np.concatenate([[0], np.cumsum([len(x) for x in cover])]).astype(
            np.int64)
        self._cover_idx = np.concatenate(cover).astype(np.int64)
        self._buf = np.zeros((total, 3))
        self._partial = np.zeros((len(lo), 2))
        self._S = np.empty((n, 3, 3))

    @property
    def rings(self) -> np.ndarray:
        """r per vertex."""
        return self._rings

    @property
    def neighbourhoods(self) -> Neighbourhoods:
        """The r-ring neighbourhoods in use, in the mesh's vertex numbering (built on demand)."""
        if self._nb_public is None:
            self._nb_public = build_neighbourhoods(self.mesh, self.w, self._rings)
        return self._nb_public

    def _factorise(self) -> None:
        t0 = time.perf_counter()
        n = self.mesh.n_vertices
        cons = self._iperm[self._constrained]
        is_free = np.ones(n, dtype=bool)
        is_free[cons] = False
        free = np.flatnonzero(is_free)
        slot = np.full(n, -1, dtype=np.int64)
        slot[free] = np.arange(len(free))
        cslot = np.full(n, -1, dtype=np.int64)
        cslot[cons] = np.arange(len(cons))
        self._free_int = free
        self._cons_int = cons
        self._slot = slot
        a, b, dw = self._E[:, 0], self._E[:, 1], self._dw
        sa, sb = slot[a], slot[b]
        nf, nc = len(free), len(cons)
        ff = (sa >= 0) & (sb >= 0)
        diag = np.bincount(sa[sa >= 0], dw[sa >= 0], nf) + np.bincount(sb[sb >= 0], dw[sb >= 0],
                                                                        nf)
        rows = np.concatenate([sa[ff], sb[ff], np.arange(nf)])
        cols = np.concatenate([sb[ff], sa[ff], np.arange(nf)])
        vals = np.concatenate([-dw[ff], -dw[ff], diag])
        fc = (sa >= 0) & (sb < 0)
        cf = (sa < 0) & (sb >= 0)
        self._A_fc = sp.csr_matrix(
            (np.concatenate([-dw[fc], -dw[cf]]),
             (np.concatenate([sa[fc], sb[cf]]), np.concatenate([cslot[b[fc]], cslot[a[cf]]]))),
            shape=(nf, nc),
        )
        remedy = (
            " (obtuse triangles give negative cotangent weights); "
            "use weights='cotan-clamped' or weights='uniform'"
            if self.weights_kind == "cotan"
            else ""
        )
        if nf:
            A = sp.coo_matrix((vals, (rows, cols)), shape=(nf, nf))
            self._factor = CholeskyFactor(A, self.mesh.name, remedy)
            self.factorisations += 1
        else:
            self._factor = CholeskyFactor.__new__(CholeskyFactor)  # nothing to solve
        self.timings["factorisation_ms"] = 1e3 * (time.perf_counter() - t0)

    # -- the two steps (internal vertex order) ----------------------------------------
    def _local(self, P: np.ndarray, R: np.ndarray) -> float:
        """Fit rotations to P (in place in R), scatter the right-hand side; return E(P, R)."""
        nbh = self._nb
        local_step(P, self._chunk_ptr, nbh.disk_ptr, nbh.disk_idx, nbh.disk_coef,
                   self._up_ptr, self._up_idx, self._up_w, self._S, R, self._buf,
                   self._win_lo, self._win_off, self._partial)
        tr, quad = self._partial.sum(axis=0)
        return float(quad + self._rest_term - 2.0 * tr)

    def _rhs(self, fixed_rhs: np.ndarray, rhs: np.ndarray) -> None:
        """Right-hand side of the free vertices from the last local step."""
        gather_rhs(self._buf, self._win_lo, self._win_off, self._chunk_ptr, self._cover_ptr,
                   self._cover_idx, self._slot, fixed_rhs, rhs)

    def vertex_energy(self, P: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Each neighbourhood's term of eq. (1) for positions P and rotations R (mesh order).

        Examples
        --------
        >>> import numpy as np
        >>> from arapkit.shapes import bar
        >>> m = bar()
        >>> d = Deformer(m, [0])
        >>> R = np.tile(np.eye(3), (m.n_vertices, 1, 1))
        >>> float(d.vertex_energy(m.vertices, R).max())
        0.0
        """
        Pi = np.ascontiguousarray(np.asarray(P, dtype=np.float64)[self._perm] / self._scale)
        Ri = np.ascontiguousarray(np.asarray(R, dtype=np.float64)[self._perm])
        return self._vertex_energy(Pi, Ri)[self._iperm] * (self._scale * self._scale)

    def _vertex_energy(self, Pi: np.ndarray, Ri: np.ndarray) -> np.ndarray:
        out = np.empty(len(Pi))
        nbh = self._nb
        neighbourhood_energies(Pi, self._P0, self._E, self.w, nbh.edge_ptr, nbh.edge_idx, Ri,
                               out)
        return out

    def _initial_positions(self, targets: np.ndarray, init) -> np.ndarray | None:
        if init is not None and not isinstance(init, str):
            P = real_array(init, "init")
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

    def prepare(self) -> None:
        """Factorise now (otherwise the first :meth:`solve` does it); reused for all targets."""
        if self._factor is None:
            self._factorise()

    # -- the solve loop ------------------------------------------------------------
    def solve(
        self,
        targets,
        init=None,
        tol: float | None = None,
        max_iter: int | None = None,
        callback: Callable[[int, float, np.ndarray], bool | None] | None = None,
        accelerate: bool | None = None,
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
        accelerate : optional override of the constructor's ``accelerate``.

        Returns
        -------
        Result
        """
        t_start = time.perf_counter()
        T = check_targets(self.handles, targets)
        tol = self.tol if tol is None else tolerance(tol)
        max_iter = self.max_iter if max_iter is None else iteration_cap(max_iter)
        s = self._scale
        s2 = s * s
        accelerate = self.accelerate if accelerate is None else bool(accelerate)
        self.prepare()
        n = self.mesh.n_vertices
        nf = len(self._free_int)
        C = self._constrained_targets(T) / s
        fixed_rhs = np.ascontiguousarray(self._A_fc @ C) if nf else np.zeros((0, 3))
        R = np.empty((n, 3, 3))
        P0 = self._initial_positions(T, init)
        rhs = np.empty((nf, 3))
        E_prev = None
        t_global = t_local = t_accel = 0.0
        if P0 is None:
            P = self._P0.copy()
            R[:] = np.eye(3)
            P[self._cons_int] = C
            rhs[:] = self._b_rest[self._free_int] - fixed_rhs
        else:
            # handles are snapped before the first fit, as libigl does, so the first
            # rotations already see the new targets
            P = np.ascontiguousarray(P0[self._perm] / s)
            P[self._cons_int] = C
            t0 = time.perf_counter()
            E_prev = self._local(P, R)
            self._check_finite(E_prev, 0, T)
            self._rhs(fixed_rhs, rhs)
            t_local += time.perf_counter() - t0
        aa = Anderson(3 * nf, self.history) if accelerate and nf else None
        x = np.ascontiguousarray(P[self._free_int])  # current iterate (free vertices)
        g = np.empty((nf, 3))
        x_aa = np.empty((nf, 3))
        history: list[float] = []
        converged = False
        rejected = 0
        # relative decrease is meaningless at round-off level: treat that as converged
        floor = 1e-24 * max(abs(self._rest_term), 1e-300)
        it = 0
        for it in range(1, max_iter + 1):
            t0 = time.perf_counter()
            if nf:
                self._factor.solve(rhs, g)  # g = G(x)
            t1 = time.perf_counter()
            t_global += t1 - t0
            E = None
            if aa is not None and E_prev is not None:
                y = aa.step(x, g, x_aa)
                t2 = time.perf_counter()
                t_accel += t2 - t1
                if y is not None:
                    scatter_rows(x_aa, self._free_int, P)
                    E_try = self._local(P, R)
                    if E_try < E_prev:  # safeguard: keep only energy-lowering extrapolations
                        E = E_try
                        x, x_aa = x_aa, x
                    else:
                        rejected += 1
                t_local += time.perf_counter() - t2
            t2 = time.perf_counter()
            if E is None:
                scatter_rows(g, self._free_int, P)
                E = self._local(P, R)
                if aa is not None:
                    x, g = g, x
            if it < max_iter:
                self._rhs(fixed_rhs, rhs)
            t_local += time.perf_counter() - t2
            self._check_finite(E, it, T)
            history.append(E * s2)
            # abs(): obtuse meshes have negative cotangent weights and can have E < 0
            if abs(E) <= floor or (E_prev is not None and (E_prev - E) / abs(E_prev) < tol):
                converged = True
            E_prev = E
            if callback is not None and callback(it, E * s2, P[self._iperm] * s):
                break
            if converged:
                break
        timings = {
            "neighbourhood_ms": self.timings.get("neighbourhood_ms", 0.0),
            "factorisation_ms": self.timings.get("factorisation_ms", 0.0),
            "global_ms_per_iter": 1e3 * t_global / max(it, 1),
            "local_ms_per_iter": 1e3 * t_local / max(it, 1),
            "iterations": it,
            "total_s": time.perf_counter() - t_start,
        }
        if aa is not None:
            timings["accel_ms_per_iter"] = 1e3 * t_accel / max(it, 1)
            timings["accel_rejected"] = rejected
        inv = self._iperm

        def vertex_energy() -> np.ndarray:
            return self._vertex_energy(P, R)[inv] * s2

        V = P[inv] * s
        if not np.isfinite(V).all():
            self._check_finite(float("nan"), it, T)
        return Result(V, history[-1], history, it, converged, R[inv], timings, vertex_energy)

    def _check_finite(self, E: float, iteration: int, T: np.ndarray) -> None:
        """Stop with a one-line error when the solve left the range of double precision.

        Checked once per iteration on the energy (a scalar: free); a non-finite position
        makes the energy non-finite too, and the positions are checked again at the end.
        """
        s2 = self._scale * self._scale
        if math.isfinite(E) and math.isfinite(E * s2):
            return
        with np.errstate(over="ignore", invalid="ignore"):
            far = float(np.max(np.abs(T))) if T.size else 0.0
        raise InputError(
            f"{self.mesh.name}: the solve produced non-finite values at iteration {iteration}: "
            f"targets too large for double precision (largest |coordinate| {far:.3g}, "
            f"mesh extent about {self._scale:.3g})"
        )
