"""Best-fit rotations for covariance matrices (the ARAP local step).

For a covariance ``S = sum_e w_e e_e e'_e^T`` (rest edge times deformed edge), the
rotation that minimises ``sum_e w_e |e'_e - R e_e|^2`` maximises ``tr(R S)``; with
``S = U Sigma V^T`` it is ``R = V U^T``, with the column of ``U`` that belongs to the
smallest singular value negated when ``det(V U^T) < 0`` (Sorkine & Alexa 2007).

Algorithm
---------
A hand-written 3x3 SVD in double precision, in the spirit of McAdams et al. (2011),
"Computing the singular value decomposition of 3x3 matrices with minimal branching":

1. ``S`` is divided by its largest entry, so that ``S^T S`` can neither overflow nor
   underflow whatever the scale of the input.
2. ``A = S^T S = V Sigma^2 V^T`` is diagonalised by cyclic Jacobi rotations (exact
   rotations, quadratic convergence: three or four sweeps reach double precision).
   ``V`` is a product of rotations, so ``det V = +1`` without any test.
3. The columns of ``V`` are sorted by decreasing ``sigma^2`` (each swap negates a
   column to keep ``det V = +1``).
4. ``B = S V`` has columns ``sigma_i u_i``.  ``u_1`` and ``u_2`` come from Gram-Schmidt
   on the two leading columns and ``u_3 = u_1 x u_2``, so ``U`` is a proper rotation as
   well, and the sign of ``det S`` falls on the smallest singular value exactly as the
   reflection fix requires.  ``R = V U^T`` is therefore orthonormal to rounding error and
   has ``det R = +1`` by construction, for any input.

Forming ``S^T S`` squares the condition number, which only matters when the second
singular value is tiny compared with the first (a nearly collinear neighbourhood): then
the ``(v_2, v_3)`` plane is re-diagonalised by a one-sided Jacobi rotation on the
columns of ``B`` (which sees ``S`` itself, not its square), and a rank-one ``S`` gets
an arbitrary ``u_2`` orthogonal to ``u_1`` (every such choice is optimal).
``S = 0`` gives the identity.

:func:`fit_rotations` runs a branch-free version (four fixed sweeps) on blocks of
matrices laid out so that LLVM vectorises it across matrices (AVX2/AVX-512), and sends
the rare matrices it cannot vouch for (degenerate, unconverged, zero or non-finite) to
the scalar kernel :func:`rotation_from_covariance`.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..errors import InputError

# Largest off-diagonal norm of the Jacobi-rotated Gram matrix, relative to its trace,
# that counts as converged.  tr(R S) is only second-order sensitive to it; R itself is
# then accurate to ~1e-14 / kappa, kappa = (sigma_2 + sign(det S) sigma_3) / sigma_1.
# Rounding leaves the off-diagonal at ~1e-16, far below, so convergence always happens.
_JACOBI_TOL = 1e-14
# Cyclic Jacobi converges quadratically: 3 sweeps for ~3/4 of random matrices, 4 for
# the rest.  The cap is a safety net only.
_MAX_SWEEPS = 16
# Below this ratio sigma_2^2 / sigma_1^2 the Gram matrix has lost too many digits of
# sigma_2 (and of the (u_2, u_3) plane) and the one-sided fix-up is applied.
_DEGENERATE = 1e-6
# sigma_2 / sigma_1 below which S is treated as rank one (costs at most ~2e-13 of tr).
_RANK_ONE = 1e-13
# Jacobi pivots at or below this are left alone: the matrices they act on are scaled
# to trace >= 1 (pivots of the one-sided fix-up scale with sigma_2^2, where skipping
# costs at most ~1e-70 of tr), and squares of anything larger do not underflow.
_NEGLIGIBLE = 1e-140
# Matrices per vectorised block; a multiple of the widest SIMD width.
_LANES = 64
# Matrices per parallel work item (a multiple of _LANES).
_CHUNK = 2048

_inline = nb.njit(inline="always", cache=True, error_model="numpy")


@_inline
def _jacobi_angle(app: float, aqq: float, apq: float) -> tuple[float, float, float]:
    # (t, c, s) of the rotation zeroing apq (Golub & Van Loan, Alg. 8.5.1, |t| <= 1),
    # with h = |(d, 2 apq)|: t = 2 apq sign(d) / (|d| + h), c^2 = (|d| + h) / (2 h).
    # Taking c from h rather than as 1 / sqrt(1 + t^2) takes one sqrt-then-divide off
    # the dependency chain (~15% faster).  The formula needs h^2 not to underflow,
    # which holds unless apq is negligible, and then the rotation is skipped (as a
    # blend, so that the vectorised kernel stays branch-free).
    d = aqq - app
    h = math.sqrt(d * d + 4.0 * apq * apq)
    e = abs(d) + h
    t = 2.0 * apq * math.copysign(1.0, d) / e
    c = math.sqrt(e / (2.0 * h))
    skip = abs(apq) <= _NEGLIGIBLE
    return (0.0 if skip else t), (1.0 if skip else c), (0.0 if skip else t * c)


@_inline
def _apply(
    s00: float, s01: float, s02: float, s10: float, s11: float, s12: float,
    s20: float, s21: float, s22: float, x: float, y: float, z: float,
) -> tuple[float, float, float]:
    # S (row major) times the column (x, y, z)
    return (
        s00 * x + s01 * y + s02 * z,
        s10 * x + s11 * y + s12 * z,
        s20 * x + s21 * y + s22 * z,
    )


@_inline
def _rotate(
    c: float, s: float, x0: float, x1: float, x2: float, y0: float, y1: float, y2: float
) -> tuple[float, float, float, float, float, float]:
    return (
        c * x0 - s * y0,
        c * x1 - s * y1,
        c * x2 - s * y2,
        s * x0 + c * y0,
        s * x1 + c * y1,
        s * x2 + c * y2,
    )


@_inline
def _max_abs9(
    s00: float,
    s01: float,
    s02: float,
    s10: float,
    s11: float,
    s12: float,
    s20: float,
    s21: float,
    s22: float,
) -> float:
    m0 = max(max(abs(s00), abs(s01)), max(abs(s02), abs(s10)))
    m1 = max(max(abs(s11), abs(s12)), max(abs(s20), abs(s21)))
    return max(max(m0, m1), abs(s22))


@_inline
def _gram(
    s00: float,
    s01: float,
    s02: float,
    s10: float,
    s11: float,
    s12: float,
    s20: float,
    s21: float,
    s22: float,
) -> tuple[float, float, float, float, float, float]:
    return (
        s00 * s00 + s10 * s10 + s20 * s20,
        s01 * s01 + s11 * s11 + s21 * s21,
        s02 * s02 + s12 * s12 + s22 * s22,
        s00 * s01 + s10 * s11 + s20 * s21,
        s00 * s02 + s10 * s12 + s20 * s22,
        s01 * s02 + s11 * s12 + s21 * s22,
    )


@_inline
def _sweep(
    a00: float,
    a11: float,
    a22: float,
    a01: float,
    a02: float,
    a12: float,
    v00: float,
    v10: float,
    v20: float,
    v01: float,
    v11: float,
    v21: float,
    v02: float,
    v12: float,
    v22: float,
) -> tuple[float, ...]:
    # One cyclic Jacobi sweep over the pairs (0,1), (0,2), (1,2) of the symmetric A,
    # accumulating the rotations into the columns of V (v_ij = V[i, j]).
    t, c, s = _jacobi_angle(a00, a11, a01)
    a00, a11, a01 = a00 - t * a01, a11 + t * a01, 0.0
    a02, a12 = c * a02 - s * a12, s * a02 + c * a12
    v00, v10, v20, v01, v11, v21 = _rotate(c, s, v00, v10, v20, v01, v11, v21)
    t, c, s = _jacobi_angle(a00, a22, a02)
    a00, a22, a02 = a00 - t * a02, a22 + t * a02, 0.0
    a01, a12 = c * a01 - s * a12, s * a01 + c * a12
    v00, v10, v20, v02, v12, v22 = _rotate(c, s, v00, v10, v20, v02, v12, v22)
    t, c, s = _jacobi_angle(a11, a22, a12)
    a11, a22, a12 = a11 - t * a12, a22 + t * a12, 0.0
    a01, a02 = c * a01 - s * a02, s * a01 + c * a02
    v01, v11, v21, v02, v12, v22 = _rotate(c, s, v01, v11, v21, v02, v12, v22)
    return a00, a11, a22, a01, a02, a12, v00, v10, v20, v01, v11, v21, v02, v12, v22


@_inline
def _sort_desc(
    a00: float,
    a11: float,
    a22: float,
    v00: float,
    v10: float,
    v20: float,
    v01: float,
    v11: float,
    v21: float,
    v02: float,
    v12: float,
    v22: float,
) -> tuple[float, ...]:
    # Sorting network on the eigenvalues; every swap negates one column of V so that
    # det V stays +1.  Written with conditional expressions only, which LLVM turns
    # into blends in the vectorised kernel.
    sw = a00 < a11
    a00, a11 = (a11 if sw else a00), (a00 if sw else a11)
    v00, v01 = (v01 if sw else v00), (-v00 if sw else v01)
    v10, v11 = (v11 if sw else v10), (-v10 if sw else v11)
    v20, v21 = (v21 if sw else v20), (-v20 if sw else v21)
    sw = a00 < a22
    a00, a22 = (a22 if sw else a00), (a00 if sw else a22)
    v00, v02 = (v02 if sw else v00), (-v00 if sw else v02)
    v10, v12 = (v12 if sw else v10), (-v10 if sw else v12)
    v20, v22 = (v22 if sw else v20), (-v20 if sw else v22)
    sw = a11 < a22
    a11, a22 = (a22 if sw else a11), (a11 if sw else a22)
    v01, v02 = (v02 if sw else v01), (-v01 if sw else v02)
    v11, v12 = (v12 if sw else v11), (-v11 if sw else v12)
    v21, v22 = (v22 if sw else v21), (-v21 if sw else v22)
    return a00, a11, a22, v00, v10, v20, v01, v11, v21, v02, v12, v22


@_inline
def _compose(
    v00: float,
    v10: float,
    v20: float,
    v01: float,
    v11: float,
    v21: float,
    v02: float,
    v12: float,
    v22: float,
    u00: float,
    u10: float,
    u20: float,
    u01: float,
    u11: float,
    u21: float,
) -> tuple[float, ...]:
    # R = V U^T with u_3 = u_1 x u_2, which makes det U = +1 and puts the sign of
    # det S on the smallest singular value.
    u02 = u10 * u21 - u20 * u11
    u12 = u20 * u01 - u00 * u21
    u22 = u00 * u11 - u10 * u01
    return (
        v00 * u00 + v01 * u01 + v02 * u02,
        v00 * u10 + v01 * u11 + v02 * u12,
        v00 * u20 + v01 * u21 + v02 * u22,
        v10 * u00 + v11 * u01 + v12 * u02,
        v10 * u10 + v11 * u11 + v12 * u12,
        v10 * u20 + v11 * u21 + v12 * u22,
        v20 * u00 + v21 * u01 + v22 * u02,
        v20 * u10 + v21 * u11 + v22 * u12,
        v20 * u20 + v21 * u21 + v22 * u22,
    )


@_inline
def _smallest_rotation(
    a0: float, a1: float, a2: float, b0: float, b1: float, b2: float
) -> tuple[float, ...]:
    # Rank-one S = sigma u_1 v_1^T: every rotation with R u_1 = v_1 is optimal. Pick the
    # one closest to the identity (the turn about n = u_1 x v_1), so that the choice is
    # continuous and a neighbourhood that has not turned gets no spurious spin (an
    # arbitrary pick makes ARAP on the box bar kink at its edges). It is built as V U^T
    # from the frames (u_1, n, u_1 x n) and (v_1', n, v_1' x n), both orthonormal to
    # rounding even when u_1 and v_1 are nearly opposite (where Rodrigues' 1 / (1 + c)
    # amplifies rounding).
    n0, n1, n2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    nn = n0 * n0 + n1 * n1 + n2 * n2
    if nn <= 1e-300:
        if a0 * b0 + a1 * b1 + a2 * b2 > 0.0:
            return 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
        # opposite: a half turn about the axis orthogonal to u_1 least aligned with it
        ax, ay, az = abs(a0), abs(a1), abs(a2)
        if ax <= ay and ax <= az:
            n0, n1, n2 = 1.0 - a0 * a0, -a0 * a1, -a0 * a2
        elif ay <= az:
            n0, n1, n2 = -a1 * a0, 1.0 - a1 * a1, -a1 * a2
        else:
            n0, n1, n2 = -a2 * a0, -a2 * a1, 1.0 - a2 * a2
    # n exactly orthogonal to u_1, then v_1' = v_1 made exactly orthogonal to n
    p = n0 * a0 + n1 * a1 + n2 * a2
    n0, n1, n2 = n0 - p * a0, n1 - p * a1, n2 - p * a2
    q = 1.0 / math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    n0, n1, n2 = n0 * q, n1 * q, n2 * q
    p = b0 * n0 + b1 * n1 + b2 * n2
    b0, b1, b2 = b0 - p * n0, b1 - p * n1, b2 - p * n2
    q = 1.0 / math.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
    b0, b1, b2 = b0 * q, b1 * q, b2 * q
    c0, c1, c2 = b1 * n2 - b2 * n1, b2 * n0 - b0 * n2, b0 * n1 - b1 * n0
    return _compose(b0, b1, b2, n0, n1, n2, c0, c1, c2, a0, a1, a2, n0, n1, n2)


@_inline
def _finish_regular(
    s00: float,
    s01: float,
    s02: float,
    s10: float,
    s11: float,
    s12: float,
    s20: float,
    s21: float,
    s22: float,
    v00: float,
    v10: float,
    v20: float,
    v01: float,
    v11: float,
    v21: float,
    v02: float,
    v12: float,
    v22: float,
) -> tuple[float, ...]:
    # u_1, u_2 from Gram-Schmidt on S v_1, S v_2.  Valid when sigma_2 is not tiny
    # relative to sigma_1, so that S v_2 is far from zero and already nearly
    # orthogonal to u_1: a single projection keeps |u_1 . u_2| at rounding level.
    b00, b10, b20 = _apply(
        s00, s01, s02, s10, s11, s12, s20, s21, s22, v00, v10, v20)
    b01, b11, b21 = _apply(
        s00, s01, s02, s10, s11, s12, s20, s21, s22, v01, v11, v21)
    n = 1.0 / math.sqrt(b00 * b00 + b10 * b10 + b20 * b20)
    u00, u10, u20 = b00 * n, b10 * n, b20 * n
    p = u00 * b01 + u10 * b11 + u20 * b21
    w0, w1, w2 = b01 - p * u00, b11 - p * u10, b21 - p * u20
    n = 1.0 / math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    return _compose(
        v00, v10, v20, v01, v11, v21, v02, v12, v22, u00, u10, u20, w0 * n, w1 * n, w2 * n
    )


@_inline
def _finish_degenerate(
    s00: float,
    s01: float,
    s02: float,
    s10: float,
    s11: float,
    s12: float,
    s20: float,
    s21: float,
    s22: float,
    v00: float,
    v10: float,
    v20: float,
    v01: float,
    v11: float,
    v21: float,
    v02: float,
    v12: float,
    v22: float,
) -> tuple[float, ...]:
    # sigma_2 << sigma_1: the (v_2, v_3) plane from the Gram matrix is only accurate to
    # ~eps sigma_1^2 / sigma_2^2, so re-diagonalise that plane with a one-sided Jacobi
    # rotation on the columns S v_2, S v_3 (relative accuracy eps sigma_1 / sigma_2).
    b00, b10, b20 = _apply(
        s00, s01, s02, s10, s11, s12, s20, s21, s22, v00, v10, v20)
    b01, b11, b21 = _apply(
        s00, s01, s02, s10, s11, s12, s20, s21, s22, v01, v11, v21)
    b02, b12, b22 = _apply(
        s00, s01, s02, s10, s11, s12, s20, s21, s22, v02, v12, v22)
    al = b01 * b01 + b11 * b11 + b21 * b21
    be = b02 * b02 + b12 * b12 + b22 * b22
    ga = b01 * b02 + b11 * b12 + b21 * b22
    t, c, s = _jacobi_angle(al, be, ga)
    b01, b11, b21, b02, b12, b22 = _rotate(c, s, b01, b11, b21, b02, b12, b22)
    v01, v11, v21, v02, v12, v22 = _rotate(c, s, v01, v11, v21, v02, v12, v22)
    if al - t * ga < be + t * ga:
        # keep the larger of the two as sigma_2 (swap with a sign to keep det V = +1)
        b01, b11, b21 = b02, b12, b22
        v01, v11, v21, v02, v12, v22 = v02, v12, v22, -v01, -v11, -v21
    n0 = b00 * b00 + b10 * b10 + b20 * b20
    n = 1.0 / math.sqrt(n0)
    u00, u10, u20 = b00 * n, b10 * n, b20 * n
    # S v_2 is small here, so project twice ("twice is enough") to keep u_2 orthogonal
    p = u00 * b01 + u10 * b11 + u20 * b21
    w0, w1, w2 = b01 - p * u00, b11 - p * u10, b21 - p * u20
    p = u00 * w0 + u10 * w1 + u20 * w2
    w0, w1, w2 = w0 - p * u00, w1 - p * u10, w2 - p * u20
    nw = w0 * w0 + w1 * w1 + w2 * w2
    if nw <= (_RANK_ONE * _RANK_ONE) * n0:
        return _smallest_rotation(u00, u10, u20, v00, v10, v20)
    n = 1.0 / math.sqrt(nw)
    return _compose(
        v00, v10, v20, v01, v11, v21, v02, v12, v22, u00, u10, u20, w0 * n, w1 * n, w2 * n
    )


@_inline
def _rotation9(
    s00: float,
    s01: float,
    s02: float,
    s10: float,
    s11: float,
    s12: float,
    s20: float,
    s21: float,
    s22: float,
) -> tuple[float, ...]:
    # The scalar algorithm on the nine entries of S (row major); returns R row major.
    m = _max_abs9(s00, s01, s02, s10, s11, s12, s20, s21, s22)
    if m == 0.0:
        return 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
    if not (m < math.inf):
        nan = math.nan
        return nan, nan, nan, nan, nan, nan, nan, nan, nan
    # Scale to max |S_ij| = 1 so that S^T S stays in range; R is scale invariant.
    k = 1.0 / m
    s00, s01, s02, s10, s11, s12 = s00 * k, s01 * k, s02 * k, s10 * k, s11 * k, s12 * k
    s20, s21, s22 = s20 * k, s21 * k, s22 * k
    a00, a11, a22, a01, a02, a12 = _gram(s00, s01, s02, s10, s11, s12, s20, s21, s22)
    thr = (_JACOBI_TOL * (a00 + a11 + a22)) ** 2
    v00, v10, v20, v01, v11, v21, v02, v12, v22 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
    for _ in range(_MAX_SWEEPS):
        if a01 * a01 + a02 * a02 + a12 * a12 <= thr:
            break
        a00, a11, a22, a01, a02, a12, v00, v10, v20, v01, v11, v21, v02, v12, v22 = _sweep(
            a00, a11, a22, a01, a02, a12, v00, v10, v20, v01, v11, v21, v02, v12, v22
        )
    a00, a11, a22, v00, v10, v20, v01, v11, v21, v02, v12, v22 = _sort_desc(
        a00, a11, a22, v00, v10, v20, v01, v11, v21, v02, v12, v22
    )
    if a11 >= _DEGENERATE * a00:
        return _finish_regular(
            s00, s01, s02, s10, s11, s12, s20, s21, s22,
            v00, v10, v20, v01, v11, v21, v02, v12, v22,
        )
    return _finish_degenerate(
        s00, s01, s02, s10, s11, s12, s20, s21, s22,
        v00, v10, v20, v01, v11, v21, v02, v12, v22,
    )


@nb.njit(cache=True, error_model="numpy", nogil=True)
def rotation_from_covariance(S: np.ndarray, R: np.ndarray) -> None:
    """Write into ``R`` the rotation maximising ``tr(R @ S)``.

    A scalar kernel for use inside other compiled (including ``prange``) loops: it
    allocates nothing and branches only on convergence and degenerate input.  ``R``
    may be ``S`` itself.

    Parameters
    ----------
    S : (3, 3) float64
        Covariance matrix.
    R : (3, 3) float64
        Output, overwritten with ``R`` in SO(3) (orthonormal to ~1e-15, ``det R = +1``).
        For ``S = 0`` this is the identity; when the optimum is not unique (repeated
        singular values, rank below two) it is one of the optimal rotations.  Non-finite
        ``S`` gives NaN.

    Examples
    --------
    >>> import numpy as np
    >>> S = np.diag([2.0, -1.0, 0.5])  # det S < 0: no rotation maps it to |S|
    >>> R = np.empty((3, 3))
    >>> rotation_from_covariance(S, R)
    >>> R  # the smallest singular value takes the sign: tr(R S) = 2 + 1 - 0.5
    array([[ 1.,  0.,  0.],
           [ 0., -1.,  0.],
           [ 0.,  0., -1.]])
    """
    r = _rotation9(S[0, 0], S[0, 1], S[0, 2], S[1, 0], S[1, 1], S[1, 2], S[2, 0], S[2, 1], S[2, 2])
    R[0, 0], R[0, 1], R[0, 2] = r[0], r[1], r[2]
    R[1, 0], R[1, 1], R[1, 2] = r[3], r[4], r[5]
    R[2, 0], R[2, 1], R[2, 2] = r[6], r[7], r[8]


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _fit_lanes(src: np.ndarray, dst: np.ndarray, redo: np.ndarray) -> None:
    # Branch-free kernel over _LANES matrices stored structure-of-arrays:
    # src[(3 i + j) * _LANES + q] = S_q[i, j], and likewise dst for R.  The compile-time
    # constant strides let LLVM prove the accesses independent and vectorise the loop
    # across matrices.  redo[q] is set where the scalar kernel must take over (zero or
    # non-finite S, sweeps not converged, sigma_2 << sigma_1).
    for q in range(_LANES):
        s00, s01, s02 = src[q], src[_LANES + q], src[2 * _LANES + q]
        s10, s11, s12 = src[3 * _LANES + q], src[4 * _LANES + q], src[5 * _LANES + q]
        s20, s21, s22 = src[6 * _LANES + q], src[7 * _LANES + q], src[8 * _LANES + q]
        m = _max_abs9(s00, s01, s02, s10, s11, s12, s20, s21, s22)
        k = 1.0 / m
        s00, s01, s02, s10, s11, s12 = s00 * k, s01 * k, s02 * k, s10 * k, s11 * k, s12 * k
        s20, s21, s22 = s20 * k, s21 * k, s22 * k
        a00, a11, a22, a01, a02, a12 = _gram(s00, s01, s02, s10, s11, s12, s20, s21, s22)
        thr = (_JACOBI_TOL * (a00 + a11 + a22)) ** 2
        v00, v10, v20, v01, v11, v21, v02, v12, v22 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
        # four sweeps, unconditionally and unrolled by hand: LLVM vectorises innermost
        # loops only, and without branches; the few matrices that need more are redone
        a00, a11, a22, a01, a02, a12, v00, v10, v20, v01, v11, v21, v02, v12, v22 = _sweep(
            a00, a11, a22, a01, a02, a12, v00, v10, v20, v01, v11, v21, v02, v12, v22
        )
        a00, a11, a22, a01, a02, a12, v00, v10, v20, v01, v11, v21, v02, v12, v22 = _sweep(
            a00, a11, a22, a01, a02, a12, v00, v10, v20, v01, v11, v21, v02, v12, v22
        )
        a00, a11, a22, a01, a02, a12, v00, v10, v20, v01, v11, v21, v02, v12, v22 = _sweep(
            a00, a11, a22, a01, a02, a12, v00, v10, v20, v01, v11, v21, v02, v12, v22
        )
        a00, a11, a22, a01, a02, a12, v00, v10, v20, v01, v11, v21, v02, v12, v22 = _sweep(
            a00, a11, a22, a01, a02, a12, v00, v10, v20, v01, v11, v21, v02, v12, v22
        )
        off = a01 * a01 + a02 * a02 + a12 * a12
        a00, a11, a22, v00, v10, v20, v01, v11, v21, v02, v12, v22 = _sort_desc(
            a00, a11, a22, v00, v10, v20, v01, v11, v21, v02, v12, v22
        )
        r = _finish_regular(
            s00, s01, s02, s10, s11, s12, s20, s21, s22,
            v00, v10, v20, v01, v11, v21, v02, v12, v22,
        )
        dst[q], dst[_LANES + q], dst[2 * _LANES + q] = r[0], r[1], r[2]
        dst[3 * _LANES + q], dst[4 * _LANES + q], dst[5 * _LANES + q] = r[3], r[4], r[5]
        dst[6 * _LANES + q], dst[7 * _LANES + q], dst[8 * _LANES + q] = r[6], r[7], r[8]
        redo[q] = not (m > 0.0 and m < math.inf and off <= thr and a11 >= _DEGENERATE * a00)


@nb.njit(cache=True, error_model="numpy", nogil=True)
def fit_rotation_range(S: np.ndarray, R: np.ndarray, lo: int, hi: int) -> None:
    """Write ``R[lo:hi]`` from ``S[lo:hi]``, vectorised across blocks of matrices.

    The serial building block of :func:`fit_rotations`, for compiled callers that run
    their own parallel loop (the solver's fused local step). Degenerate matrices go to
    :func:`rotation_from_covariance`. ``R`` may be ``S``.
    """
    # Kept out of the prange body (and the scalar fallback out of line) to keep
    # compilation of _fit_all quick.
    src = np.empty(9 * _LANES)
    dst = np.empty(9 * _LANES)
    redo = np.empty(_LANES, dtype=np.bool_)
    tmp = np.empty((3, 3))
    for k0 in range(lo, hi, _LANES):
        cnt = min(_LANES, hi - k0)
        # matrix-major loops: contiguous reads of S (and writes of R below) are ~15%
        # faster overall than entry-major ones
        for q in range(cnt):
            for ij in range(9):
                src[ij * _LANES + q] = S[k0 + q, ij // 3, ij % 3]
        # pad a short last block with identities (never written back)
        for q in range(cnt, _LANES):
            for ij in range(9):
                src[ij * _LANES + q] = 1.0 if ij % 4 == 0 else 0.0
        _fit_lanes(src, dst, redo)
        for q in range(cnt):
            for ij in range(9):
                R[k0 + q, ij // 3, ij % 3] = dst[ij * _LANES + q]
        for q in range(cnt):
            if redo[q]:
                # from the scratch copy, so that R may alias S
                for ij in range(9):
                    tmp[ij // 3, ij % 3] = src[ij * _LANES + q]
                rotation_from_covariance(tmp, R[k0 + q])


@nb.njit(parallel=True, cache=True, nogil=True)
def _fit_all(S: np.ndarray, R: np.ndarray) -> None:
    n = S.shape[0]
    for c in nb.prange((n + _CHUNK - 1) // _CHUNK):
        fit_rotation_range(S, R, c * _CHUNK, min(n, (c + 1) * _CHUNK))


def fit_rotations(S: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Best-fit rotation for each covariance matrix.

    Parameters
    ----------
    S : (n, 3, 3) float64
        Covariance matrices ``S_k = sum w e e'^T``.
    out : (n, 3, 3) float64, optional
        Where to write the result (C-contiguous float64); may be ``S`` itself.

    Returns
    -------
    (n, 3, 3) float64
        ``R_k`` in SO(3) maximising ``tr(R_k S_k)`` (see
        :func:`rotation_from_covariance` for the degenerate cases).

    Examples
    --------
    >>> import numpy as np
    >>> R = fit_rotations(np.eye(3)[None] * 2.0)
    >>> np.allclose(R[0], np.eye(3))
    True
    """
    try:
        S = np.ascontiguousarray(S, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"fit_rotations: S must be numbers ({e})") from None
    if S.ndim != 3 or S.shape[1:] != (3, 3):
        raise InputError(f"fit_rotations: S must have shape (n, 3, 3), got {S.shape}")
    if out is None:
        out = np.empty_like(S)
    elif out.shape != S.shape or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise InputError(
            f"fit_rotations: out must be a C-contiguous float64 array of shape {S.shape}"
        )
    _fit_all(S, out)
    return out
