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
from .constraints import rigid_motion
from .rotations2d import follow_in_plane, rigid_motion_2d

__all__ = ["ROUNDOFF_ULPS", "Result", "energy_floor", "local_global", "rigid_start",
           "start_energy", "with_progress"]

#: energies within this many ulps of the rest term are round-off (see :func:`energy_floor`)
ROUNDOFF_ULPS = 1024
_EPS = float(np.finfo(np.float64).eps)


@dataclass
class Result:
    """Outcome of :meth:`arapkit.Deformer.solve`.

    Attributes
    ----------
    vertices : (n, 3) deformed positions.
    energy : final energy of the method's own objective, the last entry of ``history``.
    history : energy after each iteration.
    iterations : number of iterations run.
    converged : whether the relative-decrease test held or the energy reached round-off
        (:func:`energy_floor`), rather than ``max_iter`` or a stop.
    rotations : (n, 3, 3) fitted R_k (None for methods without per-vertex rotations);
        (n, 2, 2) for a planar solve.
    timings : neighbourhood_ms, factorisation_ms, global_ms_per_iter, local_ms_per_iter,
        iterations, total_s.
    vertex_energy : (n,) each vertex's term of the energy. Computed on first access:
        interactive callers that discard superseded results skip its cost.
    folds : int or None
        For a planar (2D) solve: how many triangles are turned over relative to the rest
        shape (0 unless the pins admit no fold-free map, :mod:`arapkit.arap.flips`); None
        in 3D.
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
    folds: int | None = None

    @property
    def vertex_energy(self) -> np.ndarray:
        """Each vertex's term of the energy (computed once, on first access)."""
        if callable(self._vertex_energy):
            self._vertex_energy = self._vertex_energy()
        return self._vertex_energy


def energy_floor(rest_term: float) -> float:
    """The energy at or below which the loop stops: round-off relative to the mesh.

    The loop evaluates ``E = sum |P_e|^2 + rest_term - 2 tr(R S)`` in expanded form, so a
    shape of zero energy (the rest shape, any rigid motion of it) reads as a few ulps of
    ``rest_term = sum_e D_e |e|^2``, the energy's natural unit, of either sign: up to about
    20 ulps measured on a 37,706-vertex mesh at r = 1 and 3.  The relative-decrease test
    compares two such noise values and may never pass; an energy within
    :data:`ROUNDOFF_ULPS` ulps of ``rest_term`` is converged (an rms strain below 1e-6,
    which no figure or float32 display shows).

    Examples
    --------
    >>> round(energy_floor(2.0) / np.finfo(float).eps)  # ulps of a rest term of 2
    2048
    """
    return ROUNDOFF_ULPS * _EPS * abs(rest_term)


def rigid_start(problem, targets: np.ndarray) -> np.ndarray | None:
    """The rest shape moved rigidly onto ``targets`` when they are a rigid motion of it.

    When every handle target is one rigid motion of its rest position (to within
    ``sqrt(eps)`` of the coordinates, whose squared error is round-off of the energy),
    that motion of the whole rest shape has energy 0: the minimum with non-negative
    weights, reached from any start in one iteration instead of hundreds (rotations spread
    slowly through the local/global loop). Handles that are collinear leave the rotation
    about their line free, so they get None, as do targets that are not rigid.

    Parameters
    ----------
    problem : ARAPProblem
    targets : (h, 3) handle targets in the problem's units (divided by ``problem.scale``).

    Returns
    -------
    (n, 3) positions in the caller's numbering and the problem's units, or None.

    Examples
    --------
    >>> from arapkit.arap.problem import ARAPProblem
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    >>> E = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])
    >>> p = ARAPProblem.from_graph(V, E, np.ones(6), [0, 1, 2])
    >>> Q = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], dtype=float)   # a quarter turn
    >>> s = p.scale
    >>> bool(np.allclose(rigid_start(p, (V[:3] @ Q.T + 5) / s), (V @ Q.T + 5) / s))
    True
    >>> rigid_start(p, V[:3] * 2 / s) is None  # stretched: not rigid
    True
    """
    d = problem.dim
    rest = problem.caller_graph.vertices[:, :d]
    X = rest[problem.handles]
    if len(X) < d:
        return None
    sv = np.linalg.svd(X - X.mean(axis=0), compute_uv=False)
    # collinear in 3D (coincident in 2D): the rotation about the line is undetermined
    if sv[d - 2] <= 1e-6 * sv[0] or sv[0] == 0:
        return None
    if d == 2:
        R, t = rigid_motion_2d(X, targets)
    else:
        R, t = rigid_motion(X, targets)
    size = max(1.0, float(np.abs(targets).max()), float(np.abs(X).max()))
    if np.abs(X @ R.T + t - targets).max() > math.sqrt(_EPS) * size:
        return None
    return rest @ R.T + t


def with_progress(callback, progress):
    """One ``callback(iteration, energy, vertices)`` that also asks ``progress(iteration,
    energy)``, for a solver loop that takes only a callback (either may be None).

    Examples
    --------
    >>> seen = []
    >>> cb = with_progress(None, lambda it, E: seen.append((it, E)) or it >= 2)
    >>> cb(1, 0.5, None), cb(2, 0.25, None), seen
    (False, True, [(1, 0.5), (2, 0.25)])
    >>> with_progress(None, None) is None
    True
    """
    if progress is None:
        return callback

    def both(iteration: int, energy: float, vertices: np.ndarray) -> bool:
        if callback is not None and callback(iteration, energy, vertices):
            return True  # as in local_global: a stopping callback ends it before progress
        return bool(progress(iteration, energy))

    return both


def start_energy(problem, backend, start: np.ndarray, units: float, C: np.ndarray,
                 R: np.ndarray, R_prev: np.ndarray, snap: bool = True
                 ) -> tuple[np.ndarray, float]:
    """A solve's start: ``start / units`` in the problem's order with the handles snapped
    to ``C``, and its energy at the best rotations (written to ``R``).

    Handles are snapped before the first fit, as libigl does, so the first rotations
    already see the new targets (``snap=False`` leaves them where ``start`` has them: a
    flip guard moves them there itself). A coupled energy's first fit reads identity
    rotations in ``R_prev`` (empty for the others). Returns the positions and the energy
    in the problem's units.

    Examples
    --------
    >>> from arapkit.arap.backends import make_backend
    >>> from arapkit.arap.problem import ARAPProblem
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    >>> E = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])
    >>> p = ARAPProblem.from_graph(V, E, np.ones(6), [0, 1, 2])
    >>> R, none = np.empty((4, 3, 3)), np.empty((0, 3, 3))
    >>> C = p.constrained_targets(V[:3] / p.scale)
    >>> P, E0 = start_energy(p, make_backend(p), V, p.scale, C, R, none)
    >>> abs(E0) < 1e-12, bool(np.allclose(P, V[p.perm] / p.scale))  # rest: no energy
    (True, True)
    """
    # permuted and scaled in one new array: a scaled copy of the whole start as well
    # would be one more shape alive through the solve (40 MB at 1.75M vertices)
    P = np.asarray(start, dtype=np.float64)[problem.perm] / units
    if snap:
        P[problem.elimination.constrained] = C
    R_prev[:] = np.eye(problem.dim)
    return P, backend.local(P, R, R_prev)


def local_global(problem, backend, targets: np.ndarray, start: np.ndarray | None, *,
                 tol: float, max_iter: int, callback=None, accelerate: bool = False,
                 history: int = 5, progress=None, guard=None) -> Result:
    """Run the local/global iteration on a bound backend.

    Parameters
    ----------
    problem : ARAPProblem
    backend : a backend bound to ``problem`` (e.g. :class:`arapkit.arap.backends.cpu.CPUBackend`)
    targets : (h, 3) checked handle targets.
    start : (n, 3) start positions in the caller's numbering, or None for the rest shape
        with identity rotations (the paper).
    tol, max_iter, callback, accelerate, history, progress :
        As for :meth:`arapkit.Deformer.solve`.
    guard : FlipGuard, optional
        A planar problem's flip guard (:mod:`arapkit.arap.flips`): each global step is
        shortened to keep every triangle unfolded, and ``Result.folds`` is counted.

    A problem with ``dim == 2`` runs in two columns throughout (targets ``(h, 2)``,
    rotations 2 x 2).

    Positions cross this boundary in the caller's units and are divided by
    ``problem.scale`` (a power of two, so exactly) inside; results, energies and what the
    callback sees are scaled back. Any non-finite energy or position stops the solve with
    an :class:`~arapkit.errors.InputError` instead of reaching a file.

    Targets that are one rigid motion of the handles' rest positions start from that
    motion of the rest shape (:func:`rigid_start`), whatever ``start`` says; the loop
    stops when a plain local/global step's relative decrease is below ``tol`` (an
    accelerated step is kept only when it lowers the energy by more) or the energy is
    round-off (:func:`energy_floor`).
    """
    t_start = time.perf_counter()
    tol, max_iter = tolerance(tol), iteration_cap(max_iter)
    s = problem.scale
    s2 = s * s
    raw_targets = targets
    targets = np.asarray(targets, dtype=np.float64) / s
    start_units = s  # start / start_units is in the problem's units
    rigid = rigid_start(problem, targets) if np.isfinite(targets).all() else None
    if rigid is not None:
        start, start_units = rigid, 1.0

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
    inv = problem.iperm
    nf = len(free)
    d = problem.dim
    C = problem.constrained_targets(targets)

    def coupling(C_held: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(el.A_fc @ C_held) if nf else np.zeros((0, d))

    coupled = problem.energy.coupling is not None
    # a rotation per owner: the vertices first, then any of their own (triangles)
    K = problem.energy.n_owners
    R = np.empty((K, d, d))
    R_prev = np.empty((K, d, d)) if coupled else np.empty((0, d, d))
    rhs = np.empty((nf, d))
    E_prev = None
    t_global = t_local = t_accel = 0.0
    if start is None:
        P = problem.rest_positions.copy()
        R[:] = np.eye(d)
        if guard is None or guard.begin(P, cons, C):
            P[cons] = C
        C_held = C if guard is None else guard.now  # travelling pins: where they are
        fixed_rhs = coupling(C_held)
        rhs[:] = problem.b_rest[free, :d] - fixed_rhs
    else:
        t0 = time.perf_counter()
        snap = True
        if guard is not None:
            P0 = np.asarray(start, dtype=np.float64)[problem.perm] / start_units
            snap = guard.begin(P0, cons, C)
            start, start_units = P0[inv], 1.0
        C_held = C if guard is None else guard.now
        fixed_rhs = coupling(C_held)
        P, E_prev = start_energy(problem, backend, start, start_units, C, R, R_prev, snap)
        if guard is not None:
            E_prev += guard.barrier(P)
        check_finite(E_prev, 0)
        backend.rhs(fixed_rhs, rhs)
        t_local += time.perf_counter() - t0
    # with rigid parts an accelerated iterate also holds the rotations they are placed with
    # (three rows of three each): extrapolating the positions alone places the parts with
    # stale rotations, and the safeguard refuses nearly every extrapolation (a bone in the
    # bar bent by 90 degrees: 391 accelerated iterations against 418 plain; now 52)
    nr = getattr(backend, "part_rows", 0) if accelerate and nf and d == 3 else 0
    aa = Anderson(d * (nf + nr), history) if accelerate and nf else None
    x = np.empty((nf + nr, d))  # current iterate (free vertices, then parts' rotations)
    x[:nf] = P[free]
    # whether this solve's local step has fitted the parts' rotations yet: from a start it
    # has; from rest the first step is plain, and its result replaces x before Anderson
    # reads it (the backend's rotations are then a previous solve's)
    turned = bool(nr) and start is not None
    if turned:
        x[nf:] = backend.placed_rotations().reshape(-1, 3)
    elif nr:
        x[nf:] = np.tile(np.eye(3), (nr // 3, 1))
    g = np.empty((nf + nr, d))
    x_aa = np.empty((nf + nr, d))
    hist: list[float] = []
    landed_at = 0
    converged = False
    rejected = 0
    plain_next = False
    # relative decrease is meaningless at round-off level: treat that as converged
    floor = energy_floor(backend.rest_term)
    it = 0
    for it in range(1, max_iter + 1):
        t0 = time.perf_counter()
        if nf:
            backend.solve(rhs, g[:nf] if nr else g)  # g = G(x)
            if turned:  # ... and the rotations the parts are placed with there
                g[nf:] = backend.placed_rotations().reshape(-1, 3)
        if guard is not None:  # the guarded step (module flips)
            guard.limit(P, g, free, cons, C, E_prev, R_prev)
            if guard.now is not C_held:  # travelling pins moved on
                C_held = guard.now
                fixed_rhs = coupling(C_held)
                E_prev = None  # another problem: no comparison across the move
                landed_at = it if guard.landed else 0
        t1 = time.perf_counter()
        t_global += t1 - t0
        if coupled:  # the rotation coupling reads the last iteration's rotations
            R, R_prev = R_prev, R
        E = None
        accelerated = False
        # while pins travel to their targets the map changes each step: no extrapolation
        if aa is not None and E_prev is not None and (guard is None or guard.landed):
            y = aa.step(x, g, x_aa)
            t2 = time.perf_counter()
            t_accel += t2 - t1
            if y is not None and not plain_next:
                if nr:  # the extrapolated rotations, made rotations again
                    Rq = backend.extrapolated_rotations(x_aa[nf:].reshape(-1, 3, 3),
                                                        g[nf:].reshape(-1, 3, 3))
                    x_aa[nf:] = Rq.reshape(-1, 3)
                    backend.scatter(x_aa[:nf], free, P, Rq)
                else:
                    backend.scatter(x_aa, free, P)
                E_try = backend.local(P, R, R_prev)
                if guard is not None:
                    E_try += guard.barrier(P)
                # safeguard: keep only energy-lowering (and, guarded, fold-free) extrapolations
                if E_try < E_prev and (guard is None or guard.admits(P)):
                    accelerated = True
                    E = E_try
                    x, x_aa = x_aa, x
                else:
                    rejected += 1
            t_local += time.perf_counter() - t2
        t2 = time.perf_counter()
        if E is None:
            if not nr:
                backend.scatter(g, free, P)
            elif turned:  # with g's rotations (a refused extrapolation placed its own)
                backend.scatter(g[:nf], free, P, g[nf:].reshape(-1, 3, 3))
            else:  # the first step from rest: the parts' rotations are fitted to it
                backend.scatter(g[:nf], free, P)
                g[nf:] = backend.placed_rotations().reshape(-1, 3)
                turned = True
            E = backend.local(P, R, R_prev)
            if guard is not None:
                E += guard.barrier(P)
            if aa is not None:
                x, g = g, x
        if it < max_iter:
            backend.rhs(fixed_rhs, rhs)
        t_local += time.perf_counter() - t2
        check_finite(E, it)
        hist.append(E)
        # abs(): obtuse meshes have negative cotangent weights and can have E < 0; a method
        # that is not a descent method (SR-ARAP) may also rise: the change is what counts
        small = E_prev is not None and abs(E_prev - E) < tol * abs(E_prev)
        # only a plain step can end the solve: an extrapolation that barely lowers the energy
        # (a stalled history) says nothing about the fixed point; kept as the end, it ended
        # volumetric solves 16-58 % above the energy the plain steps went on to reach
        if (abs(E) <= floor or (small and not accelerated)) and (guard is None
                                                                  or guard.landed):
            converged = True
        plain_next = small and accelerated
        E_prev = E
        if callback is not None and callback(it, E * s2, backend.gather(P, inv, s)):
            break
        if progress is not None and progress(it, E * s2):
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
    # the iteration's arrays go before the result's are made: kept, Anderson's history and
    # the loop's vectors (0.45 GiB at 1.75M vertices) would stack on the result's copies
    # and set the solve's peak memory
    aa = x = g = x_aa = rhs = fixed_rhs = R_prev = None

    def vertex_energy() -> np.ndarray:
        return backend.vertex_energy(P, R)[inv] * s2

    hist = [E * s2 for E in hist]
    folds = None if guard is None else guard.folds(P)
    if guard is not None and guard.released:
        timings["flip_guard_released"] = 1
    if guard is not None and landed_at:
        timings["pins_landed_at"] = landed_at  # the pins travelled: history index of landing
    V, Rv = P[inv], R[inv]
    if problem.free_components == "follow" and len(problem.fixed_extra):
        # components without handles: energy 0 at rest and under any rigid motion; place
        # them with their neighbours rather than leave them behind
        if d == 3:
            problem.followers.apply(V, Rv)
        else:
            V, Rv = follow_in_plane(problem.followers, V, Rv)
    V *= s
    if not np.isfinite(V).all():
        check_finite(math.nan, it)
    return Result(V, hist[-1], hist, it, converged, Rv, timings, vertex_energy, folds=folds)
