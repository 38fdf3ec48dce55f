"""The local/global loop: alternate best-fit rotations and one linear solve.

Independent of the energy (supplied by the problem) and of the device (the backend):
convergence test, Anderson acceleration with its energy safeguard, timings and the
per-iteration callback live here and nowhere else (libigl's ``arap_solve``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..validate import iteration_cap, tolerance
from .accel import Anderson
from .constraints import follow_rigidly

__all__ = ["Result", "local_global"]


@dataclass
class Result:
    """Outcome of :meth:`arapkit.Deformer.solve`.

    Attributes
    ----------
    vertices : (n, 3) deformed positions.
    energy : final energy of the method's own objective, the last entry of ``history``.
    history : energy after each iteration.
    iterations : number of iterations run.
    converged : whether the relative-decrease test held (rather than ``max_iter`` or a stop).
    rotations : (n, 3, 3) fitted R_k (None for methods without per-vertex rotations).
    timings : neighbourhood_ms, factorisation_ms, global_ms_per_iter, local_ms_per_iter,
        iterations, total_s.
    vertex_energy : (n,) each vertex's term of the energy. Computed on first access:
        interactive callers that discard superseded results skip its cost.
    """

    vertices: np.ndarray
    energy: float
    history: list[float]
    iterations: int
    converged: bool
    rotations: np.ndarray | None
    timings: dict[str, float] = field(default_factory=dict)
    _vertex_energy: np.ndarray | Callable[[], np.ndarray] | None = field(default=None,
                                                                          repr=False)

    @property
    def vertex_energy(self) -> np.ndarray:
        """Each vertex's term of the energy (computed once, on first access)."""
        if callable(self._vertex_energy):
            self._vertex_energy = self._vertex_energy()
        return self._vertex_energy


def local_global(problem, backend, targets: np.ndarray, start: np.ndarray | None, *,
                 tol: float, max_iter: int, callback=None, accelerate: bool = False,
                 history: int = 5) -> Result:
    """Run the local/global iteration on a bound backend.

    Parameters
    ----------
    problem : ARAPProblem
    backend : a backend bound to ``problem`` (e.g. :class:`arapkit.arap.backends.cpu.CPUBackend`)
    targets : (h, 3) checked handle targets.
    start : (n, 3) start positions in the caller's numbering, or None for the rest shape
        with identity rotations (the paper).
    tol, max_iter, callback, accelerate, history :
        As for :meth:`arapkit.Deformer.solve`.

    Positions cross this boundary in the caller's units and are divided by
    ``problem.scale`` (a power of two, so exactly) inside; results, energies and what the
    callback sees are scaled back. Any non-finite energy or position stops the solve with
    an :class:`~arapkit.errors.InputError` instead of reaching a file.
    """
    t_start = time.perf_counter()
    tol, max_iter = tolerance(tol), iteration_cap(max_iter)
    s = problem.scale
    s2 = s * s
    raw_targets = targets
    targets = np.asarray(targets, dtype=np.float64) / s
    if start is not None:
        start = np.asarray(start, dtype=np.float64) / s

    def check_finite(E: float, iteration: int) -> None:
        # one scalar per iteration: a non-finite position makes the energy non-finite too
        if math.isfinite(E) and math.isfinite(E * s2):
            return
        with np.errstate(over="ignore", invalid="ignore"):
            far = float(np.max(np.abs(raw_targets))) if np.size(raw_targets) else 0.0
        raise InputError(
            f"{problem.graph.name}: the solve produced non-finite values at iteration "
            f"{iteration}: targets too large for double precision (largest |coordinate| "
            f"{far:.3g}, mesh extent about {s:.3g})"
        )

    el = problem.elimination
    free, cons = el.free, el.constrained
    perm, inv = problem.perm, problem.iperm
    n = problem.n_vertices
    nf = len(free)
    C = problem.constrained_targets(targets)
    fixed_rhs = np.ascontiguousarray(el.A_fc @ C) if nf else np.zeros((0, 3))
    coupled = problem.energy.coupling is not None
    R = np.empty((n, 3, 3))
    R_prev = np.empty((n, 3, 3)) if coupled else np.empty((0, 3, 3))
    rhs = np.empty((nf, 3))
    E_prev = None
    t_global = t_local = t_accel = 0.0
    if start is None:
        P = problem.vertices.copy()
        R[:] = np.eye(3)
        P[cons] = C
        rhs[:] = problem.b_rest[free] - fixed_rhs
    else:
        # handles are snapped before the first fit, as libigl does, so the first
        # rotations already see the new targets
        P = np.ascontiguousarray(start[perm])
        P[cons] = C
        t0 = time.perf_counter()
        if coupled:
            R_prev[:] = np.eye(3)
        E_prev = backend.local(P, R, R_prev)
        check_finite(E_prev, 0)
        backend.rhs(fixed_rhs, rhs)
        t_local += time.perf_counter() - t0
    aa = Anderson(3 * nf, history) if accelerate and nf else None
    x = np.ascontiguousarray(P[free])  # current iterate (free vertices)
    g = np.empty((nf, 3))
    x_aa = np.empty((nf, 3))
    hist: list[float] = []
    converged = False
    rejected = 0
    # relative decrease is meaningless at round-off level: treat that as converged
    floor = 1e-24 * max(abs(backend.rest_term), 1e-300)
    it = 0
    for it in range(1, max_iter + 1):
        t0 = time.perf_counter()
        if nf:
            backend.solve(rhs, g)  # g = G(x)
        t1 = time.perf_counter()
        t_global += t1 - t0
        if coupled:  # the rotation coupling reads the last iteration's rotations
            R, R_prev = R_prev, R
        E = None
        if aa is not None and E_prev is not None:
            y = aa.step(x, g, x_aa)
            t2 = time.perf_counter()
            t_accel += t2 - t1
            if y is not None:
                backend.scatter(x_aa, free, P)
                E_try = backend.local(P, R, R_prev)
                if E_try < E_prev:  # safeguard: keep only energy-lowering extrapolations
                    E = E_try
                    x, x_aa = x_aa, x
                else:
                    rejected += 1
            t_local += time.perf_counter() - t2
        t2 = time.perf_counter()
        if E is None:
            backend.scatter(g, free, P)
            E = backend.local(P, R, R_prev)
            if aa is not None:
                x, g = g, x
        if it < max_iter:
            backend.rhs(fixed_rhs, rhs)
        t_local += time.perf_counter() - t2
        check_finite(E, it)
        hist.append(E)
        # abs(): obtuse meshes have negative cotangent weights and can have E < 0; a method
        # that is not a descent method (SR-ARAP) may also rise: the change is what counts
        if abs(E) <= floor or (E_prev is not None and abs(E_prev - E) / abs(E_prev) < tol):
            converged = True
        E_prev = E
        if callback is not None and callback(it, E * s2, P[inv] * s):
            break
        if converged:
            break
    timings = {
        "neighbourhood_ms": problem.timings.get("neighbourhood_ms", 0.0),
        "factorisation_ms": problem.timings.get("factorisation_ms", 0.0),
        "global_ms_per_iter": 1e3 * t_global / max(it, 1),
        "local_ms_per_iter": 1e3 * t_local / max(it, 1),
        "iterations": it,
        "total_s": time.perf_counter() - t_start,
    }
    if aa is not None:
        timings["accel_ms_per_iter"] = 1e3 * t_accel / max(it, 1)
        timings["accel_rejected"] = rejected

    def vertex_energy() -> np.ndarray:
        return backend.vertex_energy(P, R)[inv] * s2

    hist = [E * s2 for E in hist]
    V, Rv = P[inv], R[inv]
    if problem.free_components == "follow" and len(problem.fixed_extra):
        # components without handles: energy 0 at rest and under any rigid motion; place
        # them with their neighbours rather than leave them behind
        follow_rigidly(problem.caller_graph, problem.fixed_extra, V, Rv)
    V *= s
    if not np.isfinite(V).all():
        check_finite(math.nan, it)
    return Result(V, hist[-1], hist, it, converged, Rv, timings, vertex_energy)
