"""The PyTorch layer: ``X = ARAPLayer(mesh, handles)(targets)``, ARAP solved in torch ops.

The forward is the local/global loop of :class:`arapkit.Deformer` on the device; the backward
is implicit differentiation at the converged solution (see :class:`_ARAPSolve`). Details and
an example: ``docs/torch.md``.
"""

from __future__ import annotations

import torch as _torch

from ..arap.backends.torch_backend import (
    TorchSystem,
    _pose_sums,
    best_rotations,
    check_dtype,
    fit_rotations,
)
from ..arap.problem import ARAPProblem
from ..errors import InputError
from ..mesh.model import bounding_box_diagonal
from ..validate import iteration_cap, tolerance

__all__ = ["ARAPLayer"]


def planar_rotations(S: _torch.Tensor) -> _torch.Tensor:
    """In-plane rotations ``(..., 3, 3)`` (a 2 x 2 turn, z kept) maximising ``tr(R S)``
    over turns about z: the closed form of :mod:`arapkit.arap.rotations2d`, differentiable
    by autograd (``(c, s) = (a, b) / |(a, b)|``, ``a = S_00 + S_11``, ``b = S_01 - S_10``).

    Examples
    --------
    >>> import torch
    >>> S = torch.tensor([[[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]])
    >>> planar_rotations(S)[0, :2, :2].tolist()  # a quarter turn
    [[0.0, -1.0], [1.0, 0.0]]
    """
    a = S[..., 0, 0] + S[..., 1, 1]
    b = S[..., 0, 1] - S[..., 1, 0]
    h = _torch.sqrt(a * a + b * b)
    none = h == 0
    hs = _torch.where(none, _torch.ones_like(h), h)
    c = _torch.where(none, _torch.ones_like(a), a / hs)
    s = _torch.where(none, _torch.zeros_like(b), b / hs)
    z, o = _torch.zeros_like(c), _torch.ones_like(c)
    return _torch.stack([_torch.stack([c, -s, z], -1), _torch.stack([s, c, z], -1),
                         _torch.stack([z, z, o], -1)], -2)


def _check_targets(T, system: TorchSystem, handles, dim: int = 3
                   ) -> tuple[_torch.Tensor, bool]:
    """Targets as ``(B, h, dim)`` on the layer's device and dtype; whether a batch was
    given."""
    h = len(handles)
    if not isinstance(T, _torch.Tensor):
        raise InputError(f"targets: expected a torch.Tensor of shape ({h}, 3) or (B, {h}, 3), "
                         f"got {type(T).__name__}")
    if T.ndim not in (2, 3) or tuple(T.shape[-2:]) != (h, dim) or (T.ndim == 3
                                                                    and not len(T)):
        raise InputError(f"targets: expected shape ({h}, {dim}) or (B, {h}, {dim}), got "
                         f"{tuple(T.shape)}")
    if T.dtype != system.dtype:
        raise InputError(f"targets: dtype {T.dtype} does not match the layer's {system.dtype} "
                         f"(convert with .to({system.dtype}))")
    if T.device != system.device and not (T.device.type == system.device.type == "cuda"
                                          and system.device.index is None):
        raise InputError(f"targets: on device {T.device}, the layer is on {system.device} "
                         f"(move them with .to('{system.device}'))")
    batched = T.ndim == 3
    T3 = T if batched else T[None]
    ok = _torch.isfinite(T3).all(dim=-1)
    if not bool(ok.all()):
        b, i = (int(v) for v in _torch.nonzero(~ok)[0])
        where = f"pose {b}, " if batched else ""
        raise InputError(f"targets: {where}handle {i} (vertex {int(handles[i])}) target is "
                         "not finite")
    return T3, batched


def _bdot(a: _torch.Tensor, b: _torch.Tensor) -> _torch.Tensor:
    """Per-batch inner product of ``(B, ...)`` tensors, shaped ``(B, 1, 1)`` (each pose
    rounded as alone, so that a pose's gradient does not depend on its batch-mates)."""
    return _pose_sums(a * b)[:, None, None]


class _ARAPSolve(_torch.autograd.Function):
    """Local/global solve with implicit differentiation at the converged solution.

    Forward: the loop of :func:`arapkit.arap.loop.local_global` in torch ops, batched.

    Backward: the converged free positions ``x`` satisfy ``grad_x f(x, T) = 0`` for the
    reduced energy ``f(x, T) = min_R E``, i.e. ``A x = b(x, T) - A_fc C(T)`` with
    ``b(P) = sum_k R_k(P) c_k``, the gradient of the convex ``sum_k max_R tr(R S_k(P))``.
    Differentiating: ``(A - B) dx = (db/dT - A_fc) dT`` with ``B = db/dx``, symmetric, so
    ``dL/dT = (db/dT - A_fc)^T mu`` plus the direct path (the handles' own rows of the
    output), where ``(A - B) mu = dL/dx``. ``A - B`` is half the Hessian of ``f``
    (positive definite at a strict minimum): ``mu`` comes from conjugate gradients
    preconditioned by the Cholesky factor of ``A``, so each CG step costs one solve with
    the forward's factor and one vector-Jacobian product of ``b`` (through the closed-form
    rotation derivative of :func:`arapkit.arap.backends.torch_backend.fit_rotations`).
    """

    @staticmethod
    def forward(ctx, T, layer: ARAPLayer):
        ts = layer.system
        with _torch.no_grad():
            x, info = layer._iterate(T)
            P = ts.assemble(x, ts.constrained(T))
        ctx.layer = layer
        ctx.save_for_backward(T, x)
        layer.last_info = info
        return P[:, ts.iperm]

    @staticmethod
    def backward(ctx, gX):
        layer = ctx.layer
        ts = layer.system
        T, x_star = ctx.saved_tensors
        gP = gX[:, ts.perm]
        g_free = gP[:, ts.free]
        gT = gP[:, ts.cons[:ts.n_handles]].clone()
        with _torch.enable_grad():
            x = x_star.detach().requires_grad_(True)
            Tq = T.detach().requires_grad_(True)
            P = ts.assemble(x, ts.constrained(Tq))
            b = ts.rhs(layer.fit(ts.covariances(P)))[:, ts.free]

            def hess(u):  # (A - B) u
                (Bu,) = _torch.autograd.grad(b, x, u, retain_graph=True)
                return ts.apply_A(u) - Bu

            mu, layer.last_info["adjoint_iterations"] = _pcg(hess, ts.solve, g_free,
                                                              layer.adjoint_tol,
                                                              layer.adjoint_max_iter)
            (gb,) = _torch.autograd.grad(b, Tq, mu)
        gT += gb - ts.apply_A_fc_T(mu)[:, :ts.n_handles]
        return gT, None


def _pcg(apply_H, precond, g: _torch.Tensor, tol: float, max_iter: int):
    """Solve ``H mu = g`` per batch element by preconditioned conjugate gradients.

    A batch element that meets its tolerance stops there (its step is zero from then
    on), so its ``mu`` does not depend on the others.
    """
    mu = _torch.zeros_like(g)
    r = g.clone()
    g_norm = _torch.sqrt(_bdot(g, g))
    z = precond(r)
    p = z.clone()
    rz = _bdot(r, z)
    live = _torch.ones_like(rz, dtype=_torch.bool)
    it = 0
    while it < max_iter:
        it += 1
        Hp = apply_H(p)
        pHp = _bdot(p, Hp)
        alpha = _torch.where(live & (pHp != 0), rz / pHp, _torch.zeros_like(rz))
        mu = mu + alpha * p
        r = r - alpha * Hp
        live &= _torch.sqrt(_bdot(r, r)) > tol * g_norm
        if not bool(live.any()):
            break
        z = precond(r)
        rz_new = _bdot(r, z)
        beta = _torch.where(rz != 0, rz_new / rz, _torch.zeros_like(rz))
        p = z + beta * p
        rz = rz_new
    return mu, it


def _check_layer_energy(energy: str) -> None:
    """Refuse, in one line, a method the layer does not offer (the registry's "torch" door)."""
    from ..methods.registry import method, method_names

    if energy not in method_names():
        known = method_names("library")
        raise InputError(f"unknown energy '{energy}' (use one of {', '.join(known)})")
    info = method(energy)
    if "torch" not in info.interfaces:
        why = info.why_not.get("torch", "it is not offered by the layer")
        raise InputError(f"energy '{energy}' is not available in ARAPLayer ({why}); use "
                         f"{' or '.join(repr(e) for e in method_names('torch'))}")


class ARAPLayer(_torch.nn.Module):
    """Differentiable ARAP: handle targets in, deformed vertices out.

    Parameters
    ----------
    mesh : arapkit.Mesh, or a point cloud (arapkit.PointCloud, Graph, an (n, 3) array)
        The shape; a point cloud is solved on its neighbourhood graph (``docs/clouds.md``).
    handles : (h,) int
        Handle vertices; ``targets[..., i, :]`` is where ``handles[i]`` goes.
    rings : int or (n,) int
        r per vertex (rigidity), held fixed.
    weights : str, optional
        Edge weighting (default: the shape's own, :data:`arapkit.mesh.weights.DEFAULT_WEIGHTS`
        on a mesh, ``gaussian`` on a point cloud).
    energy : {"rring", "spokes-and-rims", "smooth-arap"}
        The local/global energy (SR-ARAP's rotation coupling has no fixed point of one
        step alone and is not offered here). Smooth ARAP runs at its default lambda.
    tol, max_iter :
        The forward's stopping test, as for :class:`arapkit.Deformer`. Each pose of a
        batch stops when it passes the test itself, so it gets the answer (and iteration
        count) of its own single solve. Gradients are those of the exact solution: a loose ``tol``
        gives gradients of a point near it.
    xtol : float, optional
        Also stop when no free vertex moved more than ``xtol`` times the rest shape's
        bounding-box diagonal in the last iteration. The energy test is second order in
        the positions and drowns in round-off below ``tol ~ 1e-13``; use ``xtol`` (with
        ``tol=0``) to converge the positions tightly, e.g. for finite-difference checks.
    dtype : torch.float32 or torch.float64
    dim : {None, 2, 3}
        2 solves a planar shape (``(n, 2)`` positions, or one z) in its plane: targets and
        output ``(.., 2)`` for ``(n, 2)`` input, rotations turns about z (no folds through
        3D); None: 2 for planar input, else 3 (as :class:`arapkit.Deformer`).
    device : "cpu", "cuda" or "cuda:N"
        Where the tensors and the factor live (fixed at construction; ``.to()`` does not
        move them).
    adjoint_tol, adjoint_max_iter :
        Relative residual and iteration cap of the backward's conjugate gradients
        (default 1e-10 in float64, 1e-5 in float32).
    groups : VertexGroups or (n,) int, optional
        Rigid parts and shared-rotation groups, as for :class:`arapkit.Deformer` (a plain
        array is libigl's ``G``). Shared-rotation groups run on any device; with rigid
        parts each pose is solved exactly by the CPU engine (float64, ``device="cpu"``) and
        differentiated implicitly with the parts' rotations among the unknowns
        (:mod:`arapkit.arap.backends.torch_parts`).

    Examples
    --------
    >>> import torch
    >>> from arapkit.mesh.shapes import bar, bar_bend
    >>> mesh = bar(segments=(10, 2, 2))
    >>> h, t = bar_bend(mesh, 45)
    >>> layer = ARAPLayer(mesh, h, dtype=torch.float64)
    >>> T = torch.tensor(t, requires_grad=True)
    >>> X = layer(T)
    >>> X.shape == (mesh.n_vertices, 3)
    True
    >>> X[:, 2].sum().backward()
    >>> T.grad.shape == T.shape
    True
    """

    def __init__(self, mesh, handles, rings=1, weights: str | None = None,
                 energy: str = "rring", tol: float = 1e-3, max_iter: int = 1000,
                 dtype=_torch.float32, device="cpu", *, xtol: float | None = None,
                 adjoint_tol: float | None = None, adjoint_max_iter: int = 1000,
                 dim: int | None = None, groups=None) -> None:
        super().__init__()
        check_dtype(dtype)
        _check_layer_energy(energy)
        from ..mesh.planar import PlanarInput
        from ..methods.dispatch import check_domain
        from ..methods.planar import solve_dim
        from ..methods.registry import method

        shape = PlanarInput.of_shape(mesh)  # a point cloud too, on its graph
        check_domain(shape.mesh, energy)  # a method on triangles refuses a cloud
        #: solved in the plane (turns about z only); ``given_dim``: the caller's columns
        self.planar = solve_dim(shape, dim, method(energy).planar, energy) == 2
        self.given_dim = shape.given_dim
        self._z = shape.z
        self.fit = planar_rotations if self.planar else fit_rotations
        problem = ARAPProblem.from_mesh(shape.mesh, handles, energy, weights, rings=rings)
        self._parts = None
        if groups is not None:
            if self.planar:  # a part's fit is a 3 x 3 rotation
                raise InputError("groups: vertex groups are solved in 3D; a planar layer "
                                 "takes none (pass dim=3 to solve the shape in 3D)")
            problem = _with_groups(problem, energy, groups, device)
            if getattr(problem, "layout", None) is not None:
                from ..arap.backends.torch_parts import PartsAdjoint

                self._parts = PartsAdjoint(problem)
        self.problem = problem
        self.system = TorchSystem(problem, device, dtype)
        if self._parts is None:  # the parts' merged system is the CPU engine's
            self.system.bind(problem)
        self.tol = tolerance(tol)
        self.max_iter = iteration_cap(max_iter)
        V = problem.vertices
        self._step_tol = None if xtol is None else float(xtol) * bounding_box_diagonal(V)
        self.adjoint_tol = (1e-10 if dtype == _torch.float64 else 1e-5) \
            if adjoint_tol is None else float(adjoint_tol)
        self.adjoint_max_iter = int(adjoint_max_iter)
        self.last_info: dict = {}

    @property
    def handles(self):
        """Handle vertices (caller numbering)."""
        return self.problem.handles

    @property
    def device(self) -> _torch.device:
        """Where the layer's tensors live."""
        return self.system.device

    @property
    def dtype(self) -> _torch.dtype:
        """The layer's floating-point type."""
        return self.system.dtype

    def forward(self, targets: _torch.Tensor) -> _torch.Tensor:
        """Deformed vertices ``(n, 3)`` or ``(B, n, 3)`` for targets ``(h, 3)`` or ``(B, h, 3)``."""
        T, batched = _check_targets(targets, self.system, self.handles, self.given_dim)
        if self.given_dim == 2:  # onto the plane z = 0 the problem was built on
            T = _torch.cat([T, T.new_zeros(T.shape[:-1] + (1,))], dim=-1)
        elif self.planar and bool((T[..., 2] != self._z).any()):
            raise InputError(f"targets: a planar layer keeps z = {self._z:g} (the plane); "
                             "use dim=3 to deform the shape out of its plane")
        # the problem lives in units of problem.scale (a power of two: exact); autograd sees
        # the two scalings as ordinary operations
        s = self.problem.scale
        solve = _ARAPSolve if self._parts is None else _PartsSolve
        X = solve.apply(T / s, self) * s
        if self.given_dim == 2:
            X = X[..., :2]
        return X if batched else X[0]

    def _iterate(self, T: _torch.Tensor) -> tuple[_torch.Tensor, dict]:
        """The local/global loop from the rest shape (internal numbering, no autograd).

        Each pose of a batch stops at its own stopping test and keeps the iterate at
        which it passed: the poses still running go on alone, so a pose's answer and
        iteration count do not depend on its batch-mates.
        """
        ts = self.system
        B = T.shape[0]
        C = ts.constrained(T)
        fixed = ts.fixed_rhs(C)
        floor = 1e-24 * max(abs(ts.rest_term), 1e-300)
        out = _Frozen(ts.b_rest_free.new_zeros(B, ts.nf, 3))
        live = _torch.arange(B, device=T.device)  # the poses still iterating
        rhs = ts.b_rest_free[None] - fixed
        x = ts.b_rest_free.new_zeros(B, ts.nf, 3)
        E_prev = None
        for it in range(1, self.max_iter + 1):
            x, x_prev = ts.solve(rhs), x
            P = ts.assemble(x, C)
            S = ts.covariances(P)
            R = best_rotations(S) if not self.planar else planar_rotations(S)
            E = ts.energy_expanded(P, R, S)
            passed = self._passed(E, E_prev, x - x_prev, it, floor)
            done = passed | (it == self.max_iter)
            out.keep(live[done], x[done], E[done], it, passed[done])
            if bool(done.all()):
                break
            go = ~done
            live, x, C, fixed, E_prev, R = live[go], x[go], C[go], fixed[go], E[go], R[go]
            rhs = ts.rhs(R)[:, ts.free] - fixed
        s2 = self.problem.scale ** 2
        return out.x, {"iterations": int(out.iterations.max()),
                       "converged": bool(out.converged.all()),
                       "energy": out.energy * s2,
                       "pose_iterations": out.iterations,
                       "pose_converged": out.converged}

    def _passed(self, E: _torch.Tensor, E_prev: _torch.Tensor | None, step: _torch.Tensor,
                it: int, floor: float) -> _torch.Tensor:
        """Per pose: the stopping test of :func:`arapkit.arap.loop.local_global` (relative
        energy decrease below ``tol``, or an energy at round-off level), or ``xtol``."""
        passed = E.abs() <= floor
        if E_prev is not None:
            passed |= (E_prev - E).abs() / E_prev.abs().clamp_min(1e-300) < self.tol
        if self._step_tol is not None and it > 1 and self.system.nf:
            passed |= step.abs().amax(dim=(1, 2)) <= self._step_tol
        return passed


def _with_groups(problem: ARAPProblem, energy: str, groups, device):
    """``problem`` with the layer's groups (refused where the method or device cannot)."""
    from ..arap.grouped import as_groups, with_groups
    from ..methods.registry import method, method_names

    if not method(energy).groups:
        takes = ", ".join(m for m in method_names("torch") if method(m).groups)
        raise InputError(f"groups: energy '{energy}' takes no vertex groups (these methods "
                         f"do: {takes})")
    g = as_groups(groups, problem.n_vertices)
    if g.rigid.any() and str(device) != "cpu":
        raise InputError(f"{g.source}: rigid parts in ARAPLayer solve on device='cpu' (the "
                         "exact parts run on the CPU engine)")
    return with_groups(problem, g)


class _PartsSolve(_torch.autograd.Function):
    """A layer with rigid parts: each pose solved by the CPU engine of
    :mod:`arapkit.arap.grouped`, the backward by
    :class:`~arapkit.arap.backends.torch_parts.PartsAdjoint` (in the problem's units)."""

    @staticmethod
    def forward(ctx, T, layer: ARAPLayer):
        import numpy as np

        from ..arap.backends.cpu import CPUBackend
        from ..arap.grouped import GroupedBackend
        from ..arap.loop import local_global

        p = layer.problem
        s = p.scale
        if getattr(layer, "_backend", None) is None:
            layer._backend = GroupedBackend(CPUBackend(p), p).bind(p)
        be = layer._backend
        free = p.elimination.free
        out, ys, Rs, info = [], [], [], {"iterations": 0, "converged": True, "energy": []}
        for Tb in T.detach().to(_torch.float64).cpu().numpy():
            res = local_global(p, be, Tb * s, None, tol=layer.tol, max_iter=layer.max_iter)
            V = res.vertices / s
            out.append(V)
            ys.append(V[p.perm][free])
            Rs.append(be.R_cur.copy())
            info["iterations"] = max(info["iterations"], res.iterations)
            info["converged"] &= bool(res.converged)
            info["energy"].append(res.energy)
        info["energy"] = _torch.tensor(info["energy"])
        layer.last_info = info
        ctx.layer, ctx.ys, ctx.Rs = layer, ys, Rs
        ctx.save_for_backward(T)
        return _torch.as_tensor(np.stack(out), dtype=T.dtype, device=T.device)

    @staticmethod
    def backward(ctx, gX):
        layer = ctx.layer
        (T,) = ctx.saved_tensors
        perm = _torch.as_tensor(layer.problem.perm)
        adj = layer._parts
        gT, its = [], 0
        for b in range(T.shape[0]):
            g, k = adj.vjp(ctx.ys[b], ctx.Rs[b], T[b], gX[b].to(_torch.float64)[perm],
                           layer.adjoint_tol, layer.adjoint_max_iter)
            gT.append(g)
            its = max(its, k)
        layer.last_info["adjoint_iterations"] = its
        return _torch.stack(gT).to(T.dtype), None


class _Frozen:
    """The forward's answer per pose, filled in as each pose stops."""

    def __init__(self, x: _torch.Tensor) -> None:
        B = x.shape[0]
        self.x = x
        self.energy = x.new_zeros(B)
        self.iterations = _torch.zeros(B, dtype=_torch.int64)
        self.converged = _torch.zeros(B, dtype=_torch.bool)

    def keep(self, poses: _torch.Tensor, x: _torch.Tensor, E: _torch.Tensor, it: int,
             passed: _torch.Tensor) -> None:
        """Record the iterate ``x`` (energy ``E``) of ``poses`` stopped at iteration ``it``."""
        self.x[poses] = x
        self.energy[poses] = E
        cpu = poses.cpu()
        self.iterations[cpu] = it
        self.converged[cpu] = passed.cpu()
