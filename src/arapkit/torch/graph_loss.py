"""The ARAP loss on a point set with a kNN or given graph: :class:`GraphARAPLoss`.

For positions ``X`` of n points, rest positions ``P`` and the terms ``(k, i, j, w)`` of
:mod:`arapkit.torch.neighbourhoods` (the r-rings ``N(k, r_k)`` of an undirected graph, or
each point's own k nearest neighbours)::

    E(X) = sum_k sum_{(i, j) in N(k)} w_ij |(x_i - x_j) - R_k (p_i - p_j)|^2

with ``R_k`` the best-fit rotation of each neighbourhood (eq. 1 of Chen et al. 2017 on the
graph), given rotations (e.g. each Gaussian's own), and ``penalty="norm"`` /
``reduction="mean"`` for the unsquared, averaged form of Dynamic 3D Gaussians' rigidity
loss. Memory is O(number of terms), about ``2 k n`` for a symmetrised kNN graph at r = 1:
never an ``n x n`` matrix.

Two implementations, one answer: compiled kernels for CPU tensors with detached or given
rotations (:mod:`arapkit.torch.graph_kernels`: energy and gradient in one pass, an autograd
function whose backward scales the saved gradient), and torch operations (gathers and
``index_add``) for CUDA tensors and for rotations differentiated through the SVD.
Details: ``docs/torch.md``.
"""

from __future__ import annotations

import threading

import numpy as np
import torch as _torch

from ..arap.backends.torch_backend import best_rotations, fit_rotations
from ..errors import InputError
from .graph_kernels import gather_rows, graph_energy
from .neighbourhoods import GraphNeighbourhoods, graph_neighbourhoods
from .neighbourhoods import rest_points as checked_points

__all__ = ["GraphARAPLoss", "graph_arap_energy"]

ROTATIONS = ("detached", "differentiated")
PENALTIES = ("squared", "norm")
REDUCTIONS = ("sum", "mean")
BACKENDS = ("auto", "numba", "torch")
#: kNN's k when neither k nor edges is given
DEFAULT_K = 10


def _choice(value, allowed: tuple[str, ...], what: str, name: str) -> str:
    if value not in allowed:
        raise InputError(f"{name}: {what} must be {' or '.join(map(repr, allowed))}, got "
                         f"{value!r}")
    return value


class _CompiledEnergy(_torch.autograd.Function):
    """E per pose from the compiled kernels; the backward scales the saved ``dE/dX``
    (and ``dE/dR`` for given rotations). Once differentiable: for second derivatives (at
    fixed rotations) use the torch implementation (``backend="torch"``)."""

    @staticmethod
    def forward(ctx, X, R, loss: GraphARAPLoss, rest: np.ndarray, batched: bool):
        ctx.batched = batched
        nbh = loss.neighbourhoods
        perm, iperm = nbh.perm, loss.iperm_np
        B, n = X.shape[:2]
        # one pass each way between the caller's numbering and dtype and the kernels'
        Xs = X.detach().cpu().numpy()
        Xn = np.empty((B, n, 3))
        for b in range(B):
            if gather_rows(Xs[b], perm, Xn[b]):
                loss.refuse_non_finite(X, batched=ctx.batched)
        fit = R is None
        Rs = np.empty((B, n, 3, 3))
        if not fit:
            Rc = R.detach().cpu().numpy().reshape(R.shape[0], n, 9)
            for b in range(B):
                gather_rows(Rc[min(b, len(Rc) - 1)], perm, Rs[b].reshape(n, 9))
        want_gR = not fit and R.requires_grad
        gR = np.empty((B, n, 3, 3)) if want_gR else None
        E = np.empty(B)
        G = np.empty((B, n, 3))
        g = loss.scratch()
        for b in range(B):
            E[b], _ = graph_energy(Xn[b], rest[min(b, len(rest) - 1)], nbh, Rs[b], fit,
                                   loss.penalty == "norm", loss.eps,
                                   None if gR is None else gR[b], G[b], g)
        if loss.reduction == "mean":
            E /= loss.n_terms
            G /= loss.n_terms
            if gR is not None:
                gR /= loss.n_terms
        np_dt = Xs.dtype
        Gc = np.empty((B, n, 3), dtype=np_dt)
        for b in range(B):
            gather_rows(G[b], iperm, Gc[b])
        gRc = None
        if gR is not None:
            gRc = np.empty((B, n, 9), dtype=np_dt)
            for b in range(B):
                gather_rows(gR[b].reshape(n, 9), iperm, gRc[b])
            gRc = _torch.from_numpy(gRc.reshape(B, n, 3, 3))
        ctx.save_for_backward(_torch.from_numpy(Gc), gRc)
        ctx.R_batched = not fit and R.shape[0] > 1
        loss.keep_rotations(Rs, X.dtype)
        return _torch.from_numpy(E).to(X.dtype)

    @staticmethod
    @_torch.autograd.function.once_differentiable
    def backward(ctx, gE):
        G, gR = ctx.saved_tensors
        # a plain loss.backward() sends ones: skip the product (one more thread-pool pass)
        gX = G if bool((gE == 1).all()) else gE[:, None, None] * G
        if gR is None:
            return gX, None, None, None, None
        gRot = gE[:, None, None, None] * gR
        return gX, (gRot if ctx.R_batched else gRot.sum(0, keepdim=True)), None, None, None


class GraphARAPLoss(_torch.nn.Module):
    """ARAP energy of points on a kNN or given graph, with r-rings: an ``nn.Module`` loss.

    The graph, its weights and its r-ring neighbourhoods are built once, here; calling the
    module evaluates ``E(X)`` (see :mod:`arapkit.torch.graph_loss`) for positions ``(n, 3)``
    or a batch ``(B, n, 3)``, in memory O(n k).

    Parameters
    ----------
    rest_points : (n, 3) array or tensor
        The rest shape: the graph's points, and the rest positions ``p`` unless
        ``forward(rest=...)`` gives others.
    k : int, optional
        Neighbours per point of the kNN graph (default 10; not with ``edges``).
    edges : (m, 2) int, optional
        An undirected graph instead (each edge once, no loops).
    weights : "gaussian", "uniform", callable or (m,) array
        Weight of each edge, from its squared rest length ``d2``: ``"gaussian"`` is
        ``exp(-d2 / h^2)`` with ``h`` the mean edge length (scale-free), a callable gets
        ``d2`` as a float64 tensor (Dynamic 3D Gaussians: ``lambda d2: torch.exp(-2000 *
        d2)``); an array (with ``edges``) gives them outright. Finite and >= 0.
    rings : int or (n,) int
        r per point: ``N(k, r_k)`` holds every edge within r_k rings of k (the engine's
        r-ring neighbourhoods on this graph; r = 1: the edges at k).
    symmetric : bool
        The kNN graph's edges symmetrised (an undirected graph: default) or, False, each
        point's own k nearest neighbours only (directed, r = 1: Dynamic 3D Gaussians).
    rotations : "detached" or "differentiated"
        Best-fit rotations held fixed in the backward (ARAP's local step; at the optimum
        this is the exact gradient of ``min_R E``: envelope theorem), or differentiated
        through the batched SVD (the closed-form derivative of the polar factor). With
        ``penalty="squared"`` both give the same gradient; ``"norm"`` needs
        ``"differentiated"`` (its minimising rotations are not the least-squares ones).
    penalty : "squared" or "norm"
        ``w |r|^2`` (ARAP) or ``sqrt(w |r|^2 + eps)`` (Dynamic 3D Gaussians' code).
    reduction : "sum" or "mean"
        The sum over the terms, or their mean (divided by :attr:`n_terms`).
    backend : "auto", "numba" or "torch"
        The compiled CPU kernels (``"auto"`` picks them for CPU tensors with detached or
        given rotations; once differentiable) or torch operations (any device).
    eps : float
        Under the root of ``penalty="norm"`` (D3DGS's 1e-20: a finite gradient at r = 0).

    Examples
    --------
    >>> import torch
    >>> P = torch.rand(200, 3, dtype=torch.float64)
    >>> loss = GraphARAPLoss(P, k=8)
    >>> float(loss(P)) < 1e-20  # the rest shape costs nothing ...
    True
    >>> R = torch.linalg.qr(torch.randn(3, 3, dtype=torch.float64))[0]
    >>> float(loss(P @ R.T + 1.0)) < 1e-20  # ... nor does any rigid motion of it
    True
    >>> X = (P * torch.tensor([1.0, 1.0, 1.5], dtype=torch.float64)).requires_grad_()
    >>> E = loss(X)
    >>> E.backward()
    >>> bool(E > 0) and X.grad.shape == (200, 3)
    True
    """

    def __init__(self, rest_points, k: int | None = None, *, edges=None, weights="gaussian",
                 rings=1, symmetric: bool = True, rotations: str = "detached",
                 penalty: str = "squared", reduction: str = "sum", backend: str = "auto",
                 eps: float = 1e-20) -> None:
        super().__init__()
        name = type(self).__name__
        self.rotations = _choice(rotations, ROTATIONS, "rotations", name)
        self.penalty = _choice(penalty, PENALTIES, "penalty", name)
        self.reduction = _choice(reduction, REDUCTIONS, "reduction", name)
        self.backend = _choice(backend, BACKENDS, "backend", name)
        self.eps = float(eps)
        if not (self.eps >= 0.0 and np.isfinite(self.eps)):
            raise InputError(f"{name}: eps must be finite and >= 0, got {eps!r}")
        if k is not None and edges is not None:
            raise InputError(f"{name}: give k (a kNN graph) or edges, not both")
        P = checked_points(rest_points, name)
        self.neighbourhoods: GraphNeighbourhoods = graph_neighbourhoods(
            P, DEFAULT_K if k is None and edges is None else k, edges, weights, rings,
            symmetric, name)
        nb = self.neighbourhoods
        self.iperm_np = np.empty(nb.n, dtype=np.int64)
        self.iperm_np[nb.perm] = np.arange(nb.n)
        self._rest = np.ascontiguousarray(P[nb.perm])[None]  # internal numbering
        for key, value in (("rest_points", P), ("perm", nb.perm), ("iperm", self.iperm_np),
                           ("term_i", nb.ei.astype(np.int64)),
                           ("term_j", nb.ej.astype(np.int64)), ("term_owner", nb.owner),
                           ("term_w", nb.w)):
            self.register_buffer(key, _torch.from_numpy(np.ascontiguousarray(value)),
                                 persistent=False)
        self._rotations: _torch.Tensor | tuple | None = None
        self._batched = False  # whether the last call's X was a batch
        self._scratch: dict[int, np.ndarray] = {}  # per thread: calls may run concurrently

    @property
    def last_rotations(self) -> _torch.Tensor | None:
        """The rotations ``R_k`` of the last call (fitted or given): ``(n, 3, 3)``, or
        ``(B, n, 3, 3)`` after a batch."""
        if isinstance(self._rotations, tuple):  # the kernels' (internal order, float64)
            Rs, dtype = self._rotations
            B, n = Rs.shape[:2]
            out = np.empty((B, n, 9), dtype=np.float64)
            for b in range(B):
                gather_rows(Rs[b].reshape(n, 9), self.iperm_np, out[b])
            self._rotations = _torch.from_numpy(out.reshape(B, n, 3, 3)).to(dtype)
        R = self._rotations
        return R if R is None or self._batched else R[0]

    def keep_rotations(self, R, dtype: _torch.dtype | None = None) -> None:
        """Record the rotations ``(B, n, 3, 3)`` of this call: a tensor in the caller's
        order, or the kernels' float64 array in the internal order (converted when asked)."""
        self._rotations = R if dtype is None else (R, dtype)

    def scratch(self) -> np.ndarray:
        """The kernels' ``(M, 3)`` scratch, kept between calls (one per thread)."""
        key = threading.get_ident()
        if key not in self._scratch:
            self._scratch[key] = np.empty((self.n_terms, 3))
        return self._scratch[key]

    def __getstate__(self) -> dict:
        # copies and pickles leave the scratch behind (50 MB at 100K points)
        return {**self.__dict__, "_scratch": {}}

    @property
    def n_points(self) -> int:
        """n."""
        return self.neighbourhoods.n

    @property
    def n_terms(self) -> int:
        """The number of terms ``(k, i, j)``: ``reduction="mean"`` divides by it."""
        return self.neighbourhoods.n_terms

    @property
    def edges(self) -> np.ndarray | None:
        """The undirected graph ``(m, 2)`` (None for a directed kNN graph)."""
        return self.neighbourhoods.edges

    @property
    def edge_weights(self) -> np.ndarray | None:
        """Its weights ``(m,)`` (None for a directed kNN graph)."""
        return self.neighbourhoods.edge_w

    def extra_repr(self) -> str:
        nb = self.neighbourhoods
        graph = (f"edges={len(nb.edges)}" if nb.edges is not None else "directed kNN")
        return (f"n={nb.n}, {graph}, terms={nb.n_terms}, rings={int(nb.rings.min())}.."
                f"{int(nb.rings.max())}, rotations={self.rotations!r}, penalty="
                f"{self.penalty!r}, reduction={self.reduction!r}")

    def forward(self, X: _torch.Tensor, rest=None, R: _torch.Tensor | None = None
                ) -> _torch.Tensor:
        """The loss: shape ``()`` for ``X`` of shape ``(n, 3)``, ``(B,)`` for ``(B, n, 3)``.

        Parameters
        ----------
        X : (n, 3) or (B, n, 3) float32/float64 tensor, any device
        rest : (n, 3) or (B, n, 3), optional
            Rest positions for this call (e.g. the previous frame), instead of
            ``rest_points``; the graph and weights stay. Not differentiated.
        R : (n, 3, 3) or (B, n, 3, 3) tensor, optional
            Given rotations ``R_k`` instead of fitted ones (differentiable).
        """
        name = type(self).__name__
        Xb, batched = self._check_X(X, name)
        self._batched = batched
        P = self._rest_for(rest, Xb, name)
        Rb = None if R is None else self._check_R(R, Xb, name)
        if Rb is None and self.penalty == "norm" and self.rotations == "detached":
            # the fitted rotations minimise the squared sum, not this one: holding them fixed
            # would give a gradient that is not the loss's
            raise InputError(f"{name}: penalty='norm' with fitted rotations needs "
                             "rotations='differentiated' (the least-squares rotations do not "
                             "minimise it), or give the rotations R")
        use_numba = self.backend == "numba" or (
            self.backend == "auto" and Xb.device.type == "cpu"
            and (self.rotations == "detached" or Rb is not None))
        if use_numba:
            if Xb.device.type != "cpu":
                raise InputError(f"{name}: backend='numba' runs on CPU tensors; X is on "
                                 f"{Xb.device} (use backend='torch' or 'auto')")
            if self.rotations == "differentiated" and Rb is None:
                raise InputError(f"{name}: backend='numba' holds the fitted rotations fixed; "
                                 "rotations='differentiated' needs backend='torch' or 'auto'")
            E = _CompiledEnergy.apply(Xb, Rb, self, P, batched)  # checks X is finite
        else:
            if not bool(_torch.isfinite(Xb.detach()).all()):
                self.refuse_non_finite(Xb, batched)
            E = self._torch_energy(Xb, _torch.from_numpy(P).to(Xb), Rb)
        return E if batched else E[0]

    # -- checks ----------------------------------------------------------------------
    def _check_X(self, X, name: str) -> tuple[_torch.Tensor, bool]:
        n = self.n_points
        if not isinstance(X, _torch.Tensor):
            raise InputError(f"{name}: X must be a torch.Tensor of shape ({n}, 3) or "
                             f"(B, {n}, 3), got {type(X).__name__}")
        if X.ndim not in (2, 3) or tuple(X.shape[-2:]) != (n, 3) or X.shape[0] == 0:
            raise InputError(f"{name}: X must have shape ({n}, 3) or (B, {n}, 3), got "
                             f"{tuple(X.shape)}")
        if X.dtype not in (_torch.float32, _torch.float64):
            raise InputError(f"{name}: X has dtype {X.dtype} (use torch.float32 or "
                             "torch.float64)")
        batched = X.ndim == 3
        return (X if batched else X[None]), batched

    def refuse_non_finite(self, Xb: _torch.Tensor, batched: bool) -> None:
        """The one-line error for positions ``(B, n, 3)`` with a non-finite entry."""
        ok = _torch.isfinite(Xb.detach()).all(dim=-1)
        b, i = (int(v) for v in _torch.nonzero(~ok)[0])
        raise InputError(f"{type(self).__name__}: X: {f'pose {b}, ' if batched else ''}point "
                         f"{i} is not finite")

    def _rest_for(self, rest, Xb: _torch.Tensor, name: str) -> np.ndarray:
        """Rest positions ``(1 or B, n, 3)`` float64 for this call, internal numbering."""
        if rest is None:
            return self._rest
        if hasattr(rest, "detach"):
            rest = rest.detach().cpu().numpy()
        Pr = np.asarray(rest, dtype=np.float64)
        n, B = self.n_points, Xb.shape[0]
        if Pr.shape == (n, 3):
            Pr = Pr[None]
        if Pr.shape not in ((1, n, 3), (B, n, 3)):
            raise InputError(f"{name}: rest must have shape ({n}, 3) or ({B}, {n}, 3), got "
                             f"{Pr.shape}")
        bad = ~np.isfinite(Pr).all(axis=-1)
        if bad.any():
            b, i = np.argwhere(bad)[0]
            raise InputError(f"{name}: rest: point {int(i)} is not finite")
        return np.ascontiguousarray(Pr[:, self.neighbourhoods.perm])

    def _check_R(self, R, Xb: _torch.Tensor, name: str) -> _torch.Tensor:
        n, B = self.n_points, Xb.shape[0]
        if not isinstance(R, _torch.Tensor):
            raise InputError(f"{name}: R must be a torch.Tensor of shape ({n}, 3, 3), got "
                             f"{type(R).__name__}")
        Rb = R if R.ndim == 4 else R[None]
        if Rb.ndim != 4 or tuple(Rb.shape[1:]) != (n, 3, 3) or Rb.shape[0] not in (1, B):
            raise InputError(f"{name}: R must have shape ({n}, 3, 3) or ({B}, {n}, 3, 3), "
                             f"got {tuple(R.shape)}")
        if Rb.dtype != Xb.dtype or Rb.device != Xb.device:
            raise InputError(f"{name}: R ({Rb.dtype}, {Rb.device}) must have X's dtype and "
                             f"device ({Xb.dtype}, {Xb.device})")
        ok = _torch.isfinite(Rb.detach()).flatten(-2).all(dim=-1)
        if not bool(ok.all()):
            raise InputError(f"{name}: R: the rotation of point "
                             f"{int(_torch.nonzero(~ok)[0][1])} is not finite")
        return Rb

    # -- torch operations ----------------------------------------------------------------
    def _torch_energy(self, X: _torch.Tensor, P: _torch.Tensor,
                      R: _torch.Tensor | None) -> _torch.Tensor:
        """E per pose with gathers and ``index_add`` (autograd throughout); ``P`` is in the
        internal numbering, ``X`` and ``R`` in the caller's."""
        dev, dt = X.device, X.dtype
        perm = self.perm.to(dev)
        X = X[:, perm]
        if R is not None:
            R = R[:, perm]
        ei, ej = self.term_i.to(dev), self.term_j.to(dev)
        owner, w = self.term_owner.to(dev), self.term_w.to(device=dev, dtype=dt)
        B, n = X.shape[0], self.n_points
        D = X[:, ei] - X[:, ej]  # (B, M, 3)
        d = P[:, ei] - P[:, ej]  # (1 or B, M, 3), rest: no gradient
        if R is None:
            # S_k = sum_t w d D^T: one index_add of the (B, M, 9) outer products (faster on
            # CPU than three of (B, M, 3): 220 against 385 ms at 100K points, k = 20)
            outer = ((w[:, None] * d)[..., :, None] * D[..., None, :]).reshape(B, -1, 9)
            S = X.new_zeros(B, n, 9).index_add(1, owner, outer).reshape(B, n, 3, 3)
            if self.rotations == "differentiated":
                R = fit_rotations(S)
            else:
                with _torch.no_grad():
                    R = best_rotations(S)
        self.keep_rotations(R.detach()[:, self.iperm.to(dev)])
        q = D - (R[:, owner] @ d[..., None])[..., 0]
        s = (q * q).sum(-1)
        term = _torch.sqrt(w * s + self.eps) if self.penalty == "norm" else w * s
        E = term.sum(-1)
        return E / self.n_terms if self.reduction == "mean" else E


def graph_arap_energy(X: _torch.Tensor, rest_points, k: int | None = None, *, edges=None,
                      weights="gaussian", rings=1, symmetric: bool = True,
                      rotations: str = "detached", penalty: str = "squared",
                      reduction: str = "sum", rest=None,
                      R: _torch.Tensor | None = None) -> _torch.Tensor:
    """The graph ARAP loss in one call (builds the graph each time: in a training loop
    build a :class:`GraphARAPLoss` once instead).

    Parameters are those of :class:`GraphARAPLoss` and of its ``forward``.

    Examples
    --------
    >>> import torch
    >>> P = torch.rand(100, 3, dtype=torch.float64)
    >>> float(graph_arap_energy(P * 2.0, P, k=6, weights="uniform")) > 0
    True
    """
    loss = GraphARAPLoss(rest_points, k, edges=edges, weights=weights, rings=rings,
                         symmetric=symmetric, rotations=rotations, penalty=penalty,
                         reduction=reduction)
    return loss(X, rest=rest, R=R)
