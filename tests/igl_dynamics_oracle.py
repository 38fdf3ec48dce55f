"""Test oracle: libigl's ``arap_solve`` with ``with_dynamics``, transcribed from its source.

libigl's Python package (``pip install libigl``, a test dependency) exposes
``ARAPData.with_dynamics``, ``h``, ``ym``, ``f_ext`` and ``vel``, so its compiled
``arap_solve`` is the first oracle. Its local step, though, fits the rotations with
McAdams et al.'s single-precision 3x3 SVD (``fit_rotations(S, true, R)`` in
``arap.cpp``), which limits any agreement with it to float32 round-off of the rotations
(about 5e-7 of the bounding-box diagonal after 30 steps on the bar).

This module is the second oracle: the update formulas of libigl's ``include/igl/arap.cpp``
(commit 0cbcaf8, ``arap_precomputation`` and ``arap_solve`` with ``with_dynamics``) and of
``arap_linear_block.cpp``, ``covariance_scatter_matrix.cpp``, ``arap_rhs.cpp`` and
``columnize.cpp`` written out in NumPy, on libigl's own Python building blocks
(``cotmatrix``, ``cotmatrix_entries``, ``massmatrix``, ``fit_rotations``).
``single_precision=True`` runs libigl's float32 rotation fit, and then this transcription
agrees with the compiled ``arap_solve`` to round-off (checked by the tests): that shows the
transcription is libigl's algorithm. ``single_precision=False`` runs libigl's own
double-precision fit (``polar_svd``), and arapkit's compatibility mode must agree with
that to 1e-8 of the diagonal. Nothing here is arapkit's code.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

#: libigl's triangle edges, in the column order of ``cotmatrix_entries``
_EDGES = ((1, 2), (2, 0), (0, 1))


def arap_linear_block(V: np.ndarray, F: np.ndarray, d: int, energy: str) -> sp.csr_matrix:
    """``arap_linear_block_spokes`` / ``_spokes_and_rims`` for coordinate ``d`` (n x n)."""
    import igl

    n = len(V)
    C = igl.cotmatrix_entries(V, F.astype(np.int64))
    rows, cols, vals = [], [], []

    def add(i, j, v):
        rows.append(i)
        cols.append(j)
        vals.append(v)

    for e, (a, b) in enumerate(_EDGES):
        s, t = F[:, a], F[:, b]
        if energy == "spokes":
            v = 0.5 * C[:, e] * (V[s, d] - V[t, d])
            add(s, t, v), add(t, s, -v), add(s, s, v), add(t, t, -v)
        else:  # spokes and rims: the loop over the triangle's edges, its three cases
            v = C[:, e] * (V[s, d] - V[t, d]) / 3.0
            c = F[:, 3 - a - b]  # the third corner
            add(s, t, v), add(t, s, -v)  # the same edge
            add(t, c, -v)  # the edge that starts at dest: (Rs, Rd, -v)
            add(s, c, v)  # the edge that ends at source: (Rd, Rs, v)
            add(s, s, v), add(t, t, -v)
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n, n))


class LibiglArapDynamics:
    """libigl's ``ARAPData`` after ``arap_precomputation`` with ``with_dynamics = true``.

    Parameters
    ----------
    V, F : the mesh; b : handle vertices; h, ym : libigl's ``data.h`` and ``data.ym``;
    energy : "spokes" or "spokes-and-rims"; max_iter : ``data.max_iter``.
    """

    def __init__(self, V, F, b, h: float, ym: float = 1.0, energy: str = "spokes-and-rims",
                 max_iter: int = 10) -> None:
        import igl

        V = np.asarray(V, dtype=np.float64)
        F = np.asarray(F, dtype=np.int64)
        n = len(V)
        self.n, self.b, self.h, self.ym, self.max_iter = n, np.asarray(b), h, ym, max_iter
        L = igl.cotmatrix(V, F)
        Kd = [arap_linear_block(V, F, d, energy) for d in range(3)]
        # covariance_scatter_matrix: blkdiag(KX, KY, KZ)^T, then G_sum = identity
        self.CSM = sp.block_diag([K.T for K in Kd]).tocsr()
        # arap_rhs: K = [repdiag(KX, 3), repdiag(KY, 3), repdiag(KZ, 3)]
        self.K = sp.hstack([sp.block_diag([K] * 3) for K in Kd]).tocsr()
        self.M = igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_VORONOI)
        dw = (1.0 / ym) * (h * h)
        Q = (-L + dw * 1.0 / (h * h) * self.M).tocsc()
        self.f_ext = np.zeros((n, 3))
        self.vel = np.zeros((n, 3))
        free = np.setdiff1d(np.arange(n), self.b)
        self.free = free
        self.Q_fb = Q[free][:, self.b]
        self.solve_ff = spla.factorized(Q[free][:, free].tocsc())

    def solve(self, bc: np.ndarray, U: np.ndarray, single_precision: bool = False) -> np.ndarray:
        """``arap_solve(bc, data, U)``: ``max_iter`` iterations; updates ``vel``."""
        import igl

        n, h = self.n, self.h
        U = np.array(U, dtype=np.float64)
        U0 = U.copy()
        for _ in range(self.max_iter):
            U[self.b] = bc
            S = self.CSM @ np.vstack([U, U, U])
            S /= np.abs(S).max()  # "important to get single precision SVD code to work"
            R = igl.fit_rotations(S, single_precision)  # 3 x 3k, block r = R_r^T
            k = R.shape[1] // 3
            blocks = R.reshape(3, k, 3)  # blocks[i, b, j] = R(i, 3 b + j)
            # columnize(R, k, 2): B(j*3*k + i*k + b) = R(i, b*3 + j)
            Rcol = blocks.transpose(2, 0, 1).ravel()
            Bcol = -(self.K @ Rcol)
            dw = (1.0 / self.ym) * (h * h)
            Dl = dw * (1.0 / (h * h) * (self.M @ (-U0 - h * self.vel)) - self.f_ext)
            for c in range(3):
                Bc = Bcol[c * n:(c + 1) * n] + Dl[:, c]
                # min_quad_with_fixed: minimise x'Qx/2 + x'B with x(b) = bc
                x = np.empty(n)
                x[self.b] = bc[:, c]
                x[self.free] = self.solve_ff(-Bc[self.free] - self.Q_fb @ bc[:, c])
                U[:, c] = x
        self.vel = (U - U0) / h
        return U
