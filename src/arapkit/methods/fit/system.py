"""The fit's global step: one fixed matrix per stage, factorised once per template.

In a stage of stiffness length ``L`` every template vertex i carries the data weight
``lambda_i = a_i / L^2``: a vertex whose match is used is pulled towards its match, and a
vertex whose match is rejected towards where it is (a proximal term ``lambda_i |x_i -
x_i^k|^2``, which majorises the constant its rejected match contributes and vanishes at the
current iterate, so the energy still never rises). The matrix of the global step is then

    L_ff + diag(lambda_f) + delta I

whatever the matches are: it depends on the template, the landmark vertices and the stage
only, not on the target. :class:`StageSystems` factorises it once per stage and keeps the
factors for every later fit of the same template with the same landmark vertices (a
sequence of scans), so an iteration costs one pair of triangular solves and a fit none.
The stages' matrices differ in their diagonal only: one symbolic analysis serves them all
(:class:`~arapkit.methods.fit.ldl.SharedPattern`), and a stage's factor is a numeric
refactorisation (10-12 ms instead of 50 ms at 13,750 vertices).

The alternative, a matrix that changes with the matches (a factor at each stage's start,
then conjugate gradients preconditioned with it), needed a factorisation and 38-130 CG steps
a stage on every fit (measured in ``docs/fit.md``).

Examples
--------
>>> import numpy as np, scipy.sparse as sp
>>> L = sp.csr_matrix(np.array([[1.0, -1, 0], [-1, 2, -1], [0, -1, 1]]))
>>> s = StageSystems(L, np.array([0]), "chain")
>>> x = s.solve(0.5, np.ones(2), np.array([[0.0], [2.0]]) - s.L_fc @ np.array([[1.0]]))
>>> np.round(x.ravel(), 9).tolist(), s.factorisations
([0.8, 1.4], 1)
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from .ldl import LDLFactor, SharedPattern

__all__ = ["StageSystems"]


class StageSystems:
    """``L_ff + diag(w) + delta I`` of each stage, on the free vertices, with its factor.

    Parameters
    ----------
    L : (n, n) sparse symmetric positive semi-definite (the ARAP matrix).
    constrained : (c,) int, rows held at given values (the landmarks; eliminated).
    name : str, for messages.
    delta : float, a tiny proximal weight that keeps vertices without data (on no face)
        definite.
    """

    def __init__(self, L: sp.spmatrix, constrained: np.ndarray, name: str,
                 delta: float = 0.0) -> None:
        L = sp.csr_matrix(L)
        n = L.shape[0]
        is_free = np.ones(n, dtype=bool)
        is_free[constrained] = False
        self.free = np.flatnonzero(is_free)
        self.constrained = np.asarray(constrained, dtype=np.int64)
        self.slot = np.full(n, -1, dtype=np.int64)
        self.slot[self.free] = np.arange(len(self.free))
        Lf = L[self.free]
        self.L_ff = Lf[:, self.free].tocsr()
        self.L_fc = Lf[:, self.constrained].tocsr()
        self.name = name
        self.delta = float(delta)
        self._pattern = SharedPattern(self.L_ff, f"{name}: fit system")
        self._Ldiag = self.L_ff.diagonal()
        self._factors: dict[float, LDLFactor] = {}
        self.factorisations = 0
        self.factor_s = 0.0

    def factor(self, key: float, w: np.ndarray) -> LDLFactor:
        """The factor of ``L_ff + diag(w) + delta I`` for stage ``key`` (made on first use;
        ``w`` must be the same whenever ``key`` is)."""
        f = self._factors.get(key)
        if f is None:
            t0 = time.perf_counter()
            f = self._factors[key] = self._pattern.factor(
                self._Ldiag + np.asarray(w, dtype=np.float64) + self.delta)
            self.factorisations += 1
            self.factor_s += time.perf_counter() - t0
        return f

    def solve(self, key: float, w: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """Solve stage ``key``'s system (weights ``w``) for a (f, k) right-hand side."""
        return self.factor(key, w).solve(rhs)

