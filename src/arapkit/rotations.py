"""Best-fit rotations for covariance matrices (the ARAP local step).

For a covariance ``S = sum_e w_e e_e e'_e^T`` (rest edge times deformed edge), the
rotation that minimises ``sum_e w_e |e'_e - R e_e|^2`` maximises ``tr(R S)``; with
``S = U Sigma V^T`` it is ``R = V U^T``, with the column of ``U`` that belongs to the
smallest singular value negated when ``det(V U^T) < 0`` (Sorkine & Alexa 2007).
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, fastmath=False)
def rotation_from_covariance(S: np.ndarray, R: np.ndarray) -> None:
    """Write into ``R`` (3x3) the rotation maximising ``tr(R @ S)``.

    A scalar kernel usable from other compiled loops.
    """
    U, sig, Vt = np.linalg.svd(S)
    V = Vt.T
    Rm = V @ U.T
    if np.linalg.det(Rm) < 0.0:
        U2 = U.copy()
        U2[:, 2] = -U2[:, 2]
        Rm = V @ U2.T
    R[:, :] = Rm


@nb.njit(parallel=True, cache=True)
def _fit_all(S: np.ndarray, R: np.ndarray) -> None:
    for k in nb.prange(S.shape[0]):
        rotation_from_covariance(S[k], R[k])


def fit_rotations(S: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Best-fit rotation for each covariance matrix.

    Parameters
    ----------
    S : (n, 3, 3) float64
        Covariance matrices ``S_k = sum w e e'^T``.
    out : (n, 3, 3) float64, optional
        Where to write the result.

    Returns
    -------
    (n, 3, 3) float64
        ``R_k`` in SO(3) maximising ``tr(R_k S_k)``.

    Examples
    --------
    >>> import numpy as np
    >>> R = fit_rotations(np.eye(3)[None] * 2.0)
    >>> np.allclose(R[0], np.eye(3))
    True
    """
    S = np.ascontiguousarray(S, dtype=np.float64)
    if out is None:
        out = np.empty_like(S)
    _fit_all(S, out)
    return out
