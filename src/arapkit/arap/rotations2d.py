"""Best-fit rotations in the plane: the 2D local step, in closed form.

For a 2 x 2 covariance ``S = sum_e w_e e_e e'_e^T`` (rest edge times deformed edge) the
rotation ``R = [[c, -s], [s, c]]`` that minimises ``sum_e w_e |e'_e - R e_e|^2`` maximises

    tr(R S) = c (S_00 + S_11) + s (S_01 - S_10),

a linear function of the unit vector ``(c, s)``: its maximum is at
``(c, s) = (a, b) / |(a, b)|`` with ``a = S_00 + S_11``, ``b = S_01 - S_10``, and the
maximum is ``|(a, b)|``. No SVD, no branch but the degenerate ``a = b = 0`` (every rotation
is then optimal: the identity is taken, as the 3D kernel does for ``S = 0``). Unlike the 3D
fit restricted to the plane, a reflection is never chosen: in 3D a planar neighbourhood may
be turned over (a half turn about an in-plane axis), which in the plane is a fold.

Examples
--------
>>> import numpy as np
>>> t = 0.3
>>> Q = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
>>> S = np.diag([2.0, 1.0]) @ Q.T          # rest edges e, deformed edges Q e
>>> bool(np.allclose(fit_rotations_2d(S[None])[0], Q))
True
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..errors import InputError

__all__ = ["fit_rotations_2d", "follow_in_plane", "rigid_motion_2d", "rotation_2d"]


@nb.njit(inline="always", cache=True, error_model="numpy")
def rotation_2d(s00: float, s01: float, s10: float, s11: float) -> tuple[float, float]:
    """``(cos, sin)`` of the rotation maximising ``tr(R S)`` for ``S = [[s00, s01], [s10, s11]]``.

    ``math.hypot`` neither overflows nor underflows, so any finite scale of S gives a unit
    vector; a non-finite S gives NaN (the loop's finiteness test then names the cause).
    """
    a = s00 + s11
    b = s01 - s10
    h = math.hypot(a, b)
    if h == 0.0:
        return 1.0, 0.0
    return a / h, b / h


@nb.njit(cache=True, nogil=True)
def _fit_all_2d(S: np.ndarray, R: np.ndarray) -> None:
    for k in range(S.shape[0]):
        c, s = rotation_2d(S[k, 0, 0], S[k, 0, 1], S[k, 1, 0], S[k, 1, 1])
        R[k, 0, 0], R[k, 0, 1] = c, -s
        R[k, 1, 0], R[k, 1, 1] = s, c


def fit_rotations_2d(S: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Best-fit rotation for each 2 x 2 covariance matrix.

    Parameters
    ----------
    S : (n, 2, 2) float64
        Covariances ``S_k = sum w e e'^T``.
    out : (n, 2, 2) float64, optional
        Where to write the result; may be ``S`` itself.

    Returns
    -------
    (n, 2, 2) float64
        ``R_k`` in SO(2) maximising ``tr(R_k S_k)`` (the identity where ``S_k`` has no
        preferred turn, e.g. ``S_k = 0``).

    Examples
    --------
    >>> import numpy as np
    >>> fit_rotations_2d(np.array([[[0.0, 1.0], [-1.0, 0.0]]]))[0]  # a quarter turn
    array([[ 0., -1.],
           [ 1.,  0.]])
    """
    try:
        S = np.ascontiguousarray(S, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"fit_rotations_2d: S must be numbers ({e})") from None
    if S.ndim != 3 or S.shape[1:] != (2, 2):
        raise InputError(f"fit_rotations_2d: S must have shape (n, 2, 2), got {S.shape}")
    if out is None:
        out = np.empty_like(S)
    _fit_all_2d(S, out)
    return out


def rigid_motion_2d(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation and translation that best map points ``src`` onto ``dst`` in the
    plane (Kabsch with the closed-form fit): ``(R, t)`` minimising
    ``sum |src @ R.T + t - dst|^2`` over proper rotations.

    Examples
    --------
    >>> import numpy as np
    >>> src = np.array([[0, 0], [1, 0], [0, 1]], float)
    >>> R, t = rigid_motion_2d(src, src @ np.array([[0, 1], [-1, 0]]) + 2.0)  # a quarter turn
    >>> (np.round(R, 12) + 0.0).tolist(), np.round(t, 12).tolist()
    ([[0.0, -1.0], [1.0, 0.0]], [2.0, 2.0])
    """
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    H = (src - ms).T @ (dst - md)  # sum (s - ms)(d - md)^T: tr(R H) is maximised
    R = fit_rotations_2d(H[None])[0]
    return R, md - R @ ms


def follow_in_plane(followers, V: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Place a planar solve's handle-free components with their neighbours: the 3D
    :class:`~arapkit.arap.constraints.Followers` on ``(n, 2)`` positions and ``(n, 2, 2)``
    rotations (lifted onto the rest plane and back; planar motions stay in the plane)."""
    z = followers.rest[:, 2:3]
    V3 = np.concatenate([V, z], axis=1)
    R3 = np.zeros((len(R), 3, 3))
    R3[:, :2, :2] = R
    R3[:, 2, 2] = 1.0
    followers.apply(V3, R3)
    return np.ascontiguousarray(V3[:, :2]), np.ascontiguousarray(R3[:, :2, :2])
