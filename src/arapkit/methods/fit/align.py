"""The fit's first move: a similarity (scale, rotation, translation) of the whole template.

From landmarks it is the least-squares similarity of the landmark vertices onto their
targets (Umeyama 1991); without landmarks it is refined from the template's placement by
rigid ICP (closest points, rejection, the same fit of a similarity each round).

Examples
--------
>>> import numpy as np
>>> src = np.random.default_rng(1).random((6, 3))
>>> s, R, t = similarity(src, 2.0 * src + [1.0, 0.0, 0.0])
>>> round(s, 9), (np.round(t, 9) + 0.0).tolist()
(2.0, [1.0, 0.0, 0.0])
"""

from __future__ import annotations

import numpy as np

from ...arap.rotations import fit_rotations

__all__ = ["Similarity", "similarity"]

#: a similarity ``x -> scale R x + t``
Similarity = tuple[float, np.ndarray, np.ndarray]


def similarity(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None,
               scale: bool = True) -> Similarity:
    """The similarity (or, with ``scale=False``, the rigid motion) that best maps ``src``
    onto ``dst`` in the weighted least-squares sense.

    Fewer than three points, or collinear ones, leave a rotation undetermined: those get
    the translation of their centroids only (scale 1, no rotation).

    Returns
    -------
    (scale, R, t) with ``dst ~ scale * src @ R.T + t``.
    """
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    w = np.ones(len(src)) if weights is None else np.asarray(weights, dtype=np.float64)
    w = w / w.sum()
    ms, md = w @ src, w @ dst
    A, B = src - ms, dst - md
    if len(src) < 3 or np.linalg.svd(A, compute_uv=False)[1] <= 1e-9 * max(
            np.abs(A).max(), 1e-300):
        return 1.0, np.eye(3), md - ms
    # Kabsch: R maximises tr(R H), H = sum_i w_i a_i b_i^T
    R = fit_rotations(np.einsum("n,ni,nj->ij", w, A, B)[None])[0]
    s = 1.0
    if scale:
        var = float((w * (A * A).sum(axis=1)).sum())
        s = float((w * ((A @ R.T) * B).sum(axis=1)).sum()) / var if var > 0 else 1.0
        if not s > 0:
            s = 1.0
    return s, R, md - s * ms @ R.T
