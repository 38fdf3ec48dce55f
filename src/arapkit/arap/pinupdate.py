"""Adding and removing pins without refactorising: a bordered solve on the existing factor.

The global step solves ``A_11 x = r`` over the free vertices ``F1`` of a new constrained set,
with ``A`` the Laplacian. The factor at hand is of ``A_00`` over the free vertices ``F0`` of the
old set. Write ``G = F0 - added`` (still free), ``a = added`` (newly pinned) and ``d = dropped``
(newly free), so ``F1 = G + d``. The system we want is

    [A_GG  A_Gd] [x_G]   [r_G]
    [A_dG  A_dd] [x_d] = [r_d],

and it is the ``x_a = 0`` slice of the bordered system over ``F0 + d`` with a multiplier
``l`` per added vertex (``E`` selects the added vertices among ``F0``):

    [A_00   A_0d  E] [x_0]   [(r_G, 0)]
    [A_d0   A_dd  0] [x_d] = [r_d     ]
    [E^T    0     0] [l  ]   [0       ].

(The added rows of the first block read ``A_aG x_G + A_ad x_d + l = 0``: ``l`` absorbs them,
and ``x_a = 0`` leaves the G rows as the system above.) Eliminating ``x_0`` with the old
factor: with ``K = [A_0d, E]`` (``|F0| x s``, ``s = |d| + |a|``), ``Z = A_00^{-1} K`` and the
``s x s`` Schur complement ``S = M - K^T Z`` (``M = diag(A_dd, 0)``),

    y = S^{-1} ((r_d, 0) - K^T A_00^{-1} r_0),   x_0 = A_00^{-1} r_0 - Z y.

Building it costs ``s`` solves with the old factor (one multi-column solve) and an
``s x s`` inverse; every global step after costs one solve with the old factor and
``O(|F0| s)``. Past :data:`MAX_CHANGES` changed vertices a refactorisation is cheaper and
:meth:`UpdatedElimination.update` says so by returning None.

Examples
--------
>>> import numpy as np
>>> from arapkit.arap.constraints import Elimination
>>> E = np.array([[0, 1], [1, 2], [2, 3], [3, 4]]); w = np.ones(4)
>>> base = Elimination.from_edges(5, E, w, [0, 4], "chain")
>>> upd = UpdatedElimination.update(base, E, w, np.array([0, 2]), "chain")  # 4 out, 2 in
>>> ref = Elimination.from_edges(5, E, w, [0, 2], "chain")
>>> C = np.array([[0.0], [2.0]])
>>> bool(np.allclose(upd.solve(-upd.A_fc @ C), ref.solve(-ref.A_fc @ C)))
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import InputError
from .constraints import Elimination

__all__ = ["MAX_CHANGES", "UpdatedElimination"]

#: changed vertices (pinned plus unpinned) beyond which refactorising is the better deal
MAX_CHANGES = 64


@dataclass(frozen=True, eq=False)
class UpdatedElimination:
    """An :class:`~arapkit.arap.constraints.Elimination` for a new constrained set, solved
    with the factor of an old one (the module's bordered system).

    Attributes
    ----------
    free, constrained, slot, A_fc :
        As :class:`~arapkit.arap.constraints.Elimination`, for the new set.
    base : Elimination
        The eliminated system whose factor is reused (never itself an update).
    """

    free: np.ndarray
    constrained: np.ndarray
    slot: np.ndarray
    A_fc: sp.csr_matrix
    base: Elimination
    g_base: np.ndarray     # rows of G in the base's reduced numbering
    g_new: np.ndarray      # ... and in the new reduced numbering
    d_new: np.ndarray      # rows of the dropped (newly free) vertices in the new numbering
    K: sp.csc_matrix       # |F0| x s
    Z: np.ndarray          # A_00^{-1} K
    s_inv: np.ndarray | None  # inverse of the s x s Schur complement
    n_dropped: int

    @property
    def factor(self):
        """The reused factor (an updated elimination always has one)."""
        return self.base.factor

    @classmethod
    def update(cls, old, edges: np.ndarray, weights: np.ndarray, constrained,
               what: str = "mesh") -> UpdatedElimination | None:
        """The elimination of ``constrained`` from ``old``'s factor, or None where that
        does not pay (too many changes, or none to reuse).

        ``old`` may itself be an update: its base is reused, so a long editing session
        never stacks corrections.
        """
        base = old.base if isinstance(old, UpdatedElimination) else old
        if base.factor is None:
            return None
        n = len(base.slot)
        cons = np.asarray(constrained, dtype=np.int64)
        is_cons = np.zeros(n, dtype=bool)
        is_cons[cons] = True
        was_cons = base.slot < 0
        added = np.flatnonzero(is_cons & ~was_cons)
        dropped = np.flatnonzero(~is_cons & was_cons)
        s = len(added) + len(dropped)
        if s > MAX_CHANGES:
            return None
        free, slot = _split(n, cons)
        nf0 = len(base.free)
        # the blocks come straight from the edge list, as Elimination.from_edges does (a
        # full Laplacian and SciPy's fancy indexing took most of 16 ms at 10K vertices)
        ea, eb, w = edges[:, 0], edges[:, 1], weights
        cslot = np.full(n, -1, dtype=np.int64)
        cslot[cons] = np.arange(len(cons))
        fa, fb = slot[ea], slot[eb]
        ab, ba = (fa >= 0) & (fb < 0), (fb >= 0) & (fa < 0)
        A_fc = sp.csr_matrix((np.concatenate([-w[ab], -w[ba]]),
                              (np.concatenate([fa[ab], fb[ba]]),
                               np.concatenate([cslot[eb[ab]], cslot[ea[ba]]]))),
                             shape=(len(free), len(cons)))
        # K = [A_{F0, d}, E_a]: the dropped vertices' columns, then one unit per added one
        dcol = np.full(n, -1, dtype=np.int64)
        dcol[dropped] = np.arange(len(dropped))
        s0a, s0b = base.slot[ea], base.slot[eb]
        ab, ba = (s0a >= 0) & (dcol[eb] >= 0), (s0b >= 0) & (dcol[ea] >= 0)
        K = sp.csc_matrix((np.concatenate([-w[ab], -w[ba], np.ones(len(added))]),
                           (np.concatenate([s0a[ab], s0b[ba], base.slot[added]]),
                            np.concatenate([dcol[eb[ab]], dcol[ea[ba]],
                                            len(dropped) + np.arange(len(added))]))),
                          shape=(nf0, s))
        if s:
            Z = base.factor.solve(np.ascontiguousarray(K.toarray()))
            # M = diag(A_dd, 0): the dropped vertices' own block of the Laplacian
            M = np.zeros((s, s))
            nd = len(dropped)
            da, db = dcol[ea], dcol[eb]
            both = (da >= 0) & (db >= 0)
            np.add.at(M, (da[both], db[both]), -w[both])
            np.add.at(M, (db[both], da[both]), -w[both])
            touch = (da >= 0) | (db >= 0)
            deg = np.bincount(np.concatenate([da[touch & (da >= 0)], db[touch & (db >= 0)]]),
                              np.concatenate([w[touch & (da >= 0)], w[touch & (db >= 0)]]),
                              nd) if nd else np.zeros(0)
            M[np.arange(nd), np.arange(nd)] += deg
            S = M - K.T @ Z
            # the inverse of the small s x s matrix, once: SciPy's lu_solve took 2-25 ms a
            # call here (its LAPACK wrapper's overhead) against 1 us for the product
            cond = np.linalg.cond(S)
            if not np.isfinite(cond) or cond > 1e12:
                raise InputError(f"{what}: the system with these handles is singular "
                                 "(a part is left without a handle)")
            s_inv = np.linalg.inv(S)
        else:
            Z, s_inv = np.zeros((nf0, 0)), None
        keep = ~is_cons[base.free]  # G among the base's free vertices
        g_base = np.flatnonzero(keep)
        g_new = slot[base.free[keep]]
        d_new = slot[dropped]
        return cls(free, cons, slot, A_fc, base, g_base, g_new, d_new, K, Z, s_inv,
                   len(dropped))

    def solve(self, rhs: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``A_11^{-1} rhs`` for the new free vertices (``(f,)`` or ``(f, k)``)."""
        rhs = np.asarray(rhs, dtype=np.float64)
        R = rhs.reshape(len(rhs), -1)
        k = R.shape[1]
        r0 = np.zeros((len(self.base.free), k))
        r0[self.g_base] = R[self.g_new]
        y0 = self.base.factor.solve(r0)
        X = np.empty((len(self.free), k))
        if self.s_inv is not None:
            ry = np.zeros((self.K.shape[1], k))
            ry[:self.n_dropped] = R[self.d_new]
            y = self.s_inv @ (ry - self.K.T @ y0)
            y0 -= self.Z @ y
            X[self.d_new] = y[:self.n_dropped]
        X[self.g_new] = y0[self.g_base]
        X = X.reshape(rhs.shape)
        if out is None:
            return X
        out[...] = X
        return out


def _split(n: int, cons: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Free vertices and each vertex's row among them (-1: constrained)."""
    is_free = np.ones(n, dtype=bool)
    is_free[cons] = False
    free = np.flatnonzero(is_free)
    slot = np.full(n, -1, dtype=np.int64)
    slot[free] = np.arange(len(free))
    return free, slot
