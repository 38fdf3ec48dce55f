"""Anderson acceleration of fixed-point iterations (Peng, Deng, Zhang, Liu 2018).

For a local/global solver ``x_{t+1} = G(x_t)`` Anderson acceleration extrapolates from the
last ``m`` iterates: with ``f_t = G(x_t) - x_t`` and the differences ``dF``, ``dG`` of the
last ``m`` residuals and images, ``theta = argmin |f_t - dF theta|`` and the accelerated
iterate is ``G(x_t) - dG theta``. The caller keeps the energy safeguard (accept only when
the accelerated iterate lowers the energy, else fall back to ``G(x_t)``), see
:func:`arapkit.arap.loop.local_global`.

The vectors are long (three coordinates per free vertex), so the updates are compiled,
single-pass kernels; the ``m x m`` normal equations are updated one row per iteration.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["Anderson"]


@nb.njit(parallel=True, cache=True, nogil=True)
def _push(x, g, f_prev, g_prev, dF, dG, j, k, n_chunks, part_M, part_r):
    """Store column j of dF, dG; shift f_prev, g_prev; partial dots for row j and dF^T f.

    One pass over the vectors: the history columns are read once per iteration.
    """
    n = x.shape[0]
    size = (n + n_chunks - 1) // n_chunks
    for c in nb.prange(n_chunks):
        for i in range(k):
            part_M[c, i] = 0.0
            part_r[c, i] = 0.0
        for t in range(c * size, min(n, (c + 1) * size)):
            f = g[t] - x[t]
            df = f - f_prev[t]
            dF[j, t] = df
            dG[j, t] = g[t] - g_prev[t]
            f_prev[t] = f
            g_prev[t] = g[t]
            for i in range(k):
                part_M[c, i] += df * dF[i, t]
                part_r[c, i] += dF[i, t] * f


@nb.njit(parallel=True, cache=True, nogil=True)
def _start(x, g, f_prev, g_prev):
    for t in nb.prange(x.shape[0]):
        f_prev[t] = g[t] - x[t]
        g_prev[t] = g[t]


@nb.njit(parallel=True, cache=True, nogil=True)
def _combine(g, dG, theta, out):
    k = theta.shape[0]
    for t in nb.prange(g.shape[0]):
        acc = g[t]
        for i in range(k):
            acc -= theta[i] * dG[i, t]
        out[t] = acc


class Anderson:
    """Anderson acceleration (type II) with a history of ``m`` iterates.

    Parameters
    ----------
    dim : int
        Length of the (flattened) iterate.
    m : int
        History size (Peng et al. use 5 or 6 for local/global solvers).

    Examples
    --------
    >>> import numpy as np
    >>> aa = Anderson(2, m=3)
    >>> G = lambda x: 0.5 * x + 1.0          # fixed point at 2
    >>> x = np.zeros(2)
    >>> for _ in range(4):
    ...     y = aa.step(x, G(x))
    ...     x = G(x) if y is None else y
    >>> np.allclose(x, 2.0)
    True
    """

    def __init__(self, dim: int, m: int = 5) -> None:
        if m < 1:
            raise ValueError("Anderson history m must be >= 1")
        self.dim = int(dim)
        self.m = int(m)
        self.dF = np.empty((self.m, self.dim))
        self.dG = np.empty((self.m, self.dim))
        self.f_prev = np.empty(self.dim)
        self.g_prev = np.empty(self.dim)
        self.M = np.zeros((self.m, self.m))
        self.n_chunks = max(1, min(self.dim // 4096, 4 * nb.get_num_threads()))
        self._pM = np.zeros((self.n_chunks, self.m))
        self._pr = np.zeros((self.n_chunks, self.m))
        self.count = 0

    def reset(self) -> None:
        """Forget the history (the next :meth:`step` only records)."""
        self.count = 0

    def step(self, x: np.ndarray, g: np.ndarray, out: np.ndarray | None = None):
        """Record ``(x, G(x))`` and return the accelerated iterate, or None without history.

        Parameters
        ----------
        x, g : (dim,) or any C-contiguous shape with ``dim`` elements
            Current iterate and its image under the fixed-point map.
        out : optional array like ``g`` to write the result into.
        """
        xf = x.reshape(-1)
        gf = g.reshape(-1)
        if self.count == 0:
            _start(xf, gf, self.f_prev, self.g_prev)
            self.count = 1
            return None
        j = (self.count - 1) % self.m
        k = min(self.count, self.m)
        _push(xf, gf, self.f_prev, self.g_prev, self.dF, self.dG, j, k, self.n_chunks,
              self._pM, self._pr)
        row = self._pM[:, :k].sum(axis=0)
        rhs = self._pr[:, :k].sum(axis=0)
        self.M[j, :k] = row
        self.M[:k, j] = row
        self.count += 1
        M = self.M[:k, :k]
        # the normal equations lose half the digits; a relative ridge keeps theta bounded
        # when consecutive residuals are nearly parallel (near convergence)
        scale = max(float(np.trace(M)) / k, 1e-300)
        try:
            theta = np.linalg.solve(M + 1e-10 * scale * np.eye(k), rhs)
        except np.linalg.LinAlgError:
            return None
        if not np.all(np.isfinite(theta)):
            return None
        res = np.empty_like(g) if out is None else out
        _combine(gf, self.dG[:k], theta, res.reshape(-1))
        return res
