"""Compiled CPU kernels of the graph ARAP loss: energy and gradient in O(terms), no autograd.

For the terms of :class:`~arapkit.torch.neighbourhoods.GraphNeighbourhoods` (owner k, edge
(i, j), weight w), rest positions P and positions X, with residuals
``r_t = (x_i - x_j) - R_k (p_i - p_j)``:

    E = sum_t w_t |r_t|^2     (penalty "squared")  or  E = sum_t sqrt(w_t |r_t|^2 + eps)

:func:`graph_energy` fits ``R_k = argmax tr(R S_k)``, ``S_k = sum_t w_t d_t D_t^T`` (the
engine's compiled :func:`arapkit.arap.rotations.fit_rotation_range`, block by block as in
the engine's fused local step) or takes them given, and returns E with its gradient at
those rotations: with ``g_t = dE/dr_t`` (``2 w r``, or ``w r / sqrt(w |r|^2 + eps)``),
``dE/dx_v`` is the sum of ``g_t`` over the terms with ``i = v`` minus that over the terms
with ``j = v``, and ``dE/dR_k = -sum_t g_t d_t^T``. The gradient is gathered point by point
through the transposed term lists (no races, no atomics: the same answer for any thread
count). Everything runs in float64.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..arap.rotations import fit_rotation_range

__all__ = ["graph_energy"]


#: owners whose covariances and rotations a thread holds at once (as the engine's fused
#: local step): their terms are still in cache when the residuals read them again
_BLOCK = 256


@nb.njit(cache=True, nogil=True, inline="always")
def _covariance(X, P, ptr, ei, ej, w, k, S, b):
    """``S[b] = sum_t w_t (p_i - p_j) (x_i - x_j)^T`` over owner k's terms."""
    s00 = s01 = s02 = s10 = s11 = s12 = s20 = s21 = s22 = 0.0
    for t in range(ptr[k], ptr[k + 1]):
        i, j, wt = ei[t], ej[t], w[t]
        d0 = wt * (P[i, 0] - P[j, 0])
        d1 = wt * (P[i, 1] - P[j, 1])
        d2 = wt * (P[i, 2] - P[j, 2])
        e0 = X[i, 0] - X[j, 0]
        e1 = X[i, 1] - X[j, 1]
        e2 = X[i, 2] - X[j, 2]
        s00 += d0 * e0
        s01 += d0 * e1
        s02 += d0 * e2
        s10 += d1 * e0
        s11 += d1 * e1
        s12 += d1 * e2
        s20 += d2 * e0
        s21 += d2 * e1
        s22 += d2 * e2
    S[b, 0, 0], S[b, 0, 1], S[b, 0, 2] = s00, s01, s02
    S[b, 1, 0], S[b, 1, 1], S[b, 1, 2] = s10, s11, s12
    S[b, 2, 0], S[b, 2, 1], S[b, 2, 2] = s20, s21, s22


@nb.njit(cache=True, nogil=True, inline="always")
def _residuals(X, P, ptr, ei, ej, w, R, k, norm, eps, want_gR, Ek, g, gR):
    """Owner k's energy ``Ek[k]``, its ``g_t = dE/dr_t`` and (``want_gR``) ``dE/dR_k``."""
    r00, r01, r02 = R[k, 0, 0], R[k, 0, 1], R[k, 0, 2]
    r10, r11, r12 = R[k, 1, 0], R[k, 1, 1], R[k, 1, 2]
    r20, r21, r22 = R[k, 2, 0], R[k, 2, 1], R[k, 2, 2]
    acc = 0.0
    h00 = h01 = h02 = h10 = h11 = h12 = h20 = h21 = h22 = 0.0
    for t in range(ptr[k], ptr[k + 1]):
        i, j, wt = ei[t], ej[t], w[t]
        d0 = P[i, 0] - P[j, 0]
        d1 = P[i, 1] - P[j, 1]
        d2 = P[i, 2] - P[j, 2]
        q0 = (X[i, 0] - X[j, 0]) - (r00 * d0 + r01 * d1 + r02 * d2)
        q1 = (X[i, 1] - X[j, 1]) - (r10 * d0 + r11 * d1 + r12 * d2)
        q2 = (X[i, 2] - X[j, 2]) - (r20 * d0 + r21 * d1 + r22 * d2)
        s = q0 * q0 + q1 * q1 + q2 * q2
        if norm:
            root = math.sqrt(wt * s + eps)
            acc += root
            c = wt / root if root > 0.0 else 0.0
        else:
            acc += wt * s
            c = 2.0 * wt
        g0, g1, g2 = c * q0, c * q1, c * q2
        g[t, 0], g[t, 1], g[t, 2] = g0, g1, g2
        if want_gR:
            h00 -= g0 * d0
            h01 -= g0 * d1
            h02 -= g0 * d2
            h10 -= g1 * d0
            h11 -= g1 * d1
            h12 -= g1 * d2
            h20 -= g2 * d0
            h21 -= g2 * d1
            h22 -= g2 * d2
    Ek[k] = acc
    if want_gR:
        gR[k, 0, 0], gR[k, 0, 1], gR[k, 0, 2] = h00, h01, h02
        gR[k, 1, 0], gR[k, 1, 1], gR[k, 1, 2] = h10, h11, h12
        gR[k, 2, 0], gR[k, 2, 1], gR[k, 2, 2] = h20, h21, h22


@nb.njit(parallel=True, cache=True, nogil=True)
def owner_pass(X, P, ptr, ei, ej, w, fit, R, norm, eps, want_gR, Ek, g, gR):
    """Per owner, block by block: (``fit``) ``S_k`` and ``R_k`` into ``R``; then its energy,
    ``g_t`` and ``dE/dR_k``."""
    n = len(ptr) - 1
    for c in nb.prange((n + _BLOCK - 1) // _BLOCK):
        k0 = c * _BLOCK
        k1 = min(n, k0 + _BLOCK)
        if fit:
            S = np.empty((_BLOCK, 3, 3))
            for k in range(k0, k1):
                _covariance(X, P, ptr, ei, ej, w, k, S, k - k0)
            fit_rotation_range(S, R[k0:k1], 0, k1 - k0)
        for k in range(k0, k1):
            _residuals(X, P, ptr, ei, ej, w, R, k, norm, eps, want_gR, Ek, g, gR)


@nb.njit(parallel=True, cache=True, nogil=True)
def gather_gradient(g, ti_ptr, ti_idx, tj_ptr, tj_idx, G):
    """``G_v = sum_{t: i_t = v} g_t - sum_{t: j_t = v} g_t``, point by point."""
    for v in nb.prange(len(ti_ptr) - 1):
        a0 = a1 = a2 = 0.0
        for q in range(ti_ptr[v], ti_ptr[v + 1]):
            t = ti_idx[q]
            a0 += g[t, 0]
            a1 += g[t, 1]
            a2 += g[t, 2]
        for q in range(tj_ptr[v], tj_ptr[v + 1]):
            t = tj_idx[q]
            a0 -= g[t, 0]
            a1 -= g[t, 1]
            a2 -= g[t, 2]
        G[v, 0], G[v, 1], G[v, 2] = a0, a1, a2


@nb.njit(parallel=True, cache=True, nogil=True)
def gather_rows(src, idx, out):
    """``out[a] = src[idx[a]]`` (rows, any float types: one pass that converts); returns
    how many entries were not finite (checked on the way, so that no torch operation runs
    between the kernels: two thread pools in turn wait for each other's spinning threads)."""
    bad = 0
    for a in nb.prange(len(idx)):
        row_bad = 0
        for c in range(src.shape[1]):
            v = src[idx[a], c]
            out[a, c] = v
            if not math.isfinite(v):
                row_bad += 1
        bad += row_bad
    return bad


def graph_energy(X: np.ndarray, P: np.ndarray, nbh, R: np.ndarray, fit: bool = True,
                 norm: bool = False, eps: float = 0.0, gR: np.ndarray | None = None,
                 G: np.ndarray | None = None, g: np.ndarray | None = None
                 ) -> tuple[float, np.ndarray]:
    """Energy and gradient of one pose (see the module docstring).

    Parameters
    ----------
    X, P : (n, 3) float64, C-contiguous
        Positions and rest positions.
    nbh : GraphNeighbourhoods
    R : (n, 3, 3) float64, C-contiguous
        The rotations: fitted to X and written here (``fit``), else given.
    norm, eps :
        ``penalty="norm"`` and the constant under its root.
    gR : (n, 3, 3) float64, optional
        Where to write ``dE/dR``, if wanted.
    G : (n, 3) float64, optional
        Where to write ``dE/dX`` (a new array if None).
    g : (M, 3) float64, optional
        Scratch for the terms' ``g_t`` (reused across calls: a fresh 50 MB array at 100K
        points costs its page faults on every call).

    Returns
    -------
    E : float
    G : (n, 3) float64
        ``dE/dX`` at the rotations used.

    Examples
    --------
    >>> from arapkit.torch.neighbourhoods import graph_neighbourhoods
    >>> P = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> nbh = graph_neighbourhoods(P, 2, weights="uniform")
    >>> R = np.empty((4, 3, 3))
    >>> E, G = graph_energy(P @ np.diag([1.0, 1, 2]), P, nbh, R)  # stretched along z
    >>> E > 0, bool(np.allclose(G.sum(axis=0), 0))  # translation-invariant
    (True, True)
    """
    n = nbh.n
    Ek = np.empty(n)
    if g is None:
        g = np.empty((nbh.n_terms, 3))
    want_gR = gR is not None
    owner_pass(X, P, nbh.ptr, nbh.ei, nbh.ej, nbh.w, fit, R, norm, eps, want_gR, Ek, g,
               gR if want_gR else np.empty((0, 3, 3)))
    if G is None:
        G = np.empty((n, 3))
    gather_gradient(g, nbh.ti_ptr, nbh.ti_idx, nbh.tj_ptr, nbh.tj_idx, G)
    return float(Ek.sum()), G
