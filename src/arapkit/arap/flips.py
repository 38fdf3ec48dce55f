"""No flipped triangles in 2D: a flip-preventing line search on the global step.

Method (after Smith & Schaefer 2015, "Bijective parameterization with free boundaries",
section 4: the largest step along a search direction that keeps every triangle's signed
area positive is the smallest positive root of one quadratic per triangle).

Let ``x`` be the current positions (fold-free) and ``g`` the global step's minimiser of
``E(., R)`` for the rotations just fitted. ``E(., R)`` is a convex quadratic in the free
positions with its minimum at ``g``, so along the segment ``x + a (g - x)`` it falls
monotonically for ``a`` in [0, 1]; the local step that follows lowers it again. Taking any
``a`` in (0, 1] therefore keeps the local/global loop a descent method, and
:meth:`FlipGuard.limit` takes the largest one for which no triangle's signed area (relative
to its orientation at rest) falls below a positive floor: twice the area of triangle t moves
as ``A_t(a) = p a^2 + q a + A_t(0)``, and the floor is met at the smallest positive root. The
floor is ``min(eps |A_t(rest)|, A_t(0) / 2)``: a triangle may be squeezed, never turned over.

Pins. The guard does not snap the pins onto new targets where that alone would fold a
triangle (a pin dragged far in one frame): the pins then travel with the line search,
``p + a (c - p)``, toward their targets, which the global step always aims at. Once they
land (``a = 1`` once) they stay exact and the energy is monotone from there. Where the
pins admit no fold-free map the pins cannot land: after :data:`STALL_ITERATIONS` iterations
without halving their distance to the targets the guard lets go (:meth:`FlipGuard.release`),
the pins are snapped, plain ARAP finishes the solve, and :attr:`arapkit.Result.folds` says
how many triangles folded instead of hiding it.

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

__all__ = ["FLOOR", "STALL_ITERATIONS", "FlipGuard", "count_folds", "max_step"]

#: the smallest signed area a triangle may be squeezed to, relative to its area at rest
FLOOR = 1e-4
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


class FlipGuard:
    """The line search of this module for one planar problem (internal numbering).

    Parameters
    ----------
    problem : ARAPProblem
        With ``dim == 2`` and its triangles.
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

    def __init__(self, problem, prevent: bool = True) -> None:
        F = problem.graph.faces
        self.faces = np.ascontiguousarray(F, dtype=np.int64)
        rest = problem.rest_positions
        A0 = (rest[F[:, 1], 0] - rest[F[:, 0], 0]) * (rest[F[:, 2], 1] - rest[F[:, 0], 1]) \
            - (rest[F[:, 1], 1] - rest[F[:, 0], 1]) * (rest[F[:, 2], 0] - rest[F[:, 0], 0])
        # a triangle flat at rest has no orientation to keep
        tiny = 1e-14 * max(float(np.abs(A0).max(initial=0.0)), 1e-300)
        self.sign = np.where(np.abs(A0) > tiny, np.sign(A0), 0.0)
        self.floor = FLOOR * np.abs(A0)
        self.prevent = bool(prevent)
        self.active = self.prevent
        self.landed = True
        self.released = False
        self._gap_mark = math.inf
        self._since = 0
        self._before = np.zeros((0, 2))

    def folds(self, P: np.ndarray) -> int:
        """Triangles of P (internal numbering) turned over relative to the rest shape."""
        return int(count_folds(P, self.faces, self.sign))

    def begin(self, P: np.ndarray, cons: np.ndarray, C: np.ndarray) -> bool:
        """Whether the pins may be snapped onto ``C`` at the start (no new fold); if not,
        they stay where P has them and travel with the line search."""
        if not self.active or not len(cons):
            self.landed = True
            return True
        Q = P.copy()
        Q[cons] = C
        self.landed = self.folds(Q) <= self.folds(P)
        self._gap_mark = math.inf
        self._since = 0
        return self.landed

    def limit(self, P: np.ndarray, g: np.ndarray, free: np.ndarray, cons: np.ndarray,
              C: np.ndarray) -> float:
        """Shorten the step from P to (``g`` on the free vertices, ``C`` on the pins) to the
        largest fold-free fraction ``a <= 1``: ``g`` is overwritten with the free
        vertices' new positions and the pins of P are moved. Returns ``a``."""
        if not self.active:
            return 1.0
        self._before = P.copy()
        Q = P.copy()
        Q[free] = g
        Q[cons] = C
        a = min(1.0, max_step(P, Q, self.faces, self.sign, self.floor))
        if a < 1.0:
            g -= (1.0 - a) * (g - P[free])
            if not self.landed:
                P[cons] += a * (C - P[cons])
        elif not self.landed:
            P[cons] = C
            self.landed = True
        if not self.landed:
            gap = float(np.abs(P[cons] - C).max())
            self._since += 1
            if gap <= 0.5 * self._gap_mark:
                self._gap_mark, self._since = gap, 0
            elif self._since >= STALL_ITERATIONS:
                self.release(P, cons, C)
        return a

    def admits(self, P: np.ndarray) -> bool:
        """Whether the straight path from the positions of the last :meth:`limit` to P
        keeps every unfolded triangle above its floor (an extrapolated step may be kept)."""
        if not self.active:
            return True
        return bool(max_step(self._before, P, self.faces, self.sign, self.floor) > 1.0)

    def release(self, P: np.ndarray, cons: np.ndarray, C: np.ndarray) -> None:
        """Give up: snap the pins onto their targets and let plain ARAP finish."""
        P[cons] = C
        self.landed = True
        self.active = False
        self.released = True
