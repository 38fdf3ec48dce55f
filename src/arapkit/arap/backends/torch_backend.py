"""Torch backend of the local/global solver: one code path for CPU and CUDA tensors.

Needs the optional extra ``arapkit[torch]``; nothing in the core package imports this
module unless a torch device is asked for.

Two layers live here:

* :class:`TorchSystem`: an :class:`~arapkit.arap.problem.ARAPProblem` converted once to torch
  tensors on one device and dtype (the neighbourhood CSR as index arrays, the free /
  constrained split, the reduced matrix ``A_ff`` with its cholespy factor on the same
  device), and the batched operations on positions ``P`` of shape ``(B, n, 3)``
  (internal numbering): :meth:`~TorchSystem.covariances`, :func:`fit_rotations`,
  :meth:`~TorchSystem.rhs`, :meth:`~TorchSystem.solve`. The layer of :mod:`arapkit.torch`
  is built on these.
* :class:`TorchBackend`: the same operations behind the interface of
  :class:`arapkit.arap.backends.cpu.CPUBackend`, so that :func:`arapkit.arap.loop.local_global` (and
  therefore :class:`arapkit.Deformer` with ``device="cuda"`` or ``"torch-cpu"``) runs on
  it unchanged. The loop keeps its iterate in numpy, so every iteration copies positions
  and rotations between host and device: :class:`arapkit.torch.ARAPLayer` keeps
  everything on the device and is the fast path on a GPU.

Rotations are fitted by a batched 3x3 SVD (``torch.linalg.svd``) with the reflection
fix. Its derivative is the closed form of the polar factor (see :class:`_PolarRotation`),
not the autograd of the SVD, which divides by differences of singular values and breaks
at the repeated ones that symmetric rest neighbourhoods have.
"""

from __future__ import annotations

import atexit
import weakref

import numpy as np
import torch

from ...errors import InputError
from ..problem import ARAPProblem

__all__ = ["TorchBackend", "TorchSystem", "best_rotations", "fit_rotations", "resolve_device"]

#: cholespy's CUDA solver takes at most this many right-hand sides per call (a multiple
#: of _BLOCK)
_CUDA_MAX_RHS = 128
#: columns per pose in a solve: x, y, z and a zero column (see TorchSystem.solve)
_BLOCK = 4

_CUDA_REMEDY = ("install a CUDA build of torch (pip install 'arapkit[torch]' on a machine "
                "with an NVIDIA driver) or use device='cpu'")


_LIVE: weakref.WeakSet = weakref.WeakSet()


@atexit.register
def _release_factors() -> None:
    """Drop the cholespy factors before interpreter shutdown.

    Autograd contexts keep layers (and their factors) alive until the very end, after
    nanobind has checked for live instances, which then prints a "leaked instances" report.
    """
    for system in list(_LIVE):
        system._factor = None
        # the problem's own (CPU) factor is kept alive by the same contexts
        for problem in (system.problem, system._bound):
            if problem is None or not problem.factorised:
                continue
            el = problem.elimination
            if el.factor is not None:
                el.factor._solver = None


def resolve_device(device) -> torch.device:
    """A torch device from ``"cpu"``, ``"cuda"``, ``"cuda:N"`` or a :class:`torch.device`.

    A CUDA request without a visible CUDA device raises a one-line :class:`InputError`
    naming the remedy.

    Examples
    --------
    >>> resolve_device("cpu")
    device(type='cpu')
    """
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError):
        raise InputError(f"unknown device {device!r} (use 'cpu', 'cuda' or 'cuda:N')") from None
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            raise InputError(f"device={str(device)!r}: torch sees no CUDA device; "
                             + _CUDA_REMEDY)
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise InputError(f"device={str(device)!r}: only {torch.cuda.device_count()} CUDA "
                             "device(s) are visible")
    elif dev.type != "cpu":
        raise InputError(f"device={str(device)!r}: only 'cpu' and 'cuda' are supported")
    return dev


def check_dtype(dtype) -> torch.dtype:
    """float32 or float64, else a one-line :class:`InputError`."""
    if dtype not in (torch.float32, torch.float64):
        raise InputError(f"dtype {dtype} is not supported (use torch.float32 or torch.float64)")
    return dtype


# -- rotations -----------------------------------------------------------------------


def _svd_rotation(S: torch.Tensor):
    """``R = V D U^T`` maximising ``tr(R S)``, with ``D = diag(1, 1, det(V U^T))``.

    Returns R, V and the signed singular values ``s = D Sigma`` (the eigenvalues of the
    symmetric ``R S = V diag(s) V^T``).
    """
    U, sig, Vh = torch.linalg.svd(S)
    V = Vh.transpose(-1, -2)
    det = torch.linalg.det(V @ U.transpose(-1, -2))
    d = torch.ones_like(sig)
    d[..., 2] = torch.where(det < 0, -1.0, 1.0).to(sig.dtype)
    R = (V * d[..., None, :]) @ U.transpose(-1, -2)
    return R, V, sig * d


class _PolarRotation(torch.autograd.Function):
    """Best-fit rotation of covariances with the closed-form derivative of the polar factor.

    At the optimum ``Y = R S`` is symmetric. A change ``dS`` moves ``R`` by ``dR = W R``
    with ``W`` skew; keeping ``R S`` symmetric gives, in the frame of ``V`` (where
    ``Y = diag(s)``) and with ``Z = V^T R dS V``::

        W_ij = (Z_ji - Z_ij) / (s_i + s_j)

    The transpose of that map is the backward below. ``s_i + s_j`` vanishes only for a
    rank-one ``S`` (or a reflected neighbourhood with ``sigma_2 = sigma_3``), where the
    optimal rotation is not unique: those terms are dropped (the rotation is held fixed in
    that direction).
    """

    @staticmethod
    def forward(ctx, S):
        R, V, s = _svd_rotation(S)
        ctx.save_for_backward(R, V, s)
        return R

    @staticmethod
    def backward(ctx, gR):
        R, V, s = ctx.saved_tensors
        Vt = V.transpose(-1, -2)
        H = Vt @ gR @ R.transpose(-1, -2) @ V
        den = s[..., :, None] + s[..., None, :]
        tiny = torch.finfo(s.dtype).eps * 64 * s[..., :1, None].abs().clamp_min(
            torch.finfo(s.dtype).tiny)
        den = torch.where(den.abs() > tiny, den, torch.full_like(den, float("inf")))
        K = (H.transpose(-1, -2) - H) / den
        return R.transpose(-1, -2) @ V @ K @ Vt


def best_rotations(S: torch.Tensor) -> torch.Tensor:
    """Rotations of covariances ``(..., 3, 3)`` without a derivative (the forward loop).

    On CPU tensors the compiled kernel of :mod:`arapkit.arap.rotations` (vectorised across
    matrices; ~5-10x faster than ``torch.linalg.svd``, which makes one LAPACK call per
    3x3 matrix); on CUDA the batched SVD of :func:`_svd_rotation`. Both return the same
    rotations (to round-off) wherever the optimum is unique.

    Examples
    --------
    >>> import torch
    >>> S = torch.diag(torch.tensor([3.0, 2.0, -1.0]))[None]
    >>> best_rotations(S)[0].diag().tolist()  # det S < 0, yet a rotation: the identity
    [1.0, 1.0, 1.0]
    """
    if S.device.type == "cpu":
        from ..rotations import fit_rotations as fit_numpy

        R = fit_numpy(S.detach().reshape(-1, 3, 3).to(torch.float64).numpy())
        return torch.from_numpy(R).to(S.dtype).reshape(S.shape)
    return _svd_rotation(S.detach())[0]


def fit_rotations(S: torch.Tensor) -> torch.Tensor:
    """Rotations ``R_k = argmax tr(R S_k)`` for covariances ``(..., 3, 3)``, differentiable.

    Examples
    --------
    >>> import torch
    >>> S = torch.diag(torch.tensor([3.0, 2.0, 1.0], dtype=torch.float64))
    >>> bool(torch.allclose(fit_rotations(S[None]), torch.eye(3, dtype=torch.float64)))
    True
    """
    return _PolarRotation.apply(S)


# -- the problem on a device ---------------------------------------------------------


def _reduced_matrix(problem: ARAPProblem) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """COO (rows, cols, values) of ``A_ff``, the reduced system of the problem's energy."""
    el = problem.elimination
    E, w = problem.edges, problem.energy.system_w
    sa, sb = el.slot[E[:, 0]], el.slot[E[:, 1]]
    nf = len(el.free)
    ff = (sa >= 0) & (sb >= 0)
    diag = (np.bincount(sa[sa >= 0], w[sa >= 0], nf) + np.bincount(sb[sb >= 0], w[sb >= 0], nf))
    rows = np.concatenate([sa[ff], sb[ff], np.arange(nf)])
    cols = np.concatenate([sb[ff], sa[ff], np.arange(nf)])
    vals = np.concatenate([-w[ff], -w[ff], diag])
    return rows, cols, vals


class TorchSystem:
    """One :class:`ARAPProblem` as torch tensors on one device and dtype.

    The energy's structure is converted at construction; the handle-dependent part
    (free/constrained split, ``A_fc``, ``A_ff`` and its factor) by :meth:`bind`, on first
    use. All positions are ``(B, n, 3)`` in the problem's internal numbering.

    Examples
    --------
    >>> import torch
    >>> from arapkit.mesh.shapes import bar
    >>> p = ARAPProblem.from_mesh(bar(), [0, 1])
    >>> ts = TorchSystem(p, "cpu", torch.float64)
    >>> P = torch.as_tensor(p.vertices)[None]
    >>> float(ts.energy(P, ts.rotations(P)).abs().max()) < 1e-20  # rest: zero energy
    True
    """

    def __init__(self, problem: ARAPProblem, device="cpu", dtype=torch.float64) -> None:
        self.device = resolve_device(device)
        self.dtype = check_dtype(dtype)
        en = problem.energy
        nbh = en.nbh
        n = problem.n_vertices
        if en.n_owners != n:
            raise InputError(f"{problem.name}: the torch backend fits one rotation per vertex; "
                             "this energy has rotations of its own past them (a ring scale "
                             "below 1): use device='cpu'")
        self.n = n

        def t(a, dt=None):
            return torch.as_tensor(np.ascontiguousarray(a), device=self.device,
                                   dtype=dt or self.dtype)

        long = torch.int64
        sizes = np.diff(nbh.disk_ptr)
        self.disk_k = t(np.repeat(np.arange(n), sizes), long)
        self.disk_v = t(nbh.disk_idx, long)
        self.disk_coef = t(nbh.disk_coef)
        # C[3k + a, v] = c_kv[a]: covariances are C P, right-hand sides C^T R
        rows = (self.disk_k[:, None] * 3 + torch.arange(3, device=self.device)).reshape(-1)
        cols = self.disk_v[:, None].expand(-1, 3).reshape(-1)
        self.C = torch.sparse_coo_tensor(torch.stack([rows, cols]), self.disk_coef.reshape(-1),
                                         (3 * n, n), check_invariants=False).coalesce()
        self.CT = self.C.t().coalesce()
        E = problem.edges
        self.edges = t(E, long)
        self.system_w = t(en.system_w)
        # the Laplacian of D_e, for the energy's quadratic term
        a, b = self.edges[:, 0], self.edges[:, 1]
        self.L = torch.sparse_coo_tensor(
            torch.stack([torch.cat([a, b, a, b]), torch.cat([b, a, a, b])]),
            torch.cat([-self.system_w, -self.system_w, self.system_w, self.system_w]),
            (n, n), check_invariants=False).coalesce()
        # the energy's entries (k, edge) with their weights, for eq. 1 as a sum of squares
        esz = np.diff(nbh.edge_ptr)
        self.ent_k = t(np.repeat(np.arange(n), esz), long)
        eid = nbh.edge_idx.astype(np.int64)
        self.ent_i = t(E[eid, 0], long)
        self.ent_j = t(E[eid, 1], long)
        self.ent_w = t(problem.w[eid] if en.entry_w is None else en.entry_w)
        P0 = problem.vertices
        self.ent_rest = t(P0[E[eid, 0]] - P0[E[eid, 1]])
        if en.coupling is not None:
            ptr, idx, coef = en.coupling
            self.rc_k = t(np.repeat(np.arange(n), np.diff(ptr)), long)
            self.rc_j = t(idx, long)
            self.rc_w = t(coef)
        else:
            self.rc_k = None
        self.rest_term = float(en.rest_term)
        self.perm = t(problem.perm, long)
        self.iperm = t(problem.iperm, long)
        self.energy_obj = en
        self.problem = problem
        self._bound: ARAPProblem | None = None
        self._factor = None
        _LIVE.add(self)

    # -- constraints and the factor ------------------------------------------------
    def bind(self, problem: ARAPProblem) -> TorchSystem:
        """Use ``problem``'s handles (same energy); factorises ``A_ff`` on the device once."""
        if problem is self._bound:
            return self
        if problem.energy is not self.energy_obj:
            raise ValueError("bind: the problem has another energy; build a new TorchSystem")
        from cholespy import CholeskySolverD, CholeskySolverF, MatrixType

        from ..constraints import quiet_c_output

        el = problem.elimination  # validates and factorises on the CPU (errors come from here)
        long = torch.int64
        dev, dt = self.device, self.dtype
        self.free = torch.as_tensor(el.free, device=dev, dtype=long)
        self.cons = torch.as_tensor(el.constrained, device=dev, dtype=long)
        self.nf, self.nc = len(el.free), len(el.constrained)
        fc = el.A_fc.tocoo()
        self.fc_row = torch.as_tensor(fc.row.astype(np.int64), device=dev)
        self.fc_col = torch.as_tensor(fc.col.astype(np.int64), device=dev)
        self.fc_val = torch.as_tensor(fc.data, device=dev, dtype=dt)
        rows, cols, vals = _reduced_matrix(problem)
        self.ff_row = torch.as_tensor(rows.astype(np.int64), device=dev)
        self.ff_col = torch.as_tensor(cols.astype(np.int64), device=dev)
        self.ff_val = torch.as_tensor(vals, device=dev, dtype=dt)
        self.anchors = torch.as_tensor(problem.caller_graph.vertices[problem.fixed_extra],
                                       device=dev, dtype=dt)
        self.n_handles = len(problem.handles)
        self.b_rest_free = torch.as_tensor(problem.b_rest[el.free], device=dev, dtype=dt)
        self._factor = None
        if self.nf:
            Solver = CholeskySolverF if dt == torch.float32 else CholeskySolverD
            with quiet_c_output():  # already known to be positive definite (el above)
                self._factor = Solver(
                    self.nf,
                    torch.as_tensor(rows.astype(np.int32), device=dev),
                    torch.as_tensor(cols.astype(np.int32), device=dev),
                    torch.as_tensor(vals, device=dev, dtype=torch.float64),
                    MatrixType.COO,
                )
        self._bound = problem
        return self

    def solve(self, rhs: torch.Tensor) -> torch.Tensor:
        """``A_ff^{-1} rhs`` for ``(B, nf, 3)``: all poses in one triangular solve.

        Each pose's 3 columns go in as a block of 4 (with a zero column): CHOLMOD solves
        right-hand sides 4 at a time, with another rounding than for 1-3 columns, so
        blocks aligned to the poses give every pose of a batch exactly its single solve.
        (On CUDA cholespy takes at most 128 columns per call; more are split, also on
        pose boundaries.)
        """
        B = rhs.shape[0]
        cols = torch.cat([rhs, rhs.new_zeros(B, self.nf, 1)], dim=2)
        cols = cols.permute(1, 0, 2).reshape(self.nf, _BLOCK * B).contiguous()
        out = torch.empty_like(cols)
        if self._factor is not None:
            step = _CUDA_MAX_RHS if self.device.type == "cuda" else cols.shape[1]
            if step >= cols.shape[1]:
                self._factor.solve(cols, out)
            else:
                for c0 in range(0, cols.shape[1], step):
                    blk = cols[:, c0:c0 + step].contiguous()
                    res = torch.empty_like(blk)
                    self._factor.solve(blk, res)
                    out[:, c0:c0 + step] = res
        return out.reshape(self.nf, B, _BLOCK)[:, :, :3].permute(1, 0, 2)

    def apply_A(self, x: torch.Tensor) -> torch.Tensor:
        """``A_ff x`` for ``(B, nf, 3)``."""
        out = torch.zeros_like(x)
        return out.index_add_(1, self.ff_row, self.ff_val[:, None] * x[:, self.ff_col])

    def fixed_rhs(self, C: torch.Tensor) -> torch.Tensor:
        """``A_fc C`` for constrained positions ``(B, nc, 3)``."""
        out = torch.zeros(C.shape[0], self.nf, 3, dtype=C.dtype, device=C.device)
        return out.index_add_(1, self.fc_row, self.fc_val[:, None] * C[:, self.fc_col])

    def apply_A_fc_T(self, y: torch.Tensor) -> torch.Tensor:
        """``A_fc^T y`` for ``(B, nf, 3)``."""
        out = torch.zeros(y.shape[0], self.nc, 3, dtype=y.dtype, device=y.device)
        return out.index_add_(1, self.fc_col, self.fc_val[:, None] * y[:, self.fc_row])

    def constrained(self, T: torch.Tensor) -> torch.Tensor:
        """Positions of the constrained vertices: handle targets ``(B, h, 3)``, then anchors."""
        if len(self.anchors) == 0:
            return T
        return torch.cat([T, self.anchors.expand(T.shape[0], -1, -1)], dim=1)

    def assemble(self, x: torch.Tensor, C: torch.Tensor) -> torch.Tensor:
        """Full positions ``(B, n, 3)`` from free ``x`` and constrained ``C``."""
        P = x.new_empty(x.shape[0], self.n, 3)
        return P.index_copy(1, self.free, x).index_copy(1, self.cons, C)

    # -- the local step -------------------------------------------------------------
    def covariances(self, P: torch.Tensor, R_prev: torch.Tensor | None = None) -> torch.Tensor:
        """``S_k = sum_v c_kv p'_v^T`` for ``(B, n, 3)`` -> ``(B, n, 3, 3)``.

        One sparse product ``C P`` for the whole batch (C is ``(3n, n)``, row ``3k + a``
        holding ``c_kv[a]``). The positions are centred first: the ``c_kv`` of a
        neighbourhood sum to zero, so this is exact and keeps float32 sums well conditioned
        far from the origin. A rotation coupling adds ``sum_j c_kj R_prev[j]^T``.
        """
        B = P.shape[0]
        Pc = _centred(P).permute(1, 0, 2).reshape(self.n, 3 * B)
        S = torch.sparse.mm(self.C, Pc).reshape(self.n, 3, B, 3).permute(2, 0, 1, 3)
        if self.rc_k is not None and R_prev is not None:
            RT = R_prev[:, self.rc_j].transpose(-1, -2) * self.rc_w[None, :, None, None]
            S = S.index_add(1, self.rc_k, RT)
        return S

    def rotations(self, P: torch.Tensor) -> torch.Tensor:
        """Best-fit rotations ``(B, n, 3, 3)`` of positions ``(B, n, 3)``."""
        return fit_rotations(self.covariances(P))

    def rhs(self, R: torch.Tensor) -> torch.Tensor:
        """``b_v = sum_k R_k c_kv`` for rotations ``(B, n, 3, 3)`` -> ``(B, n, 3)``.

        One sparse product ``C^T R`` for the whole batch.
        """
        B = R.shape[0]
        Rr = R.permute(1, 3, 0, 2).reshape(3 * self.n, 3 * B)
        return torch.sparse.mm(self.CT, Rr).reshape(self.n, B, 3).permute(1, 0, 2)

    def vertex_energy(self, P: torch.Tensor, R: torch.Tensor) -> torch.Tensor:
        """Each neighbourhood's term ``(B, n)``, summed edge by edge (a sum of squares)."""
        d = (P[:, self.ent_i] - P[:, self.ent_j]) - (
            R[:, self.ent_k] @ self.ent_rest[None, :, :, None])[..., 0]
        per = self.ent_w * (d * d).sum(-1)
        return P.new_zeros(P.shape[0], self.n).index_add_(1, self.ent_k, per)

    def energy(self, P: torch.Tensor, R: torch.Tensor) -> torch.Tensor:
        """Eq. 1 at positions ``P`` and rotations ``R``: ``(B,)``."""
        return self.vertex_energy(P, R).sum(-1)

    def energy_expanded(self, P: torch.Tensor, R: torch.Tensor, S: torch.Tensor) -> torch.Tensor:
        """Eq. 1 as ``sum_e D_e |e'|^2 + rest - 2 sum_k tr(R_k S_k)`` (the loop's cheap form)."""
        B = P.shape[0]
        # sum_e D_e |e'|^2 = tr(P^T L P): one sparse product (gathers are slow on CPU);
        # centring is exact (L 1 = 0) and spares float32 the cancellation far from the origin
        Pc = _centred(P).permute(1, 0, 2).reshape(self.n, 3 * B)
        quad = (Pc * torch.sparse.mm(self.L, Pc)).reshape(self.n, B, 3).transpose(0, 1)
        tr = R * S.transpose(-1, -2)
        return _pose_sums(quad) + self.rest_term - 2.0 * _pose_sums(tr)


def _per_pose(f, X: torch.Tensor) -> torch.Tensor:
    """``f`` applied to each pose ``X[b:b+1]`` alone, concatenated.

    For reductions over a pose: torch splits a long sum into parts by the shape of the
    whole tensor (and the threads), so the same pose summed within a batch would be
    rounded otherwise than alone, and a stopping test near round-off would stop a pose
    at another iteration in a batch than in its single solve.
    """
    if X.shape[0] == 1:
        return f(X)
    return torch.cat([f(X[b:b + 1]) for b in range(X.shape[0])])


def _centred(P: torch.Tensor) -> torch.Tensor:
    """Positions ``(B, n, 3)`` minus each pose's centroid (rounded as for the pose alone)."""
    return P - _per_pose(lambda x: x.mean(dim=1, keepdim=True), P)


def _pose_sums(X: torch.Tensor) -> torch.Tensor:
    """``(B,)`` sums of all entries of each pose of ``X`` (rounded as for the pose alone)."""
    return _per_pose(lambda x: x.reshape(1, -1).sum(dim=1), X)


# -- the backend behind the loop -----------------------------------------------------


class TorchBackend:
    """:class:`~arapkit.arap.backends.cpu.CPUBackend`'s interface on torch tensors (any device).

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.mesh.shapes import bar
    >>> p = ARAPProblem.from_mesh(bar(), [0])
    >>> be = TorchBackend(p, "cpu")
    >>> R = np.empty((p.n_vertices, 3, 3))
    >>> abs(be.local(p.vertices.copy(), R)) < 1e-12  # rest shape: zero energy
    True
    """

    name = "torch"

    def __init__(self, problem: ARAPProblem, device="cpu", dtype=torch.float64) -> None:
        self.problem = problem
        self.system = TorchSystem(problem, device, dtype)
        self.rest_term = problem.energy.rest_term
        self.nonneg = bool((problem.w >= 0).all())
        self._b: torch.Tensor | None = None

    def bind(self, problem: ARAPProblem) -> TorchBackend:
        """Use ``problem`` (same energy, possibly other handles); factorises if needed."""
        self.problem = problem
        self.system.bind(problem)
        return self

    def _t(self, a: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(a, device=self.system.device, dtype=self.system.dtype)

    @torch.no_grad()
    def local(self, P: np.ndarray, R: np.ndarray, R_prev: np.ndarray | None = None) -> float:
        """Fit rotations to P (into R), prepare the right-hand side; return E(P, R)."""
        ts = self.system
        Pt = self._t(P)[None]
        Rp = self._t(R_prev)[None] if R_prev is not None and len(R_prev) else None
        S = ts.covariances(Pt, Rp)
        Rt = best_rotations(S)
        R[:] = Rt[0].cpu().numpy()
        self._b = ts.rhs(Rt)[0]
        # a rotation coupling's terms are in S and its constant in rest_term, as on the CPU
        E = float(ts.energy_expanded(Pt, Rt, S)[0])
        return max(E, 0.0) if self.nonneg else E

    @torch.no_grad()
    def rhs(self, fixed_rhs: np.ndarray, out: np.ndarray) -> None:
        """Right-hand side of the free vertices from the last local step."""
        ts = self.system
        out[:] = (self._b[ts.free] - self._t(fixed_rhs)).cpu().numpy()

    @torch.no_grad()
    def vertex_rhs(self, out: np.ndarray) -> np.ndarray:
        """``b_v = sum_k R_k c_kv`` of every vertex from the last local step, into ``out``."""
        out[:] = self._b.cpu().numpy()
        return out

    @torch.no_grad()
    def solve(self, rhs: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Global step: ``A_ff^{-1} rhs``."""
        out[:] = self.system.solve(self._t(rhs)[None])[0].cpu().numpy()
        return out

    @staticmethod
    def scatter(X: np.ndarray, idx: np.ndarray, P: np.ndarray) -> None:
        """``P[idx[i]] = X[i]``."""
        P[idx] = X

    @staticmethod
    def gather(P: np.ndarray, idx: np.ndarray, scale: float) -> np.ndarray:
        """``P[idx] * scale``, a new array."""
        return P[idx] * scale

    @torch.no_grad()
    def vertex_energy(self, P: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Each vertex's term of the energy (internal numbering)."""
        ts = self.system
        Rt = self._t(R)[None]
        out = ts.vertex_energy(self._t(P)[None], Rt)[0]
        if ts.rc_k is not None:
            d = ((Rt[0, ts.rc_k] - Rt[0, ts.rc_j]) ** 2).sum(dim=(-1, -2))
            out = out.index_add(0, ts.rc_k, ts.rc_w * d)
        return out.cpu().numpy().astype(np.float64)
