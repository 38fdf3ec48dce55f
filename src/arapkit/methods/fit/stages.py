"""The non-rigid stages of a template fit: the energy, its alternating minimisation, its check.

In a stage of stiffness length ``L`` (a fraction ``beta`` of the template's diagonal) the fit
minimises, over positions ``x``, rotations ``R_k`` and (optionally) a global scale ``s``::

    E(x, R, s) = sum_k sum_{e in N(k, r_k)} w_e |e'(x) - s R_k e|^2            (r-ring ARAP)
               + sum_{i eligible} lambda_i min(dist(x_i, S)^2, tau^2)            (data)

with ``lambda_i = m_i a_i / L^2`` (``a_i`` the vertex's Voronoi area, ``m_i`` how many times
its r-ring energy counts its edges against the 1-ring energy: the stiffness length means the
same at every r), ``S`` the target surface (:mod:`arapkit.methods.fit.target`) and ``tau``
the rejection distance. Landmarks are eliminated (hard constraints). Eligibility (the match
is not beyond the target's border, and either the normals agree within
:data:`NORMAL_ANGLE` or the vertex lies within half an edge of the surface) and ``tau`` are
fixed for the stage, so the stage has one energy; each step lowers it:

1. rotations ``R_k = argmax tr(R S_k)`` and scale ``s = sum tr(R_k S_k) / sum_e D_e |e|^2``
   (the engine's local step; ARAP is quadratic in ``s``);
2. matches: the closest point ``q_i`` of ``S``. For any point q of S,
   ``|x - q|^2 >= dist(x, S)^2``, and the last match is always a candidate
   (:meth:`FitTarget.match`), so ``|x_i - q_i|^2`` majorises the data term and equals it
   at the current iterate;
3. positions: the minimiser of that majoriser plus ``lambda_i |x_i - x_i^k|^2`` for every
   vertex whose match is rejected (it majorises the constant ``tau^2`` or 0 and vanishes at
   ``x^k``), i.e. ``(L + diag(lambda) + delta I) x = s b(R) + lambda y + delta x^k`` with
   ``y_i`` the match or the vertex itself. The matrix is the same for every target and
   every iteration of the stage: :class:`~arapkit.methods.fit.system.StageSystems` keeps
   its factor.

So the energy never rises within a stage (tests check it). Anderson acceleration
(:class:`arapkit.arap.accel.Anderson`) extrapolates the positions and keeps an extrapolation
only when it lowers the energy, as the deformation loop does; a stage ends when a plain
step lowers the energy by less than ``tol`` (relative), or after ``stage_iter`` steps.

Examples
--------
>>> import numpy as np
>>> from arapkit.methods.fit.target import Matches
>>> m = Matches(np.zeros((3, 3)), np.zeros(3, int), np.array([0.01, 0.04, 9.0]),
...             np.array([False, False, True]), np.tile([0.0, 0.0, 1.0], (3, 1)))
>>> eligible(m, np.tile([0.0, 0.0, 1.0], (3, 1)), True, 0.0).tolist()  # the third: border
[True, True, False]
>>> threshold(m, np.array([True, True, False]), diagonal=10.0)   # 4 x median 0.15, >= 0.2
0.6000000000000001
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ...arap.accel import Anderson
from .report import StageReport
from .system import StageSystems
from .target import FitTarget, Matches

__all__ = ["ANDERSON_HISTORY", "NEAR_EDGES", "NORMAL_ANGLE", "TAU_FACTOR", "TAU_FLOOR",
           "StageLoop", "eligible", "threshold"]

#: matches farther than this many times the median distance are rejected ...
TAU_FACTOR = 4.0
#: ... but never below this fraction of the template's diagonal, nor below the stage's
#: stiffness length (a stiff stage pulls at what a soft one would reject)
TAU_FLOOR = 0.02
#: a match whose normal is more than this many degrees from the template's is rejected ...
NORMAL_ANGLE = 90.0
#: ... unless the vertex is within this many mean edge lengths of it (a fold, not the far
#: side of a thin part)
NEAR_EDGES = 0.5
#: iterates Anderson acceleration extrapolates from
ANDERSON_HISTORY = 5


def eligible(m: Matches, normals: np.ndarray, oriented: bool, near: float) -> np.ndarray:
    """Matches that may be used: not beyond the target's border, and normals within
    :data:`NORMAL_ANGLE` (as lines, for unoriented normals) or closer than ``near``."""
    dot = (normals * m.normal).sum(axis=1)
    if not oriented:
        dot = np.abs(dot)
    flat = ~(normals != 0).any(axis=1)  # a vertex on no face has no normal to compare
    agree = (dot >= np.cos(np.deg2rad(NORMAL_ANGLE))) | flat | (m.d2 < near * near)
    return ~m.border & agree


def threshold(m: Matches, elig: np.ndarray, diagonal: float, stiffness: float = 0.0) -> float:
    """The rejection distance: :data:`TAU_FACTOR` times the median distance of the eligible
    matches, at least :data:`TAU_FLOOR` of the diagonal and the stiffness length."""
    d = np.sqrt(m.d2[elig])
    med = float(np.median(d)) if len(d) else 0.0
    return max(TAU_FACTOR * med, TAU_FLOOR * diagonal, stiffness * diagonal)


@dataclass
class StageLoop:
    """The stages of one fit, run in place on positions ``P`` (internal numbering, problem
    units). Built by :meth:`arapkit.methods.fit.Fitter.fit`."""

    backend: object
    system: StageSystems
    target: FitTarget
    P: np.ndarray
    C: np.ndarray  # landmark positions (rows of system.constrained)
    weights: np.ndarray  # m_i a_i per vertex
    rest_normals: np.ndarray
    rest_term: float
    diagonal: float
    edge: float
    scale: bool
    accelerate: bool
    tol: float
    stage_iter: int
    timings: dict[str, float] = field(default_factory=dict)
    sigma: float = 1.0
    prev: np.ndarray | None = None
    matches: Matches | None = None
    accepted: np.ndarray | None = None

    def __post_init__(self) -> None:
        for k in ("matching", "local", "solve"):
            self.timings.setdefault(k, 0.0)
        self.R = np.empty((self.backend.problem.energy.n_owners, 3, 3))
        nf = len(self.system.free)
        self._b = np.empty((nf, 3))
        self._zeros = np.zeros((nf, 3))
        self._fixed = (self.system.L_fc @ self.C if len(self.C) else np.zeros((nf, 3)))
        self.P[self.system.constrained] = self.C  # the landmarks are where they must be
        self.memo = self.target.memo(len(self.P))  # the walks' memory, across the stages

    # -- one evaluation -----------------------------------------------------------------
    def measure(self, x: np.ndarray, search: bool = False) -> tuple[Matches, float]:
        """Rotations and scale (the backend keeps them for the next right-hand side) and the
        matches at free positions ``x``; returns the matches and the ARAP energy."""
        P, free = self.P, self.system.free
        P[free] = x
        t0 = time.perf_counter()
        self.backend.local(P, self.R)
        tr, quad = self.backend.terms()
        if self.scale and tr > 0 and self.rest_term > 0:
            self.sigma = tr / self.rest_term
        t1 = time.perf_counter()
        m = self.target.match(P, self.prev, search=search, memo=self.memo)
        self.timings["local"] += t1 - t0
        self.timings["matching"] += time.perf_counter() - t1
        s = self.sigma
        return m, quad + s * s * self.rest_term - 2.0 * s * tr

    @staticmethod
    def energy(m: Matches, arap: float, elig: np.ndarray, tau: float,
               lam: np.ndarray) -> tuple[float, np.ndarray]:
        """The stage's energy and the matches it uses."""
        acc = elig & (m.d2 <= tau * tau)
        # the ineligible vertices' tau^2 is a constant of the stage: left out, so that the
        # relative decrease measures what the stage can change
        data = lam * np.where(acc, m.d2, np.where(elig, tau * tau, 0.0))
        return arap + float(data.sum()), acc

    # -- the stages -----------------------------------------------------------------------
    def run(self, schedule) -> list[StageReport]:
        """Run the stages of ``schedule`` (stiffness lengths); returns their reports."""
        system, free = self.system, self.system.free
        aa = (Anderson(3 * len(free), ANDERSON_HISTORY) if self.accelerate and len(free)
              else None)
        x = np.ascontiguousarray(self.P[free])
        reports = []
        for beta in schedule:
            t_stage = time.perf_counter()
            f0 = system.factorisations
            lam = self.weights / (beta * self.diagonal) ** 2
            lam_f = lam[free]
            rep = StageReport(f"stiffness {beta:g}", beta, 0)
            # the first stage searches the whole target; later ones walk from the last match
            m, arap = self.measure(x, search=self.prev is None)
            # the template's normals turned by the ARAP rotations (cheaper than new normals)
            normals = np.einsum("kij,kj->ki", self.R[: len(self.P)], self.rest_normals)
            elig = eligible(m, normals, self.target.oriented, NEAR_EDGES * self.edge)
            elig[system.constrained] = False
            tau = threshold(m, elig, self.diagonal, beta)
            E, acc = self.energy(m, arap, elig, tau, lam)
            rep.energy.append(E)
            if aa is not None:
                aa.reset()
            for _ in range(self.stage_iter):
                t0 = time.perf_counter()
                self.backend.rhs(self._zeros, self._b, system.slot)  # of x, measured last
                # a used match pulls its vertex to it; a rejected one holds it where it is
                pull = np.where(acc[free, None], m.point[free], x)
                rhs = (self.sigma * self._b - self._fixed + lam_f[:, None] * pull
                       + system.delta * x)
                g = system.solve(beta, lam_f, rhs)
                self.timings["solve"] += time.perf_counter() - t0
                rep.iterations += 1
                self.prev = m.element  # the last match stays a candidate: the majoriser
                accelerated = False
                if aa is not None:
                    y = aa.step(x, g)
                    if y is not None:
                        m_y, arap_y = self.measure(y)
                        E_y, acc_y = self.energy(m_y, arap_y, elig, tau, lam)
                        if E_y < E:  # the safeguard: an extrapolation must lower the energy
                            accelerated = True
                            x, E_new, m, acc = y, E_y, m_y, acc_y
                if not accelerated:
                    m, arap = self.measure(g)
                    E_new, acc = self.energy(m, arap, elig, tau, lam)
                    x = g
                small = E - E_new <= self.tol * abs(E)
                E = E_new
                rep.energy.append(E)
                if small and not accelerated:
                    break
            self.P[free] = x
            rep.accepted = float(acc.mean())
            rep.threshold = tau / self.diagonal
            rep.factorisations = system.factorisations - f0
            rep.time_s = time.perf_counter() - t_stage
            reports.append(rep)
        self.matches, self.accepted = m, acc
        return reports
