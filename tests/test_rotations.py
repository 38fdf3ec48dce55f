"""Tests for the rotation-fitting kernel against numpy's SVD.

Every family is checked on the properties that matter to ARAP: ``R`` orthonormal within
1e-12, ``det R = +1`` within 1e-12, and ``tr(R S)`` equal to the optimum
``sigma_1 + sigma_2 + sign(det S) sigma_3`` within a relative 1e-10.  Where the optimum
is unique and well conditioned, ``R`` itself must also match the SVD reference.
"""

from __future__ import annotations

import itertools

import numba as nb
import numpy as np
import pytest

from arapkit.arap.rotations import fit_rotations, rotation_from_covariance

ORTH_TOL = 1e-12
TRACE_TOL = 1e-10


def reference(S: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """SVD reference: optimal rotations, optimal traces, and the conditioning of ``R``.

    The conditioning is ``kappa = (sigma_2 + sign(det S) sigma_3) / sigma_1``: the best
    rotation is unique iff ``kappa > 0`` and a perturbation of ``S`` moves it by about
    ``|dS| / (kappa sigma_1)``.
    """
    U, sig, Vt = np.linalg.svd(S)
    d = np.sign(np.linalg.det(U) * np.linalg.det(Vt))
    D = np.ones_like(sig)
    D[:, 2] = d
    R = np.einsum("nji,nj,nkj->nik", Vt, D, U)  # V diag(1, 1, d) U^T
    opt = sig[:, 0] + sig[:, 1] + d * sig[:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        kappa = np.where(sig[:, 0] > 0, (sig[:, 1] + d * sig[:, 2]) / sig[:, 0], 0.0)
    return R, opt, kappa


def random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniformly distributed rotations (QR of Gaussian matrices, signs fixed)."""
    Q, Rq = np.linalg.qr(rng.standard_normal((n, 3, 3)))
    Q = Q * np.sign(np.diagonal(Rq, axis1=1, axis2=2))[:, None, :]
    Q[np.linalg.det(Q) < 0, :, 0] *= -1.0
    return Q


def with_singular_values(rng: np.random.Generator, sig: np.ndarray) -> np.ndarray:
    """``U diag(sig) V^T`` for random rotations ``U``, ``V`` (sig may carry a sign)."""
    sig = np.broadcast_to(np.asarray(sig, dtype=np.float64), (len(sig), 3))
    U = random_rotations(rng, len(sig))
    V = random_rotations(rng, len(sig))
    return np.einsum("nij,nj,nkj->nik", U, sig, V)


def assert_optimal_rotations(S: np.ndarray, R: np.ndarray, match_kappa: float = 1e-3) -> None:
    """Check orthonormality, det, optimal trace, and agreement where well conditioned."""
    assert R.shape == S.shape
    assert np.all(np.isfinite(R))
    eye_err = np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max()
    assert eye_err <= ORTH_TOL, f"R^T R - I = {eye_err:.2e}"
    det_err = np.abs(np.linalg.det(R) - 1.0).max()
    assert det_err <= ORTH_TOL, f"det R - 1 = {det_err:.2e}"
    Rref, opt, kappa = reference(S)
    tr = np.einsum("nij,nji->n", R, S)
    scale = np.maximum(np.abs(opt), np.abs(S).max(axis=(1, 2)))
    gap = np.abs(opt - tr) / np.where(scale > 0, scale, 1.0)
    assert gap.max() <= TRACE_TOL, f"tr(RS) off the optimum by {gap.max():.2e} (relative)"
    well = kappa > match_kappa
    if well.any():
        # the SVD reference is itself only accurate to ~eps / kappa
        err = np.abs(R - Rref).max(axis=(1, 2))[well] * kappa[well]
        assert err.max() <= 1e-10, f"R differs from the SVD reference: {err.max():.2e}"


# Not cache=True on purpose: numba's cache of a caller is keyed on the caller's file
# only, so a cached wrapper would keep testing a stale copy of the kernel after edits.
@nb.njit(parallel=True)
def _scalar_kernel_in_prange(S: np.ndarray) -> np.ndarray:
    R = np.empty_like(S)
    for k in nb.prange(S.shape[0]):
        rotation_from_covariance(S[k], R[k])
    return R


def both_kernels(S: np.ndarray) -> list[np.ndarray]:
    """Results of the vectorised batch path and of the scalar kernel (from prange)."""
    return [fit_rotations(S), _scalar_kernel_in_prange(np.ascontiguousarray(S))]


def test_random_gaussian_matrices_match_svd() -> None:
    rng = np.random.default_rng(20240611)
    S = rng.standard_normal((20_000, 3, 3))
    assert (np.linalg.det(S) < 0).sum() > 5_000  # half of them are reflections
    for R in both_kernels(S):
        assert_optimal_rotations(S, R)


def test_near_rotations_as_in_arap() -> None:
    # ARAP covariances late in a solve: S = P Q^T with P symmetric positive definite
    # (the rest-pose scatter) and Q the rotation of the neighbourhood; the fit is Q.
    rng = np.random.default_rng(1)
    n = 5_000
    Q = random_rotations(rng, n)
    X = rng.standard_normal((n, 3, 6))
    P = np.einsum("nik,njk->nij", X, X)
    S = P @ np.transpose(Q, (0, 2, 1))
    for R in both_kernels(S):
        assert_optimal_rotations(S, R)
        np.testing.assert_allclose(R, Q, atol=1e-10)


def test_planar_neighbourhoods_recover_rotation() -> None:
    # Flat one-rings: rest edges in a plane, so S has rank two; the rotation of a
    # rigidly moved planar fan is still unique and must be recovered exactly.
    rng = np.random.default_rng(2)
    n = 5_000
    Q = random_rotations(rng, n)
    E = rng.standard_normal((n, 6, 3))
    E[:, :, 2] = 0.0  # rest edges in the z = 0 plane
    E = np.einsum("nij,nkj->nki", random_rotations(rng, n), E)  # arbitrary plane
    w = rng.uniform(0.1, 2.0, (n, 6))
    S = np.einsum("nk,nki,nkj->nij", w, E, E @ np.transpose(Q, (0, 2, 1)))
    assert np.all(np.linalg.matrix_rank(S[:100]) == 2)
    for R in both_kernels(S):
        assert_optimal_rotations(S, R)
        np.testing.assert_allclose(R, Q, atol=1e-9)


def test_rank_one_collinear() -> None:
    rng = np.random.default_rng(3)
    a = rng.standard_normal((4_000, 3, 1))
    b = rng.standard_normal((4_000, 1, 3))
    S = a @ b
    S[:1000] = S[:1000] * 1e-30  # also far from unit scale
    for R in both_kernels(S):
        assert_optimal_rotations(S, R)


def test_exactly_rank_deficient_integer_matrices() -> None:
    # S v_2 comes out exactly zero here (no rounding noise to normalise), so the
    # rank-one branch has to supply u_2; e_i e_j^T also covers axis-aligned flat cases
    eye = np.eye(3)
    S = [np.outer(eye[i], eye[j]) * c for i in range(3) for j in range(3) for c in (2.0, -3.0)]
    S += [np.diag(d) for d in ([1.0, 1.0, 0.0], [0.0, -2.0, 5.0], [4.0, 0.0, 0.0])]
    S += [np.outer([1.0, 2.0, 0.0], [0.0, 3.0, 1.0]), np.outer([1.0, 1.0, 1.0], [1.0, 1.0, 1.0])]
    S = np.array(S)
    for R in both_kernels(S):
        assert_optimal_rotations(S, R)


def test_every_matrix_with_entries_minus_one_zero_one() -> None:
    # all 3^9 matrices: exact zeros, permutations, reflections, every rank, many ties
    S = np.array(list(itertools.product([-1.0, 0.0, 1.0], repeat=9))).reshape(-1, 3, 3)
    nz = np.abs(S).max(axis=(1, 2)) > 0
    for R in both_kernels(S):
        assert_optimal_rotations(S[nz], R[nz])
        np.testing.assert_array_equal(R[~nz][0], np.eye(3))


def test_log_uniform_singular_values() -> None:
    # singular values spread over 20 decades, either sign of det: every conditioning
    rng = np.random.default_rng(11)
    n = 20_000
    sig = -np.sort(-(10.0 ** rng.uniform(-20.0, 0.0, (n, 3))), axis=1)
    sig[:, 2] *= rng.choice([-1.0, 1.0], n)
    S = with_singular_values(rng, sig)
    for R in both_kernels(S):
        assert_optimal_rotations(S, R)


def test_rank_two_random() -> None:
    rng = np.random.default_rng(4)
    S = rng.standard_normal((4_000, 3, 2)) @ rng.standard_normal((4_000, 2, 3))
    for R in both_kernels(S):
        assert_optimal_rotations(S, R)


@pytest.mark.parametrize(
    "sig",
    [
        (1.0, 1.0, 1.0),
        (1.0, 1.0, -1.0),
        (1.0, 1.0, 0.0),
        (1.0, 0.0, 0.0),
        (2.0, 0.5, 0.5),
        (2.0, 0.5, -0.5),
        (1.0, 1.0, 0.3),
        (1.0, 1.0 - 1e-9, 0.3),
        (1.0, 0.3, -(0.3 - 1e-9)),
        (1.0, 1e-3, -(1e-3 - 1e-12)),
    ],
)
def test_repeated_and_nearly_repeated_singular_values(sig: tuple[float, float, float]) -> None:
    rng = np.random.default_rng(5)
    S = with_singular_values(rng, np.tile(sig, (2_000, 1)))
    for R in both_kernels(S):
        assert_optimal_rotations(S, R)


@pytest.mark.parametrize("sigma2", [1e-2, 1e-3, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-14, 1e-17])
@pytest.mark.parametrize("ratio3", [0.0, 0.5, -0.5, 1.0, -1.0])
def test_nearly_collinear(sigma2: float, ratio3: float) -> None:
    # sigma_2 << sigma_1: where forming S^T S loses the (u_2, u_3) plane
    rng = np.random.default_rng(6)
    S = with_singular_values(rng, np.tile([1.0, sigma2, ratio3 * sigma2], (1_000, 1)))
    for R in both_kernels(S):
        assert_optimal_rotations(S, R)


@pytest.mark.parametrize("scale", [1e-300, 1e-200, 1e-160, 1e160, 1e200, 1e300])
def test_extreme_scales(scale: float) -> None:
    rng = np.random.default_rng(7)
    S0 = rng.standard_normal((2_000, 3, 3))
    S = S0 * scale
    assert np.all(np.isfinite(S)) and np.all(np.abs(S).max(axis=(1, 2)) > 0)
    for R in both_kernels(S):
        # scale invariance: compare the traces on the unscaled matrices
        assert_optimal_rotations(S0, R)


def test_entries_on_wildly_different_scales() -> None:
    # rows and columns scaled over 300 decades: Gram entries that underflow when
    # squared next to ones of order one, and exact ties at identity-like matrices
    rng = np.random.default_rng(12)
    n = 5_000
    S = rng.standard_normal((n, 3, 3)) * 10.0 ** rng.uniform(-150, 150, (n, 3, 1))
    S[: n // 2] *= 10.0 ** rng.uniform(-150, 150, (n // 2, 1, 3))
    S[:500] = np.eye(3) + np.diag(rng.uniform(-1, 1, 2), 1) * 1e-160  # tiny off-diagonals
    S = S / np.abs(S).max(axis=(1, 2), keepdims=True)  # keep numpy's reference in range
    for R in both_kernels(S):
        assert_optimal_rotations(S, R)


def test_reflections_take_the_smallest_singular_value() -> None:
    S = np.diag([2.0, -1.0, 0.5])[None]
    for R in both_kernels(S):
        np.testing.assert_allclose(R[0], np.diag([1.0, -1.0, -1.0]), atol=1e-15)
    S = -np.eye(3)[None] * 3.0  # det < 0, equal singular values: optimum 3 + 3 - 3
    for R in both_kernels(S):
        assert_optimal_rotations(S, R)
        assert np.trace(R[0] @ S[0]) == pytest.approx(3.0, rel=1e-12)


def test_zero_gives_identity_and_nonfinite_gives_nan() -> None:
    S = np.zeros((70, 3, 3))  # more than one vectorised block
    S[5] = np.nan
    S[6, 1, 2] = np.inf
    S[7] = np.eye(3)
    for R in both_kernels(S):
        ok = np.ones(70, dtype=bool)
        ok[[5, 6]] = False
        np.testing.assert_array_equal(R[ok], np.broadcast_to(np.eye(3), (68, 3, 3)))
        assert np.all(np.isnan(R[5])) and np.all(np.isnan(R[6]))


def test_mixed_batch_with_odd_length_and_in_place() -> None:
    # regular, degenerate, zero and rank-deficient matrices interleaved, with a length
    # that leaves a partial block; also the in-place form fit_rotations(S, out=S)
    rng = np.random.default_rng(8)
    S = rng.standard_normal((3_001, 3, 3))
    S[::7] = rng.standard_normal((429, 3, 1)) @ rng.standard_normal((429, 1, 3))
    S[::11] = with_singular_values(rng, np.tile([1.0, 1e-9, 0.0], (273, 1)))
    S[::13] = 0.0
    R = fit_rotations(S)
    nz = np.abs(S).max(axis=(1, 2)) > 0
    assert_optimal_rotations(S[nz], R[nz])
    np.testing.assert_array_equal(R[~nz], np.broadcast_to(np.eye(3), (int((~nz).sum()), 3, 3)))
    S_in = S.copy()
    out = fit_rotations(S_in, out=S_in)
    assert out is S_in
    np.testing.assert_array_equal(S_in, R)


def test_scalar_kernel_from_python_and_aliasing() -> None:
    rng = np.random.default_rng(9)
    S = rng.standard_normal((3, 3))
    R = np.empty((3, 3))
    rotation_from_covariance(S, R)
    assert_optimal_rotations(S[None], R[None])
    S2 = S.copy()
    rotation_from_covariance(S2, S2)  # R may be S
    np.testing.assert_array_equal(S2, R)


def test_fit_rotations_input_handling() -> None:
    S = np.random.default_rng(10).standard_normal((10, 3, 3))
    R_f = fit_rotations(np.asfortranarray(S).astype(np.float32))  # converted
    np.testing.assert_allclose(R_f, fit_rotations(S.astype(np.float32).astype(np.float64)))
    assert fit_rotations(np.empty((0, 3, 3))).shape == (0, 3, 3)
    with pytest.raises(ValueError, match="shape"):
        fit_rotations(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="out"):
        fit_rotations(S, out=np.empty((10, 3, 3), dtype=np.float32))
    with pytest.raises(ValueError, match="out"):
        fit_rotations(S, out=np.empty((9, 3, 3)))


def test_rank_one_picks_the_smallest_turn():
    """Rank-one S = u v^T: of all optimal rotations (R u = v) the one nearest the identity.

    Independent reference: scipy's rotation about u x v by the angle between u and v.
    """
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(7)
    u = rng.normal(size=(500, 3))
    v = rng.normal(size=(500, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    S = 2.5 * u[:, :, None] * v[:, None, :]
    axis = np.cross(u, v)
    ang = np.arctan2(np.linalg.norm(axis, axis=1), np.einsum("ij,ij->i", u, v))
    ref = Rotation.from_rotvec(axis / np.linalg.norm(axis, axis=1, keepdims=True)
                               * ang[:, None]).as_matrix()
    for R in both_kernels(S):
        assert np.allclose(R, ref, atol=1e-10)
    # u = v: the identity, not a spin about u
    same = 3.0 * u[:, :, None] * u[:, None, :]
    assert np.allclose(fit_rotations(same), np.eye(3), atol=1e-12)
