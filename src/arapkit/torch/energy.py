"""The mesh ARAP loss: eq. 1 of Chen et al. 2017 with optimal rotations, in torch.

``arap_energy(X, layer_or_problem)`` is differentiable in the positions; the rotations are
detached (envelope theorem). Details: ``docs/torch.md``.
"""

from __future__ import annotations

import weakref

import torch as _torch

from ..arap.backends.torch_backend import TorchSystem, best_rotations, check_dtype
from ..arap.problem import ARAPProblem
from ..errors import InputError
from .layer import ARAPLayer

__all__ = ["arap_energy"]


_SYSTEMS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _system_for(problem: ARAPProblem, like: _torch.Tensor) -> TorchSystem:
    """A cached energy-only :class:`TorchSystem` of ``problem`` on ``like``'s device/dtype."""
    per = _SYSTEMS.setdefault(problem, {})
    key = (str(like.device), like.dtype)
    if key not in per:
        per[key] = TorchSystem(problem, like.device, check_dtype(like.dtype))
    return per[key]


def arap_energy(X: _torch.Tensor, layer_or_problem: ARAPLayer | ARAPProblem) -> _torch.Tensor:
    """ARAP energy (eq. 1) of positions ``X`` with optimal rotations: the "ARAP loss".

    ``sum_k sum_{e in N(k)} w_ke |e'_e - R_k e_e|^2`` with each ``R_k`` the best fit to X,
    summed edge by edge. With non-negative weights (the default) it is >= 0 and 0 exactly
    at rigid motions of the rest shape. Its gradient is ``dE/dX`` at the optimal rotations
    (envelope theorem: the rotations' own derivative multiplies ``dE/dR = 0``), so the
    rotations are detached; second derivatives are therefore not those of the reduced
    energy.

    Parameters
    ----------
    X : (n, 3) or (B, n, 3) tensor
        Positions in the mesh's vertex order (float32 or float64, any device).
    layer_or_problem : ARAPLayer or arapkit.arap.problem.ARAPProblem
        Gives the rest shape, weights, neighbourhoods (r) and energy; handles play no role.

    Returns
    -------
    tensor of shape () or (B,)

    Examples
    --------
    >>> import torch
    >>> from arapkit.mesh.shapes import bar
    >>> from arapkit.arap.problem import ARAPProblem
    >>> mesh = bar(segments=(10, 2, 2))
    >>> p = ARAPProblem.from_mesh(mesh, [0], rings=2)
    >>> X = torch.tensor(mesh.vertices, requires_grad=True)
    >>> arap_energy(X, p).item() < 1e-20
    True
    >>> E = arap_energy(X * 1.1, p)
    >>> E.backward()
    >>> bool(E > 0) and X.grad.shape == X.shape
    True
    """
    if isinstance(layer_or_problem, ARAPLayer):
        problem = layer_or_problem.problem
    elif isinstance(layer_or_problem, ARAPProblem):
        problem = layer_or_problem
    else:
        raise InputError("arap_energy: second argument must be an ARAPLayer or an ARAPProblem, "
                         f"got {type(layer_or_problem).__name__}")
    if problem.energy.coupling is not None:
        raise InputError(f"arap_energy: energy '{problem.energy.name}' couples rotations and "
                         "has no closed-form optimal rotations; use 'rring' or "
                         "'spokes-and-rims'")
    n = problem.n_vertices
    if not isinstance(X, _torch.Tensor) or X.ndim not in (2, 3) or tuple(X.shape[-2:]) != (n, 3):
        shape = tuple(X.shape) if isinstance(X, _torch.Tensor) else type(X).__name__
        raise InputError(f"arap_energy: expected positions of shape ({n}, 3) or (B, {n}, 3), "
                         f"got {shape}")
    if X.dtype not in (_torch.float32, _torch.float64):
        raise InputError(f"arap_energy: dtype {X.dtype} is not supported "
                         "(use torch.float32 or torch.float64)")
    ts = _system_for(problem, X)
    s = problem.scale  # the problem's unit (a power of two): exact
    P = (X if X.ndim == 3 else X[None])[:, ts.perm] / s
    with _torch.no_grad():
        R = best_rotations(ts.covariances(P))
    E = ts.energy(P, R) * (s * s)
    return E if X.ndim == 3 else E[0]
