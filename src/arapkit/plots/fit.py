"""The figure of a template fit: the fitted template coloured by residual distance.

Built on :mod:`arapkit.plots.render` like the other figures (no pyplot). Residuals are shown
as a percentage of the target's bounding-box diagonal, on a fixed scale from 0 to 2 % (beyond
is the darkest colour), so that two fits' figures compare at a glance; the target's points
can be drawn faintly behind, to show where the scan reaches beyond the template.

Examples
--------
>>> import numpy as np
>>> from arapkit.mesh.shapes import bar
>>> m = bar()
>>> fig = residual_figure(m.vertices, m.faces, np.zeros(m.n_vertices), 1.0)
>>> [a.get_title() for a in fig.axes[:2]]
['front view (up +z)', 'back view (up +z)']
"""

from __future__ import annotations

from collections.abc import Sequence

from ..errors import require_extra

require_extra("matplotlib", "plots", "arapkit.plots")

import numpy as np  # noqa: E402
from matplotlib.colors import Normalize  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from ..mesh.orientation import view_frame  # noqa: E402
from .colors import ENERGY_CMAP  # noqa: E402
from .render import DEFAULT_MAX_FACES, colorbar, new_figure, render_mesh  # noqa: E402

__all__ = ["RESIDUAL_SCALE", "residual_figure"]

#: the colour scale's top, in percent of the target's diagonal
RESIDUAL_SCALE = 2.0


def residual_figure(
    vertices: np.ndarray,
    faces: np.ndarray,
    residuals: np.ndarray,
    diagonal: float,
    *,
    points: np.ndarray | None = None,
    title: str | None = None,
    views: Sequence[str] = ("front", "back"),
    up: str | None = None,
    max_faces: int = DEFAULT_MAX_FACES,
) -> Figure:
    """The fitted template, one panel per view, coloured by ``residuals / diagonal``.

    Parameters
    ----------
    vertices, faces : the fitted template.
    residuals : (n,) each vertex's distance to the target.
    diagonal : the target's bounding-box diagonal (the unit of the colour scale).
    points : (k, 3), optional; target points drawn faintly behind (a subsample).
    title, views, up, max_faces : as for :func:`arapkit.plots.figures.rings_figure`.
    """
    pct = 100.0 * np.asarray(residuals, dtype=np.float64) / diagonal
    norm = Normalize(0.0, RESIDUAL_SCALE)
    fig = new_figure(figsize=(max(5.0 * len(views), 8.0), 4.2), layout="constrained")
    axes = fig.subplots(1, len(views), squeeze=False)[0]
    for ax, view in zip(axes, views, strict=True):
        basis, used_up = view_frame(vertices, view, up)
        if points is not None and len(points):
            step = max(1, len(points) // 20000)
            xy = np.asarray(points)[::step] @ basis[:2].T
            ax.scatter(xy[:, 0], xy[:, 1], s=0.3, color="0.55", edgecolors="none", zorder=0)
        render_mesh(ax, vertices, faces, pct, basis=basis, cmap=ENERGY_CMAP, norm=norm,
                    max_faces=max_faces)
        ax.set_title(f"{view} view (up {used_up})", fontsize=9)
    colorbar(fig, list(axes), norm, ENERGY_CMAP,
             f"distance to the target, % of its diagonal ({RESIDUAL_SCALE:g} % and more: "
             "darkest)")
    if title:
        fig.suptitle(title, fontsize=10)
    return fig
