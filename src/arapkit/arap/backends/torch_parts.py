"""Rigid parts in the PyTorch layer: the solve on the CPU engine, its implicit derivative here.

:class:`arapkit.torch.ARAPLayer` with rigid parts solves each pose with the loop of
:mod:`arapkit.arap.grouped` (exact parts, float64) and differentiates the converged solution
implicitly, as the layer does without parts. The unknowns at the solution are ``z``: the
free rows ``y`` (free vertices and free parts' centres) and a small rotation per moving
part (3 angles; 1 for a hinge, about its axis), at which the shape is ``X(z, T)``:

* free vertices ``y``; handles ``T``; anchors at rest;
* a free part ``exp([th]x) R_P a_v + y_c``, a pivot ``exp([th]x) R_P a_v + T_c``, a hinge
  turned about its axis through ``T_c`` (the axis follows ``T``), a fixed part the best
  rigid fit to its handles ``T_h`` (differentiable through the polar factor).

The reduced energy ``F(z, T) = min_R E(X(z, T), R)`` is stationary in ``z`` at the
solution; its gradient is ``G = (dX/dz)^T (A X - b)`` (up to a factor 2) with ``b`` the
right-hand side of the optimal rotations (the envelope theorem). So ``dL/dT = (dX/dT)^T
gX - (dG/dT)^T mu`` with ``H mu = (dX/dz)^T gX``, ``H = dG/dz`` (symmetric: half the
Hessian of ``F``), solved by conjugate gradients preconditioned by the merged system's
factor and the exact rotation blocks. Every product is an automatic derivative of ``G``.

Only ``exp`` to second order is needed: ``X`` is evaluated at ``th = 0``.
"""

from __future__ import annotations

import numpy as np
import torch

from ..parts import FIXED, FREE, HINGE
from .torch_backend import TorchSystem, fit_rotations

__all__ = ["PartsAdjoint"]


def _skew(w: torch.Tensor) -> torch.Tensor:
    """``[w]x`` for ``(..., 3)``."""
    z = torch.zeros_like(w[..., 0])
    return torch.stack([torch.stack([z, -w[..., 2], w[..., 1]], -1),
                        torch.stack([w[..., 2], z, -w[..., 0]], -1),
                        torch.stack([-w[..., 1], w[..., 0], z], -1)], -2)


def _exp2(K: torch.Tensor) -> torch.Tensor:
    """``exp(K)`` to second order: exact value and first two derivatives at ``K = 0``."""
    eye = torch.eye(3, dtype=K.dtype)
    return eye + K + K @ K / 2


def _align(n0: torch.Tensor, n: torch.Tensor) -> torch.Tensor:
    """The smallest rotation taking unit ``n0`` to unit ``n`` (smooth near ``n = n0``)."""
    v = torch.linalg.cross(n0, n)
    c = (n0 * n).sum(-1)
    K = _skew(v)
    return torch.eye(3, dtype=n.dtype) + K + K @ K / (1 + c)[..., None, None]


class PartsAdjoint:
    """The implicit derivative of one grouped problem's solves (CPU, float64).

    Parameters
    ----------
    problem : arapkit.arap.grouped.GroupedProblem
        With rigid parts; its factor is built (``problem.elimination``).
    """

    def __init__(self, problem) -> None:
        self.problem = problem
        self.ts = TorchSystem(problem, "cpu", torch.float64)
        ps = problem.part_system
        self.ps = ps
        el = ps.elimination
        lay, hold = ps.layout, ps.holds
        t = lambda a: torch.as_tensor(np.ascontiguousarray(a))  # noqa: E731
        self.free, self.cons = t(el.free), t(el.constrained)
        self.rest = t(problem.vertices)
        self.handles = t(problem.iperm[problem.handles])
        self.verts, self.vert_part, self.a = t(lay.verts), t(lay.vert_part), t(ps.a)
        self.kind = hold.kind
        self.centre = t(hold.centre)
        self.axis_end = hold.axis_end
        self.hold_handles = [t(h) for h in hold.handles]
        self.moving = np.flatnonzero(self.kind != FIXED)
        # each moving part's angles in z: 3, or 1 for a hinge
        dof = np.where(self.kind[self.moving] == HINGE, 1, 3)
        self.theta_ptr = np.concatenate([[0], np.cumsum(dof)]).astype(np.int64)

    # -- the shape as a function of the unknowns -------------------------------------------
    def shape(self, y: torch.Tensor, theta: torch.Tensor, T: torch.Tensor,
              R: torch.Tensor) -> torch.Tensor:
        """``X(z, T)`` (internal numbering): ``y`` (nf, 3), ``theta`` (angles), handle
        targets ``T`` (h, 3, the problem's handle order), the parts' rotations ``R`` at the
        solution (P, 3, 3) and its hinge axes (read from ``T`` at the solution)."""
        n = self.rest.shape[0]
        known = torch.zeros(n, 3, dtype=y.dtype)
        known = known.index_copy(0, self.handles, T)
        # anchors (constrained outside the handles) stay at rest
        is_h = torch.zeros(n, dtype=torch.bool)
        is_h[self.handles] = True
        anchors = self.cons[~is_h[self.cons]]
        known = known.index_copy(0, anchors, self.rest[anchors])
        X = known.index_copy(0, self.free, y)
        rot, trans = self._motions(theta, known, R)
        vp = self.vert_part
        # a free part turns about its centre, which is one of the unknowns y
        free = torch.as_tensor(self.kind == FREE)[vp][:, None]
        at = torch.where(free, X[self.centre[vp]], trans[vp])
        return X.index_copy(0, self.verts, (rot[vp] @ self.a[..., None])[..., 0] + at)

    def _motions(self, theta: torch.Tensor, known: torch.Tensor,
                 R: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Each part's rotation and translation (a free part's centre is added after)."""
        k = len(self.kind)
        rots, trans = [], []
        mi = {p: i for i, p in enumerate(self.moving)}
        for p in range(k):
            kind = self.kind[p]
            c = self.centre[p]
            if kind == FIXED:
                h = self.hold_handles[p]
                Xh, Yh = self.rest[h], known[h]
                mx, my = Xh.mean(0), Yh.mean(0)
                H = (Xh - mx).T @ (Yh - my)
                Rp = fit_rotations(H[None])[0]
                # x_v = Rp (v_v - v_c) + (Rp v_c + my - Rp mx)
                rots.append(Rp)
                trans.append(Rp @ self.rest[c] + my - Rp @ mx)
                continue
            i = mi[p]
            th = theta[self.theta_ptr[i]:self.theta_ptr[i + 1]]
            if kind == HINGE:
                e = self.axis_end[p]
                axis = known[e] - known[c]
                n = axis / axis.norm()
                n0 = (R[p] @ (self.rest[e] - self.rest[c]))
                n0 = n0 / n0.norm()
                Rp = _exp2(th[0] * _skew(n)) @ _align(n0.detach(), n) @ R[p]
            else:
                Rp = _exp2(_skew(th)) @ R[p]
            rots.append(Rp)
            trans.append(torch.zeros(3, dtype=theta.dtype) if kind == FREE else known[c])
        return torch.stack(rots), torch.stack(trans)

    # -- the derivative ----------------------------------------------------------------------
    def gradient(self, y: torch.Tensor, theta: torch.Tensor, T: torch.Tensor,
                 R: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``X`` and ``G = (dX/dz)^T (A X - b)`` with the graph kept (for ``dG``)."""
        ts = self.ts
        X = self.shape(y, theta, T, R)
        Rk = fit_rotations(ts.covariances(X[None]))
        r = torch.sparse.mm(ts.L, X) - ts.rhs(Rk)[0]
        gy, gt = _grads(X, (y, theta), r, create_graph=True)
        return X, torch.cat([gy.reshape(-1), gt])

    def vjp(self, y_star: np.ndarray, R_star: np.ndarray, T: torch.Tensor, gX: torch.Tensor,
            tol: float, max_iter: int) -> tuple[torch.Tensor, int]:
        """``dL/dT`` for one pose: the solution's free rows ``y_star`` and part rotations
        ``R_star``, targets ``T`` (h, 3) and ``gX = dL/dX`` (n, 3), internal numbering.
        Returns it and the conjugate-gradient iterations."""
        with torch.enable_grad():  # a backward runs with gradients off
            return self._vjp(y_star, R_star, T, gX, tol, max_iter)

    def _vjp(self, y_star, R_star, T, gX, tol, max_iter):
        y = torch.as_tensor(y_star, dtype=torch.float64).clone().requires_grad_(True)
        theta = torch.zeros(int(self.theta_ptr[-1]), dtype=torch.float64, requires_grad=True)
        Tq = T.detach().to(torch.float64).clone().requires_grad_(True)
        R = torch.as_tensor(R_star, dtype=torch.float64)
        X, G = self.gradient(y, theta, Tq, R)
        nf = y.numel()
        gz = torch.cat([g.reshape(-1) for g in _grads(X, (y, theta), gX, retain_graph=True)])

        def hess(u: torch.Tensor) -> torch.Tensor:
            hy, ht = _grads(G, (y, theta), u, retain_graph=True)
            return torch.cat([hy.reshape(-1), ht])

        # preconditioner: the merged system's factor on y, the exact rotation blocks
        el = self.ps.elimination
        m = int(self.theta_ptr[-1])
        f64 = torch.float64
        Htt = torch.stack([hess(torch.cat([torch.zeros(nf, dtype=f64),
                                           torch.eye(m, dtype=f64)[i]]))[nf:]
                           for i in range(m)]) if m else torch.zeros(0, 0, dtype=f64)
        Htt_inv = torch.linalg.pinv(Htt) if m else Htt

        def precond(r: torch.Tensor) -> torch.Tensor:
            ry = r[:nf].reshape(-1, 3).numpy()
            out = el.solve(np.ascontiguousarray(ry)) if nf else ry
            return torch.cat([torch.as_tensor(out).reshape(-1), Htt_inv @ r[nf:]])

        mu, its = _pcg(hess, precond, gz, tol, max_iter)
        gT = torch.autograd.grad(X, Tq, gX, retain_graph=True, allow_unused=True)[0]
        gT = torch.zeros_like(Tq) if gT is None else gT
        gG = torch.autograd.grad(G, Tq, mu, allow_unused=True)[0]
        if gG is not None:
            gT = gT - gG
        return gT, its


def _grads(out: torch.Tensor, inputs: tuple[torch.Tensor, ...], weight: torch.Tensor,
           **kw) -> list[torch.Tensor]:
    """``(d out / d input)^T weight`` for each input, zeros for one ``out`` does not use (a
    problem whose parts are all fixed has no angles)."""
    got = torch.autograd.grad(out, inputs, weight, allow_unused=True, **kw)
    return [torch.zeros_like(x) if g is None else g for g, x in zip(got, inputs)]


def _pcg(apply_H, precond, g: torch.Tensor, tol: float, max_iter: int):
    """``H mu = g`` by preconditioned conjugate gradients (one right-hand side)."""
    mu = torch.zeros_like(g)
    r = g.clone()
    g_norm = float(g.norm())
    if g_norm == 0:
        return mu, 0
    z = precond(r)
    p = z.clone()
    rz = float(r @ z)
    for it in range(1, max_iter + 1):
        Hp = apply_H(p)
        pHp = float(p @ Hp)
        if pHp <= 0:
            break
        alpha = rz / pHp
        mu = mu + alpha * p
        r = r - alpha * Hp
        if float(r.norm()) <= tol * g_norm:
            return mu, it
        z = precond(r)
        rz_new = float(r @ z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return mu, max_iter
