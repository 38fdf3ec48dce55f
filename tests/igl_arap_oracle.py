"""Test-only oracle: libigl's ``arap_solve`` with groups ``G`` (spokes energy), step by step.

libigl's compiled ``arap_solve`` fits its rotations in single precision (``fit_rotations(S,
true, R)``, after scaling every covariance by the largest entry), so it sits a few 1e-6 of
the diagonal away from the same algorithm in double. This replica runs libigl's algorithm
with libigl's own pieces (``igl.cotmatrix``, ``igl.fit_rotations`` with its precision
flag): in single precision it reproduces ``igl.arap_solve`` to round-off, which shows it
is libigl's algorithm; in double it is the reference that arapkit must meet exactly. Used
by ``tests/test_groups.py`` and ``benchmarks/bench_groups.py``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spl


def igl_arap_groups(V: np.ndarray, F: np.ndarray, b: np.ndarray, bc: np.ndarray,
                    G: np.ndarray, iterations: int, single: bool) -> np.ndarray:
    """``iterations`` of libigl's spokes ARAP with groups ``G`` (one id per vertex, as
    libigl's ``ARAPData.G``), started from the rest shape with the handles snapped.

    ``single`` rounds the rotation fits as libigl's binary does.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar, bar_bend
    >>> m = bar(segments=(6, 2, 2)); h, t = bar_bend(m, 30)
    >>> U = igl_arap_groups(m.vertices, m.faces, h, t, np.arange(m.n_vertices), 3, False)
    >>> bool(np.abs(U[h] - t).max() < 1e-12)
    True
    """
    import igl

    n = len(V)
    L = igl.cotmatrix(V, np.asarray(F, dtype=np.int64)).tocoo()
    off = L.row != L.col
    Ia, Jb, W = L.row[off], L.col[off], L.data[off]  # each ordered pair (i, j), w_ij
    Gd = np.unique(G, return_inverse=True)[1].ravel()
    ng = int(Gd.max()) + 1
    b = np.asarray(b, dtype=np.int64)
    free = np.setdiff1d(np.arange(n), b)
    A = -L.tocsr()
    solve = spl.factorized(A[free][:, free].tocsc())
    Afc = A[free][:, b]
    U = np.array(V, dtype=np.float64)
    ev = V[Ia] - V[Jb]
    for _ in range(iterations):
        U[b] = bc
        eu = U[Ia] - U[Jb]
        Sk = np.zeros((n, 3, 3))
        np.add.at(Sk, Ia, W[:, None, None] * ev[:, :, None] * eu[:, None, :])
        Sg = np.zeros((ng, 3, 3))
        np.add.at(Sg, Gd, Sk)
        Sg /= np.abs(Sg).max()  # libigl's scaling for its single-precision fit
        # libigl's layout: row i * nr + r holds row i of S_r; R is 3 x 3 nr
        R = igl.fit_rotations(np.transpose(Sg, (1, 0, 2)).reshape(3 * ng, 3), single)
        Rg = R.reshape(3, ng, 3).transpose(1, 0, 2)[Gd]
        rhs = np.zeros((n, 3))
        np.add.at(rhs, Ia, 0.5 * W[:, None] * np.einsum("kab,kb->ka", Rg[Ia] + Rg[Jb], ev))
        U[free] = np.stack([solve(rhs[free, a] - Afc @ bc[:, a]) for a in range(3)], 1)
    U[b] = bc
    return U
