"""One-shot ARAP solve of a precomputed problem (libigl's ``arap_solve``).

:func:`arap_solve` ties the three parts together: the immutable problem
(:mod:`arapkit.arap.problem`), a backend for a device (:mod:`arapkit.arap.backends`) and the
local/global loop (:mod:`arapkit.arap.loop`). :class:`arapkit.Deformer` is the stateful
wrapper over the same parts.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .backends import make_backend
from .constraints import check_targets
from .loop import Result, local_global
from .problem import ARAPProblem

__all__ = ["arap_solve"]


def arap_solve(problem: ARAPProblem, targets, init=None, *, backend=None, device: str = "cpu",
               tol: float = 1e-3, max_iter: int = 1000, callback=None,
               accelerate: bool = False, history: int = 5) -> Result:
    """Solve ``problem`` for handle targets with the local/global loop.

    Parameters
    ----------
    problem : ARAPProblem
    targets : (h, 3)
        Handle positions, in the order of ``problem.handles``.
    init : (n, 3), optional
        Start positions (caller numbering); default the rest shape with identity
        rotations.
    backend : optional
        A backend of ``problem``'s energy to reuse (from
        :func:`arapkit.arap.backends.make_backend`); built on ``device`` when not given.
    device : str
        As for :class:`arapkit.Deformer`.
    tol, max_iter, callback, accelerate, history :
        As for :meth:`arapkit.Deformer.solve`.

    Returns
    -------
    arapkit.arap.loop.Result

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    >>> E = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])
    >>> p = ARAPProblem.from_graph(V, E, np.ones(6), [0, 1, 2])
    >>> res = arap_solve(p, V[:3] + 1.0)  # translate the handles: the tet follows rigidly
    >>> bool(np.allclose(res.vertices, V + 1.0))
    True
    """
    T = check_targets(problem.handles, targets)
    start = None
    if init is not None:
        start = np.asarray(init, dtype=np.float64)
        if start.shape != (problem.n_vertices, 3) or not np.isfinite(start).all():
            raise InputError(f"init: expected finite positions of shape "
                             f"({problem.n_vertices}, 3)")
    if backend is None:
        backend = make_backend(problem, device)
    backend.bind(problem)
    return local_global(problem, backend, T, start, tol=tol, max_iter=max_iter,
                        callback=callback, accelerate=accelerate, history=history)
