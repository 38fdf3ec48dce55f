"""Handle positions over time, for a simulation's moving handles.

:class:`Keyframes` holds the handles' positions at a few times and interpolates linearly
between them (a keyframed animation's linear interpolation); :func:`ramp` moves them from
rest to a pose over a time, each group of handles by one rigid motion when its pose is one
(an end turned by 90 degrees stays its shape on the way, where straight lines would shrink
it by a third half-way). Both are callables ``t -> (h, 3)`` that
:meth:`arapkit.methods.dynamics.Simulator.run` takes as ``targets``.

Examples
--------
>>> import numpy as np
>>> k = Keyframes([0.0, 1.0], [np.zeros((1, 3)), np.ones((1, 3))])
>>> k(0.25).tolist(), k(5.0).tolist()
([[0.25, 0.25, 0.25]], [[1.0, 1.0, 1.0]])
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..arap.constraints import rigid_motion
from ..errors import InputError
from ..validate import number, real_array

__all__ = ["Keyframes", "ramp"]


class Keyframes:
    """Handle positions at key times, linear in between, held before the first and after
    the last key.

    Parameters
    ----------
    times : (k,) float
        Strictly increasing key times (s).
    targets : (k, h, 3) float
        The handles' positions at each key.

    Examples
    --------
    >>> import numpy as np
    >>> k = Keyframes([1.0, 2.0], np.array([[[0.0, 0, 0]], [[2.0, 0, 0]]]))
    >>> [float(k(t)[0, 0]) for t in (0.0, 1.5, 3.0)]
    [0.0, 1.0, 2.0]
    """

    def __init__(self, times: Sequence[float], targets) -> None:
        t = real_array(times, "keyframe times")
        T = real_array(targets, "keyframe targets")
        if t.ndim != 1 or len(t) == 0:
            raise InputError("keyframe times: expected a 1-D list of at least one time")
        if not np.isfinite(t).all() or (np.diff(t) <= 0).any():
            raise InputError("keyframe times: must be finite and strictly increasing")
        if T.ndim != 3 or T.shape[0] != len(t) or T.shape[2] != 3:
            raise InputError(f"keyframe targets: expected shape ({len(t)}, h, 3), got "
                             f"{T.shape}")
        if not np.isfinite(T).all():
            raise InputError("keyframe targets: must be finite")
        self.times, self.targets = t, T

    def __call__(self, t: float) -> np.ndarray:
        """The handles' positions at time ``t``."""
        k = int(np.searchsorted(self.times, t, side="right"))
        if k == 0:
            return self.targets[0].copy()
        if k == len(self.times):
            return self.targets[-1].copy()
        t0, t1 = self.times[k - 1], self.times[k]
        s = (t - t0) / (t1 - t0)
        return (1.0 - s) * self.targets[k - 1] + s * self.targets[k]


class _Ramp:
    """Rest to pose between ``start`` and ``start + duration``, group by group."""

    def __init__(self, rest: np.ndarray, final: np.ndarray, duration: float, start: float,
                 groups: list[np.ndarray]) -> None:
        from scipy.spatial.transform import Rotation

        self.rest, self.final = rest, final
        self.start, self.duration = start, duration
        self.moves = []  # (indices, centre, centre's displacement, rotation vector) or None
        for g in groups:
            X, T = rest[g], final[g]
            R, t = rigid_motion(X, T)
            size = max(1.0, float(np.abs(X).max()), float(np.abs(T).max()))
            if len(g) >= 3 and np.abs(X @ R.T + t - T).max() <= 1e-9 * size:
                c = X.mean(axis=0)
                self.moves.append((g, c, c @ R.T + t - c, Rotation.from_matrix(R).as_rotvec()))
            else:
                self.moves.append((g, None, None, None))

    def __call__(self, t: float) -> np.ndarray:
        from scipy.spatial.transform import Rotation

        s = 1.0 if self.duration == 0 else (t - self.start) / self.duration
        s = min(max(s, 0.0), 1.0)
        out = self.rest.copy()
        for g, c, dc, rv in self.moves:
            if c is None:  # not a rigid motion: straight lines
                out[g] = (1.0 - s) * self.rest[g] + s * self.final[g]
            else:
                Rs = Rotation.from_rotvec(s * rv).as_matrix()
                out[g] = c + s * dc + (self.rest[g] - c) @ Rs.T
        return out


def ramp(rest, final, duration: float, groups: Sequence[Sequence[int]] | None = None,
         start: float = 0.0):
    """Handles moving from ``rest`` to ``final`` between ``start`` and ``start + duration``.

    Each group (positions in the handle list; default: all handles as one group) whose
    ``final`` positions are one rigid motion of its ``rest`` positions turns and moves by
    that motion's angle and translation in proportion to time, about its centroid;
    another group moves along straight lines.

    Parameters
    ----------
    rest, final : (h, 3)
    duration : float
        Seconds (>= 0; 0 jumps to ``final`` at ``start``).
    groups : list of int arrays, optional
        e.g. one per group of a handle file.
    start : float

    Returns
    -------
    callable(t) -> (h, 3)

    Examples
    --------
    >>> import numpy as np
    >>> X = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0]])
    >>> turned = X @ np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]).T   # a quarter turn
    >>> half = ramp(X, turned, 2.0)(1.0)                                  # an eighth
    >>> round(float(np.linalg.norm(half[0] - half[1])), 9)  # not shrunk (lines: 1.414)
    2.0
    """
    R0 = real_array(rest, "rest")
    T = real_array(final, "final")
    if R0.ndim != 2 or R0.shape[1:] != (3,) or T.shape != R0.shape:
        raise InputError(f"ramp: rest and final must both be (h, 3), got {R0.shape} and "
                         f"{T.shape}")
    if not (np.isfinite(R0).all() and np.isfinite(T).all()):
        raise InputError("ramp: rest and final must be finite")
    duration = number(duration, "duration", lo=0.0)
    start = number(start, "start")
    h = len(R0)
    gs = [np.arange(h)] if groups is None else [np.asarray(g, dtype=np.int64) for g in groups]
    for g in gs:
        if len(g) and (g.min() < 0 or g.max() >= h):
            raise InputError(f"ramp: a group names handle {int(g.max())}, out of range "
                             f"({h} handles)")
    return _Ramp(R0, T, duration, start, gs)
