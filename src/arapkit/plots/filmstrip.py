"""A filmstrip: frames of an animation side by side, in one view and one frame of reference.

Every panel shares the camera (set from the first frame, upright as the other figures:
:func:`arapkit.mesh.orientation.view_frame`) and the same screen window, the box around
all the frames shown, so motion reads as motion: a falling body drops from panel to panel
instead of being re-centred in each. The first frame is drawn faintly behind the others.

Examples
--------
>>> import numpy as np
>>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]); F = np.array([[0, 1, 2]])
>>> fig = filmstrip_figure(F, [V, V + [0, 0, -1]], [0.0, 0.5])
>>> [a.get_title() for a in fig.axes]
['t = 0 s', 't = 0.5 s']
"""

from __future__ import annotations

from collections.abc import Sequence

from ..errors import require_extra

# one line naming the extra instead of a bare "No module named 'matplotlib'"
require_extra("matplotlib", "plots", "arapkit.plots")

import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from ..mesh.orientation import view_frame  # noqa: E402
from .render import (  # noqa: E402
    DEFAULT_MAX_FACES,
    FIXED_COLOR,
    REST_COLOR,
    mark,
    new_figure,
    render_mesh,
)

__all__ = ["filmstrip_figure", "pick_frames"]


def pick_frames(count: int, panels: int = 6) -> list[int]:
    """``panels`` frame numbers spread evenly over ``count`` frames, first and last included.

    Examples
    --------
    >>> pick_frames(121, 5), pick_frames(3, 6)
    ([0, 30, 60, 90, 120], [0, 1, 2])
    """
    if count <= panels:
        return list(range(count))
    return sorted({int(round(x)) for x in np.linspace(0, count - 1, panels)})


def filmstrip_figure(
    faces: np.ndarray,
    frames: Sequence[np.ndarray],
    times: Sequence[float],
    *,
    handles: np.ndarray | None = None,
    title: str | None = None,
    ncols: int | None = None,
    max_faces: int = DEFAULT_MAX_FACES,
    view: str = "front",
    up: str | None = None,
) -> Figure:
    """Frames of one mesh in a row (or rows), one camera and one window for all.

    Parameters
    ----------
    faces : (m, 3)
    frames : list of (n, 3)
        The shapes to show (e.g. :func:`pick_frames` of a trajectory).
    times : list of float
        Their times in seconds (panel titles).
    handles : (h,) int, optional
        Handle vertices, marked in each panel.
    title : str, optional
    ncols : int, optional
        Panels per row (default all in one row).
    view, up : the camera (see :func:`arapkit.mesh.orientation.view_frame`), set from the
        first frame.
    """
    if len(frames) == 0 or len(frames) != len(times):
        raise ValueError("filmstrip_figure: one time per frame, at least one frame")
    ncols = ncols or len(frames)
    nrows = -(-len(frames) // ncols)
    fig = new_figure(figsize=(2.6 * ncols, 2.9 * nrows + (0.3 if title else 0.0)), dpi=110,
                     layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols)).ravel()
    basis = view_frame(np.asarray(frames[0]), view, up)[0]
    screen = np.concatenate([np.asarray(V) @ basis[:2].T for V in frames])
    lo, hi = screen.min(axis=0), screen.max(axis=0)
    pad = 0.05 * max(float(np.max(hi - lo)), 1e-12)
    first = np.asarray(frames[0])
    for k, (ax, V, t) in enumerate(zip(axes, frames, times, strict=False)):
        if k:  # where it started, faintly behind
            render_mesh(ax, first, faces, basis=basis, max_faces=max_faces // 4,
                        color=0.5 * REST_COLOR + 0.5)
        render_mesh(ax, np.asarray(V), faces, basis=basis, max_faces=max_faces)
        if handles is not None and len(handles):
            mark(ax, np.asarray(V)[handles], basis, FIXED_COLOR, "handles")
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_title(f"t = {t:.3g} s", fontsize=9)
    for ax in axes[len(frames):]:
        ax.set_axis_off()
    if title:
        fig.suptitle(title, fontsize=10)
    return fig
