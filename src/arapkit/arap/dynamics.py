"""Implicit Euler steps with an ARAP energy as the elastic potential (projective dynamics).

One time step of length ``h`` from positions ``x_n`` and velocities ``v_n`` minimises

    Phi(x, R) = (1 + a h) / (2 h^2) |x - y|_M^2 + k E(x, R),
    y = x_n + (h v_n + h^2 (g + M^-1 f)) / (1 + a h),

with ``M`` the lumped vertex masses (:func:`arapkit.mesh.mass.vertex_masses`), ``k`` the
stiffness (N/m: ``E`` is a length squared), ``E`` the problem's registered energy (r-ring
ARAP with r per vertex, spokes-and-rims, ...), ``a`` the mass-damping rate (1/s), ``g`` an
acceleration (gravity) and ``f`` forces per vertex (N). Setting dPhi/dx = 0 with the best R
gives ``M (v_{n+1} - v_n) / h = -k grad E(x) + M g + f - a M v_{n+1}`` with
``v_{n+1} = (x - x_n) / h``: implicit (backward) Euler with Rayleigh mass damping. ``k``
does not depend on ``h``: halving the step halves it, and the body stays as stiff.

libigl's ``arap_solve`` with ``with_dynamics`` minimises the same form with the stiffness
``ym / h^2`` times its energy (a body four times stiffer at half the step), a fixed number of
iterations and ``x_n`` as the start; :data:`LIBIGL_ENERGY_SCALE` converts (see
:meth:`arapkit.methods.dynamics.Simulator.like_libigl`).

Local/global, as Liu et al.'s and Bouaziz et al.'s projective dynamics on the ARAP loop's
own parts: the local step fits the energy's rotations to ``x`` (the inertial term does not
depend on R); the global step solves ``(L_D + b M) x = b_E(R) + b M y`` for the free
vertices with the handles at their targets, ``b = (1 + a h) / (2 k h^2)``, where
``L_D`` and ``b_E(R)`` are the static problem's matrix and right-hand side
(:mod:`arapkit.arap.problem`). ``M`` is diagonal, so ``L_D + b M`` keeps the Laplacian's
sparsity; it is factorised once per step length, stiffness, damping and handle set. Each
step minimises Phi exactly over its block of unknowns, so Phi never rises within a time
step; the step ends by the project's relative energy test on Phi (:mod:`arapkit.arap.loop`).

Vertex groups (a :class:`~arapkit.arap.grouped.GroupedProblem`) change the blocks, not the
objective's form. A shared-rotation group fits one rotation to its members' neighbourhoods
in the local step (the inertial term does not depend on R). A rigid part's vertices are
``x_v = R_P a_v + t_P``: the global step solves for ``t_P`` with the part merged into one row,
exactly as the static solver (:mod:`arapkit.arap.parts`), the merged row's inertia being the
part's mass (``b M`` enters the reduced system as a diagonal, and ``b M y`` its right-hand
side); the local step fits ``R_P`` to the whole objective, turning a free part about its
centre of mass, so each iteration keeps the step's linear momentum. The part fit also turns
the energy's rotations of the neighbourhoods inside the part (:mod:`arapkit.arap.parts`),
and Anderson acceleration extrapolates the parts' rotations with the positions.

Components without a handle are not held here (their mass keeps the system positive
definite: a free body falls); a vertex without mass (one no triangle uses) has no motion of
its own and stays where it is.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from ..errors import Advice, InputError
from ..mesh.weights import SOUND_WEIGHTS
from ..validate import handle_indices, iteration_cap, number, tolerance
from .accel import Anderson
from .backends import make_backend
from .constraints import Elimination, return_free_memory
from .energies import energy_info
from .grouped import GroupedBackend, GroupedProblem
from .loop import energy_floor
from .parts import PartSystem, nearest_rotations

if TYPE_CHECKING:
    from collections.abc import Callable

    from .problem import ARAPProblem

__all__ = ["LIBIGL_ENERGY_SCALE", "STARTS", "ImplicitEuler", "Step", "check_dt",
           "check_stiffness", "check_damping"]

#: libigl's objective is ``ym / h^2`` times this fraction of arapkit's energy of the same
#: name (with ``weights="cotan"``): its global matrix ``-L`` is half the cotangent
#: Laplacian form, arapkit's ``L_D`` twice it (spokes, r = 1) or six times (spokes and rims)
LIBIGL_ENERGY_SCALE = {"rring": 0.25, "spokes-and-rims": 1.0 / 6.0}

#: where a step's iterations start: the inertial prediction ``y`` (projective dynamics;
#: exact at once for a free fall), or ``x_n`` (libigl's ``arap_solve``)
STARTS = ("inertial", "previous")


def check_dt(value, what: str = "dt") -> float:
    """A time step in seconds: a finite number > 0.

    Examples
    --------
    >>> check_dt("0.0166")
    0.0166
    """
    return number(value, what, lo=0.0, lo_open=True)


def check_stiffness(value, what: str = "stiffness") -> float:
    """A stiffness in N/m: a finite number > 0.

    Examples
    --------
    >>> check_stiffness(1e4)
    10000.0
    """
    return number(value, what, lo=0.0, lo_open=True)


def check_damping(value, what: str = "damping") -> float:
    """A mass-damping rate in 1/s: a finite number >= 0.

    Examples
    --------
    >>> check_damping(0)
    0.0
    """
    return number(value, what, lo=0.0)


@dataclass
class Step:
    """Outcome of one time step (caller's numbering and units).

    Attributes
    ----------
    positions, velocities : (n, 3)
        ``x_{n+1}`` and ``v_{n+1} = (x_{n+1} - x_n) / h``.
    history : list of float
        The step's objective Phi (J) after each iteration; never rises.
    iterations : int
    converged : bool
        The relative decrease of Phi fell below ``tol`` (or Phi is round-off).
    elastic : float
        ``k E(x_{n+1})`` at the best rotations (J).
    rotations : (n, 3, 3)
        The fitted rotations.
    seconds : float
        Wall time of the step.
    """

    positions: np.ndarray
    velocities: np.ndarray
    history: list[float]
    iterations: int
    converged: bool
    elastic: float
    rotations: np.ndarray
    seconds: float = 0.0
    timings: dict[str, float] = field(default_factory=dict)


class ImplicitEuler:
    """The time-stepping system of one problem: masses, stiffness, step and damping.

    Parameters
    ----------
    problem : ARAPProblem
        The energy, and the handles unless ``handles`` is given (its anchoring of
        components without handles is not used: their masses hold them). A
        :class:`~arapkit.arap.grouped.GroupedProblem` brings its shared-rotation groups
        and rigid parts (see the module).
    masses : (n,) float
        Lumped vertex masses (kg), caller numbering; 0 only for vertices without triangles.
    stiffness : float
        ``k`` in N/m.
    dt : float
        Step length ``h`` in seconds.
    damping : float
        Mass-damping rate ``a`` in 1/s.
    handles : (h,) int, optional
        The handle vertices (caller numbering), possibly none (a free body); default the
        problem's.

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.arap.problem import ARAPProblem
    >>> from arapkit.mesh.mass import vertex_masses
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar()
    >>> p = ARAPProblem.from_mesh(m, [0])
    >>> ie = ImplicitEuler(p, vertex_masses(m), 1e4, 0.01, handles=[])  # a free body
    >>> s = ie.step(m.vertices, np.zeros_like(m.vertices), np.zeros((0, 3)),
    ...             accel=[0, 0, -9.81])
    >>> round(float((s.positions - m.vertices)[:, 2].mean()), 9)  # free fall: -g h^2
    -0.000981
    """

    def __init__(self, problem: ARAPProblem, masses, stiffness: float, dt: float,
                 damping: float = 0.0, handles=None) -> None:
        t0 = time.perf_counter()
        info = energy_info(problem.energy.name)
        if not info.descent or problem.energy.coupling is not None:
            raise InputError(f"dynamics: energy '{problem.energy.name}' is not a descent "
                             "energy (each step must lower the step's objective)")
        self.problem = problem
        self.stiffness = check_stiffness(stiffness)
        self.dt = check_dt(dt)
        self.damping = check_damping(damping)
        n = problem.n_vertices
        m = np.asarray(masses, dtype=np.float64)
        if m.shape != (n,) or not np.isfinite(m).all() or (m < 0).any():
            raise InputError(f"{problem.name}: masses must be {n} finite values >= 0")
        self.masses = m
        #: the inertial term's weight relative to the energy, ``(1 + a h) / (2 k h^2)``
        with np.errstate(all="ignore"):  # overflow and underflow are refused below
            h = np.float64(self.dt)
            beta = (1.0 + np.float64(self.damping) * h) / (2.0 * np.float64(self.stiffness)
                                                           * h * h)
        self.beta = float(beta)
        if not math.isfinite(self.beta) or self.beta <= 0:
            raise InputError(f"dynamics: stiffness {self.stiffness:g} and dt {self.dt:g} "
                             "are out of range of double precision")
        # vertices without mass or edges would make the system singular: held in place
        massless = m == 0
        if massless.any():
            E = problem.caller_graph.edges
            ends = E[massless[E].any(axis=1)].ravel()
            if len(ends):
                v = int(ends[massless[ends]][0])
                raise InputError(f"{problem.name}: vertex {v} has edges but no mass")
        massless = np.flatnonzero(massless)
        if handles is None:
            handles = problem.handles
        elif np.size(handles) == 0:
            handles = np.zeros(0, dtype=np.int64)
        else:
            handles = handle_indices(handles, n, problem.name)
        #: the handle vertices (caller numbering)
        self.handles = np.asarray(handles, dtype=np.int64)
        layout = problem.layout if isinstance(problem, GroupedProblem) else None
        held = np.setdiff1d(massless, self.handles).astype(np.int64)
        if layout is not None:  # a part's massless vertices move with it
            held = held[layout.part[problem.iperm[held]] < 0]
            mass = np.bincount(layout.vert_part, m[problem.perm][layout.verts],
                               layout.n_parts)
            if (mass <= 0).any():
                raise InputError(f"{problem.groups.source}: rigid part "
                                 f"{layout.names[int(np.argmax(mass <= 0))]!r} has no mass "
                                 "(its vertices are in no triangle)")
        self.held = held
        #: handles first, then the held massless vertices (caller numbering)
        self.constrained = np.concatenate([self.handles, self.held])
        self.m_int = m[problem.perm]
        #: the rigid parts' reduced system (None without rigid parts)
        self.parts: PartSystem | None = None
        self.elimination = self._factorise()
        self.free = self.elimination.free
        inner = make_backend(problem, "cpu")
        # the energy alone (best rotations, no part moved): the elastic energy's
        self.energy_backend = inner.bind(problem, self.elimination)
        self.backend = inner if not isinstance(problem, GroupedProblem) else GroupedBackend(
            inner, problem).bind(problem, self.elimination, self.parts)
        self.m_free = self.m_int[self.free]
        self.timings = {"factorisation_ms": 1e3 * (time.perf_counter() - t0)}

    def _factorise(self) -> Elimination:
        """``L_D + b M`` with the constrained vertices eliminated (the one place that
        assembles the global matrix); with rigid parts, the parts' merged system
        (:class:`~arapkit.arap.parts.PartSystem`) with ``b M`` as its diagonal."""
        p = self.problem
        n = p.n_vertices
        E, w = p.edges, p.energy.system_w
        remedy = (
            Advice(" for this step length (obtuse triangles give negative cotangent "
                   "weights); use {weights} or a smaller dt", weights=SOUND_WEIGHTS)
            if (p.w < 0).any() else ""
        )
        if isinstance(p, GroupedProblem) and p.layout is not None:
            self.parts = PartSystem.build(p.layout, p.graph, w, p.iperm[self.constrained],
                                          p.name, remedy, diag=self.beta * self.m_int,
                                          nbh=p.energy.nbh)
            return_free_memory()
            return self.parts.elimination
        a, b = E[:, 0], E[:, 1]
        diag = (np.bincount(a, w, n) + np.bincount(b, w, n)) + self.beta * self.m_int
        A = sp.coo_matrix((np.concatenate([-w, -w, diag]),
                           (np.concatenate([a, b, np.arange(n)]),
                            np.concatenate([b, a, np.arange(n)]))), shape=(n, n)).tocsr()
        el = Elimination.from_matrix(A, p.iperm[self.constrained], p.name, remedy)
        return_free_memory()
        return el

    # -- one step ------------------------------------------------------------------
    def predictor(self, x: np.ndarray, v: np.ndarray, accel=None, forces=None) -> np.ndarray:
        """The inertial prediction ``y`` (caller numbering): where the body goes with no
        elastic force."""
        h, c = self.dt, 1.0 + self.damping * self.dt
        dv = np.zeros(3) if accel is None else np.asarray(accel, dtype=np.float64)
        inc = h * v + (h * h) * dv
        if forces is not None:
            m = self.masses
            inc += (h * h) * np.divide(forces, m[:, None], out=np.zeros_like(forces),
                                       where=m[:, None] > 0)
        return x + inc / c

    def step(self, x: np.ndarray, v: np.ndarray, targets: np.ndarray, *, accel=None,
             forces=None, tol: float = 1e-6, max_iter: int = 1000, start: str = "inertial",
             accelerate: bool = False, history: int = 5,
             callback: Callable[[int, float], bool | None] | None = None) -> Step:
        """One implicit Euler step from ``(x, v)`` with the handles at ``targets``.

        Parameters
        ----------
        x, v : (n, 3)
            Positions and velocities now (caller numbering, checked by the caller).
        targets : (h, 3)
            Handle positions at the end of the step, in the order of :attr:`handles`.
        accel : (3,) or (n, 3), optional
            Acceleration (gravity), m/s^2.
        forces : (n, 3), optional
            Forces per vertex, N.
        tol, max_iter :
            The relative decrease of Phi that ends the step, or Phi at round-off, and the
            iteration cap (``tol=0`` runs exactly ``max_iter`` iterations, libigl's fixed
            count).
        start : {"inertial", "previous"}
            Start the iterations at ``y`` or at ``x`` (libigl).
        accelerate, history :
            Anderson acceleration of the iterations with the loop's safeguard (an
            extrapolation is kept only when it lowers Phi), as
            :func:`arapkit.arap.loop.local_global`.
        callback : callable(iteration, Phi) -> bool, optional
            Returning True ends the step early.
        """
        t_start = time.perf_counter()
        tol, max_iter = tolerance(tol), iteration_cap(max_iter)
        if start not in STARTS:
            raise InputError(f"unknown start '{start}' (use {' or '.join(STARTS)})")
        p, be, el = self.problem, self.backend, self.elimination
        s = p.scale
        perm, inv, free, cons = p.perm, p.iperm, self.free, el.constrained
        with np.errstate(over="ignore", invalid="ignore"):  # refused as non-finite below
            y = self.predictor(x, v, accel, forces)
        Y = y[perm] / s
        C = np.concatenate([np.asarray(targets, dtype=np.float64) / s, x[self.held] / s])
        beta = self.beta
        m_int = self.m_int[:, None]
        if self.parts is not None:
            # the parts' system reads every vertex's right-hand side, b M y included, and
            # places the held parts by their handles
            be.extra_rhs = beta * m_int * Y
            known = np.zeros((p.n_vertices, 3))
            known[inv[self.constrained]] = C
            C = self.parts.constrained_positions(p.vertices, known, p.diagonal,
                                                 p.groups.source)
            fixed_rhs = np.zeros((len(free), 3))
        else:
            my = beta * self.m_free[:, None] * Y[free]
            fixed_rhs = (np.ascontiguousarray((el.A_fc @ C) - my) if len(free)
                         else np.zeros((0, 3)))
        P = (Y if start == "inertial" else x[perm] / s).copy()
        P[cons] = C
        R = np.empty((p.energy.n_owners, 3, 3))

        def inertia() -> float:
            with np.errstate(over="ignore", invalid="ignore"):  # refused as non-finite below
                return beta * float(np.sum(m_int * (P - Y) ** 2))

        def objective() -> float:
            # the inertia before the local step: a rigid part's fit moves P, and the change
            # it reports is the whole objective's
            kin = inertia()
            return be.local(P, R) + kin

        phi_prev = objective()
        floor = energy_floor(be.rest_term)
        nf = len(free)
        # with rigid parts the iterate also holds the rotations they are placed with (three
        # rows of three each): extrapolating the positions alone would place the parts
        # with stale rotations, and the safeguard would refuse nearly every extrapolation
        nr = 3 * self.parts.layout.n_parts if self.parts is not None else 0
        rhs = np.empty((nf, 3))
        g = np.empty((nf + nr, 3))
        aa = Anderson(3 * (nf + nr), history) if accelerate and nf else None
        x_it = np.empty((nf + nr, 3))  # the current iterate
        x_it[:nf] = P[free]
        if nr:
            x_it[nf:] = be.R_cur.reshape(-1, 3)
        x_aa = np.empty((nf + nr, 3))
        hist: list[float] = []
        converged = plain_next = False
        it = 0
        to_j = self.stiffness * s * s  # Phi inside -> joules
        for it in range(1, max_iter + 1):
            accepted = False
            if nf:
                be.rhs(fixed_rhs, rhs)
                el.solve(rhs, g[:nf])  # g = G(x): one local/global step from x
                if nr:
                    g[nf:] = be.R_rhs.reshape(-1, 3)
                y_aa = aa.step(x_it, g, x_aa) if aa is not None else None
                if y_aa is not None and not plain_next:
                    if nr:  # the extrapolated rotations, made rotations again
                        Rq = nearest_rotations(x_aa[nf:].reshape(-1, 3, 3))
                        x_aa[nf:] = Rq.reshape(-1, 3)
                        be.scatter(x_aa[:nf], free, P, Rq)
                    else:
                        be.scatter(x_aa, free, P)
                    phi = objective()
                    # the safeguard: an extrapolation is kept only when it lowers Phi, so
                    # Phi still never rises
                    accepted = phi < phi_prev
                    if accepted:
                        x_it, x_aa = x_aa, x_it
                if not accepted:
                    # with the rotations g was solved with (a refused extrapolation has
                    # placed the parts with its own)
                    if nr:
                        be.scatter(g[:nf], free, P, g[nf:].reshape(-1, 3, 3))
                    else:
                        be.scatter(g, free, P)
                    if aa is not None:
                        x_it, g = g, x_it
            if not accepted:
                phi = objective()
            if not (math.isfinite(phi) and math.isfinite(phi * to_j)):
                raise InputError(f"{p.name}: the time step produced non-finite values at "
                                 f"iteration {it}: forces, speeds or targets too large for "
                                 "double precision")
            hist.append(phi * to_j)
            small = abs(phi_prev - phi) < tol * abs(phi_prev)
            # only a plain step can end the step (as in arapkit.arap.loop); tol = 0 is
            # libigl's fixed count: no test at all, not even round-off's
            converged = tol > 0 and (abs(phi) <= floor or (small and not accepted))
            plain_next = small and accepted
            phi_prev = phi
            if callback is not None and callback(it, phi * to_j):
                break
            if converged:
                break
        if self.parts is None:
            elastic = (phi_prev - inertia()) * to_j
        else:  # the last part fit moved P after the energy's rotations were fitted
            elastic = self.energy_backend.local(P, np.empty_like(R)) * to_j
        X = P[inv] * s
        return Step(X, (X - x) / self.dt, hist, it, converged, max(elastic, 0.0)
                    if self.backend.nonneg else elastic, R[:p.n_vertices][inv],
                    time.perf_counter() - t_start)

    def elastic_energy(self, x: np.ndarray) -> float:
        """``k E(x)`` at the best rotations (J), caller numbering.

        Examples
        --------
        >>> from arapkit.arap.problem import ARAPProblem
        >>> from arapkit.mesh.mass import vertex_masses
        >>> from arapkit.mesh.shapes import bar
        >>> m = bar()
        >>> ie = ImplicitEuler(ARAPProblem.from_mesh(m, [0]), vertex_masses(m), 1e4, 0.01)
        >>> ie.elastic_energy(m.vertices + 1.0)  # a translation: no strain
        0.0
        """
        p = self.problem
        s = p.scale
        P = np.ascontiguousarray(np.asarray(x, dtype=np.float64)[p.perm] / s)
        R = np.empty((p.energy.n_owners, 3, 3))
        return float(self.energy_backend.local(P, R)) * self.stiffness * s * s
