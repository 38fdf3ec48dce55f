"""No flipped triangles in 2D: a flip-preventing line search and a barrier on the global step.

Method (in the spirit of Smith & Schaefer 2015, "Bijective parameterization with free
boundaries", section 4, and of interior-point barriers). Two parts, each derived from the
energy so that the loop stays a descent method:

1. **The largest fold-free step.** Let ``x`` be the current positions (fold-free) and ``g``
   the global step's minimiser of ``E(., R)`` for the rotations just fitted. Twice the
   signed area of triangle t moves along ``x + a (g - x)`` as ``A_t(a) = p a^2 + q a +
   A_t(0)``: the step may not pass the smallest positive root (:func:`max_step`).
   ``E(., R)`` is a convex quadratic with its minimum at ``g``, so it falls monotonically
   for ``a`` in [0, 1], and the local step that follows lowers it again.

2. **A barrier where triangles are squeezed.** A line search alone stalls: a triangle
   pressed against zero area stays there while the global step keeps pushing it over. So
   the energy the guarded loop minimises is

       E_total(x, R) = E(x, R) + mu sum_t A0_t phi(s_t),
       phi(s) = -log(s / s0) + s / s0 - 1 for s < s0, else 0,

   with ``s_t = A_t / A0_t`` the area ratio to the rest shape (:data:`ZONE` ``= s0``,
   :data:`WEIGHT` ``= mu``). ``phi`` is zero, with zero slope, above ``s0``, and infinite at
   0: where no triangle is squeezed below a tenth of its area the energy, the steps and the
   minimum are plain ARAP's (the libigl agreement holds), and no step can cross ``s = 0``.
   Where it is active, the step is ``x + a d`` with ``d = -A^{-1} grad E_total / 2`` (the
   ARAP matrix ``A`` as the preconditioner: one more solve with the same factor), a
   descent direction of ``E_total(., R)``; ``a`` is the largest of ``a0, a0 / 2, ...``
   (``a0`` nine tenths of the largest fold-free step, at most 1) that lowers ``E_total``
   after the local step (Armijo's backtracking, with the refitted rotations).

Pins. The guard does not snap the pins onto new targets where that alone would fold a
triangle (a pin dragged far in one frame): the pins then travel with the step,
``p + a (c - p)``, toward their targets, which the global step always aims at (their
triangles kept above :data:`FLOOR` of their area). Once they land they stay exact and the
energy is monotone from there. Where the pins admit no fold-free map they cannot land:
after :data:`STALL_ITERATIONS` iterations without halving their distance to the targets
the guard lets go (:meth:`FlipGuard.release`), the pins are snapped, plain ARAP finishes the
solve, and :attr:`arapkit.Result.folds` says how many triangles folded instead of hiding it.

Examples
--------
>>> import numpy as np
>>> F = np.array([[0, 1, 2]])
>>> P = np.array([[0, 0], [1, 0], [0, 1]], float)
>>> Q = np.array([[0, 0], [1, 0], [0, -1]], float)    # would turn the triangle over
>>> a = max_step(P, Q, F, np.ones(1), np.full(1, 1e-4))
>>> round(a, 5), count_folds(P + a * (Q - P), F, np.ones(1))  # stops at the floor
(0.49995, 0)
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

__all__ = ["FLOOR", "STALL_ITERATIONS", "WEIGHT", "ZONE", "FlipGuard", "barrier",
           "count_folds", "max_step"]

#: while pins travel: the smallest signed area a triangle may be squeezed to, relative to
#: its area at rest
FLOOR = 1e-4
#: the area ratio below which the barrier acts (s0)
ZONE = 0.2
#: the barrier's weight (mu), per unit of rest area: ARAP's own scale per triangle
WEIGHT = 30.0
#: halvings of the step the backtracking tries before it keeps the shape where it is
BACKTRACKS = 40
#: iterations the pins may take to halve their distance to the targets before the guard lets go
STALL_ITERATIONS = 60


@nb.njit(cache=True, nogil=True)
def _area2(P, i, j, k):
    return ((P[j, 0] - P[i, 0]) * (P[k, 1] - P[i, 1])
            - (P[j, 1] - P[i, 1]) * (P[k, 0] - P[i, 0]))


@nb.njit(cache=True, nogil=True)
def max_step(P, Q, faces, sign, floor):
    """The largest ``a`` in (0, inf) (``inf``: none limits) before a triangle that is not
    folded at P reaches its floor on ``P + a (Q - P)``.

    ``sign[t]`` is triangle t's orientation at rest (+1, -1; 0 ignores it) and
    ``floor[t] >= 0`` its smallest allowed signed area (twice the area, in P's units).
    """
    best = math.inf
    for t in range(faces.shape[0]):
        s = sign[t]
        if s == 0.0:
            continue
        i, j, k = faces[t, 0], faces[t, 1], faces[t, 2]
        e1x, e1y = P[j, 0] - P[i, 0], P[j, 1] - P[i, 1]
        e2x, e2y = P[k, 0] - P[i, 0], P[k, 1] - P[i, 1]
        c = s * (e1x * e2y - e1y * e2x)
        if c <= 0.0:
            continue  # already folded or flat: free to unfold, not held
        lo = min(floor[t], 0.5 * c)
        dix, diy = Q[i, 0] - P[i, 0], Q[i, 1] - P[i, 1]
        f1x, f1y = Q[j, 0] - P[j, 0] - dix, Q[j, 1] - P[j, 1] - diy
        f2x, f2y = Q[k, 0] - P[k, 0] - dix, Q[k, 1] - P[k, 1] - diy
        a = s * (f1x * f2y - f1y * f2x)
        b = s * (e1x * f2y - e1y * f2x + f1x * e2y - f1y * e2x)
        c0 = c - lo  # > 0: the root of a x^2 + b x + c0 is where the floor is met
        root = math.inf
        if abs(a) <= 1e-14 * (abs(b) + c0):
            if b < 0.0:
                root = -c0 / b
        else:
            disc = b * b - 4.0 * a * c0
            if disc >= 0.0:
                sq = math.sqrt(disc)
                q = -0.5 * (b + math.copysign(sq, b))
                r1 = q / a
                r2 = c0 / q if q != 0.0 else math.inf
                if r1 > 0.0:
                    root = r1
                if r2 > 0.0 and r2 < root:
                    root = r2
        if root < best:
            best = root
    return best


@nb.njit(cache=True, nogil=True)
def count_folds(P, faces, sign):
    """How many triangles have turned over (signed area of the wrong sign, or zero)."""
    n = 0
    for t in range(faces.shape[0]):
        s = sign[t]
        if s != 0.0 and s * _area2(P, faces[t, 0], faces[t, 1], faces[t, 2]) <= 0.0:
            n += 1
    return n


@nb.njit(cache=True, nogil=True)
def barrier(P, faces, sign, A0, s0, mu, grad):
    """``mu sum_t A0_t phi(s_t)`` (the module's barrier) and, when ``grad`` has rows, its
    gradient added into ``grad``. Triangles already turned over are left out: the guarded
    steps never turn one over, and one that was may unfold."""
    total = 0.0
    want = grad.shape[0] > 0
    for t in range(faces.shape[0]):
        sg = sign[t]
        if sg == 0.0:
            continue
        i, j, k = faces[t, 0], faces[t, 1], faces[t, 2]
        ex, ey = P[j, 0] - P[i, 0], P[j, 1] - P[i, 1]
        fx, fy = P[k, 0] - P[i, 0], P[k, 1] - P[i, 1]
        s = sg * (ex * fy - ey * fx) / A0[t]
        if s >= s0:
            continue
        if s <= 0.0:
            continue  # folded already (a start that was): free to unfold, not held
        total += mu * A0[t] * (-math.log(s / s0) + s / s0 - 1.0)
        if want:
            # d/dA of mu A0 phi(A sg / A0) = mu sg (1 / s0 - 1 / s); dA/dp: perpendiculars
            c = mu * sg * (1.0 / s0 - 1.0 / s)
            gjx, gjy = fy, -fx
            gkx, gky = -ey, ex
            grad[j, 0] += c * gjx
            grad[j, 1] += c * gjy
            grad[k, 0] += c * gkx
            grad[k, 1] += c * gky
            grad[i, 0] -= c * (gjx + gkx)
            grad[i, 1] -= c * (gjy + gky)
    return total


class FlipGuard:
    """The line search and barrier of this module for one planar problem (internal
    numbering).

    Parameters
    ----------
    problem : ARAPProblem
        With ``dim == 2`` and its triangles.
    backend : optional
        The problem's bound backend (the barrier's extra solve and the backtracking's
        local steps); needed to limit steps, not to count folds.
    prevent : bool
        Limit the steps (True) or only count the folds (False: plain ARAP).

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.arap.problem import ARAPProblem
    >>> V = np.array([[0, 0], [1, 0], [0, 1]], float)
    >>> p = ARAPProblem.from_mesh((V, [[0, 1, 2]]), [0], dim=2)
    >>> g = FlipGuard(p)
    >>> g.folds(np.array([[0, 0], [1, 0], [0, -1]], float)[p.perm])  # internal numbering
    1
    """

    def __init__(self, problem, backend=None, prevent: bool = True) -> None:
        F = problem.graph.faces
        self.faces = np.ascontiguousarray(F, dtype=np.int64)
        rest = problem.rest_positions
        A0 = (rest[F[:, 1], 0] - rest[F[:, 0], 0]) * (rest[F[:, 2], 1] - rest[F[:, 0], 1]) \
            - (rest[F[:, 1], 1] - rest[F[:, 0], 1]) * (rest[F[:, 2], 0] - rest[F[:, 0], 0])
        # a triangle flat at rest has no orientation to keep
        tiny = 1e-14 * max(float(np.abs(A0).max(initial=0.0)), 1e-300)
        self.sign = np.where(np.abs(A0) > tiny, np.sign(A0), 0.0)
        self.A0 = np.maximum(np.abs(A0), tiny)
        self.floor = FLOOR * self.A0
        self.zone = ZONE * self.A0
        self.zero = np.zeros(len(F))
        self.backend = backend
        self._last_barrier = math.inf  # the loop's last barrier(P): P's own, reused
        self.prevent = bool(prevent) and backend is not None
        self.active = self.prevent
        self.landed = True
        self.released = False
        self._gap_mark = math.inf
        self._since = 0
        self._before = np.zeros((0, 2))
        self._no_grad = np.zeros((0, 2))
        self._R = np.empty((problem.energy.n_owners, 2, 2))
        #: where the pins are held now: their targets, or on the way there
        self.now = np.zeros((0, 2))

    def folds(self, P: np.ndarray) -> int:
        """Triangles of P (internal numbering) turned over relative to the rest shape."""
        return int(count_folds(P, self.faces, self.sign))

    def barrier(self, P: np.ndarray) -> float:
        """The barrier's term of the guarded energy at P (0 when the guard is off)."""
        if not self.active:
            return 0.0
        self._last_barrier = float(barrier(P, self.faces, self.sign, self.A0, ZONE, WEIGHT,
                                           self._no_grad))
        return self._last_barrier

    def begin(self, P: np.ndarray, cons: np.ndarray, C: np.ndarray) -> bool:
        """Whether the pins may be snapped onto ``C`` at the start (no new fold); if not,
        they stay where P has them (:attr:`now`) and travel toward ``C`` step by step."""
        self.now = C
        self._last_barrier = math.inf
        self.active, self.released = self.prevent, False  # a guard serves solve after solve
        if not self.active or not len(cons):
            self.landed = True
            return True
        Q = P.copy()
        Q[cons] = C
        after = self.folds(Q)
        self.landed = after == 0 or after <= self.folds(P)
        if not self.landed:
            self.now = P[cons].copy()
        self._gap_mark = math.inf
        self._since = 0
        return self.landed

    def limit(self, P: np.ndarray, g: np.ndarray, free: np.ndarray, cons: np.ndarray,
              C: np.ndarray, E_prev: float | None = None,
              R_prev: np.ndarray | None = None) -> float:
        """Turn the global step from P to ``g`` (the free vertices; the pins held at
        :attr:`now`) into the guarded step of the module, overwriting ``g``; then, while
        the pins travel, move them on toward ``C`` as far as the triangles allow (a new
        :attr:`now`). ``E_prev`` is the guarded energy at P (None: no backtracking).
        Returns the free vertices' step fraction ``a``."""
        if not self.active:
            return 1.0
        self._before = P.copy()
        x = self._before[free]
        squeezed = False
        B = self._last_barrier if math.isfinite(self._last_barrier) else self.barrier(P)
        if B > 0:  # the loop's barrier(P), or P's own at the first step
            # d = (g - x) - A^{-1} mu grad B / 2: the barrier's share with the same factor
            G = np.zeros_like(P)
            barrier(P, self.faces, self.sign, self.A0, ZONE, WEIGHT, G)
            g -= self.backend.solve(np.ascontiguousarray(0.5 * G[free]), np.empty_like(g))
            squeezed = True
        Q = P.copy()
        Q[free] = g
        # reaching the zone comes before turning over: one test in the common case
        if squeezed or max_step(P, Q, self.faces, self.sign, self.zone) <= 1.0:
            reach = max_step(P, Q, self.faces, self.sign, self.zero)
            a = min(1.0, 0.9 * reach)
            if E_prev is not None and math.isfinite(E_prev):
                a = self._backtrack(P, x, g - x, free, a, E_prev, R_prev)
            g[:] = x + a * (g - x)
        else:
            a = 1.0  # plain ARAP: nothing squeezed, now or along the step
        if not self.landed:
            self._advance(P, g, free, cons, C)
        return a

    def _backtrack(self, P, x, d, free, a: float, E_prev: float, R_prev) -> float:
        """Armijo's halving from ``a`` until the guarded energy (after the local step)
        falls below ``E_prev``; 0 when none of :data:`BACKTRACKS` halvings does."""
        trial = P.copy()
        R_prev = np.empty((0, 2, 2)) if R_prev is None else R_prev
        for _ in range(BACKTRACKS):
            trial[free] = x + a * d
            if self.backend.local(trial, self._R, R_prev) + self.barrier(trial) < E_prev:
                return a
            a *= 0.5
        return 0.0

    def _advance(self, P, g, free, cons, C) -> None:
        """Move the travelling pins toward ``C``, the free vertices with them along the
        Laplacian's response (``A_ff u = -A_fc dC``: one solve with the same factor, so the
        pins pull the shape instead of punching into it), as far as keeps every triangle
        above the barrier's zone (or half its area where it is below); land, or let go."""
        dC = C - self.now
        el = self.backend.problem.elimination
        u = self.backend.solve(np.ascontiguousarray(-(el.A_fc @ dC)), np.empty_like(g)) \
            if len(g) else np.zeros_like(g)
        Pn = P.copy()
        Pn[free] = g
        Qn = Pn.copy()
        Qn[free] += u
        Qn[cons] = C
        b = min(1.0, max_step(Pn, Qn, self.faces, self.sign, self.zone))
        g += b * u
        self.now = C if b >= 1.0 else self.now + b * dC
        P[cons] = self.now
        if b >= 1.0:
            self.landed = True
            return
        gap = float(np.abs(self.now - C).max())
        self._since += 1
        if gap <= 0.5 * self._gap_mark:
            self._gap_mark, self._since = gap, 0
        elif self._since >= STALL_ITERATIONS:
            self.release(P, cons, C)

    def admits(self, P: np.ndarray) -> bool:
        """Whether the straight path from the positions of the last :meth:`limit` to P
        keeps every unfolded triangle unfolded (an extrapolated step may be kept)."""
        if not self.active:
            return True
        return bool(max_step(self._before, P, self.faces, self.sign, self.zero) > 1.0)

    def release(self, P: np.ndarray, cons: np.ndarray, C: np.ndarray) -> None:
        """Give up: snap the pins onto their targets and let plain ARAP finish."""
        P[cons] = C
        self.now = C
        self.landed = True
        self.active = False
        self.released = True
