"""Colour views of the editor: rigidity r (1 blue ... 6 red) and per-vertex energy.

The colours come from :mod:`arapkit.plots.colors`, the same as in the figures.

viser meshes carry one colour each, so a coloured view is drawn as a few sub-meshes, one
per colour bin, each with only the vertices its faces use.  During a drag only their
vertex arrays are refreshed; the split is recomputed when the colours change.

Examples
--------
>>> import numpy as np
>>> F = np.array([[0, 1, 2], [1, 3, 2]])
>>> groups = face_groups(F, np.array([0, 0, 0, 5]), 6)
>>> [(g.label, g.vertices.tolist(), g.faces.tolist()) for g in groups]
[(0, [0, 1, 2], [[0, 1, 2]]), (5, [1, 2, 3], [[0, 2, 1]])]
"""

from __future__ import annotations

import dataclasses

import numpy as np

from arapkit.plots.colors import ENERGY_CMAP, RING_COLORS

ENERGY_BINS = 8
SHADED_COLOR = (190, 195, 205)


@dataclasses.dataclass(frozen=True)
class FaceGroup:
    """Faces of one colour, re-indexed into their own vertex list."""

    label: int
    vertices: np.ndarray  # (k,) indices into the full vertex array
    faces: np.ndarray  # (m, 3) indices into ``vertices``


def ring_labels(rings: np.ndarray) -> np.ndarray:
    """Colour bin (0..5) of each vertex's r."""
    return np.clip(np.asarray(rings, dtype=np.int64), 1, len(RING_COLORS)) - 1


def energy_scale(vertex_energy: np.ndarray) -> float:
    """Upper end of the energy colour bar: the 99th percentile, robust to a few spikes."""
    e = np.asarray(vertex_energy, dtype=np.float64)
    e = e[np.isfinite(e)]
    if e.size == 0:
        return 1.0
    top = float(np.percentile(e, 99))
    return top if top > 0 else max(float(e.max()), 1e-30)


def energy_labels(vertex_energy: np.ndarray, vmax: float, bins: int = ENERGY_BINS) -> np.ndarray:
    """Colour bin (0..bins-1) of each vertex energy on a linear scale [0, vmax]."""
    e = np.nan_to_num(np.asarray(vertex_energy, dtype=np.float64), nan=0.0)
    return np.clip((e / vmax * bins).astype(np.int64), 0, bins - 1)


def energy_colors(bins: int = ENERGY_BINS) -> list[tuple[int, int, int]]:
    """Bin colours from :data:`arapkit.plots.colors.ENERGY_CMAP` (pale = low energy, dark red =
    high)."""
    from matplotlib import colormaps

    cmap = colormaps[ENERGY_CMAP]
    return [
        tuple(int(255 * c) for c in cmap((k + 0.5) / bins)[:3])  # type: ignore[misc]
        for k in range(bins)
    ]


def face_groups(faces: np.ndarray, vertex_labels: np.ndarray, n_labels: int) -> list[FaceGroup]:
    """Split faces by the largest label among their corners.

    Taking the maximum means a painted region shows its boundary faces in its own
    colour, so a single painted vertex is still visible.
    """
    F = np.asarray(faces, dtype=np.int64)
    flab = np.asarray(vertex_labels)[F].max(axis=1)
    groups = []
    for k in range(n_labels):
        sel = F[flab == k]
        if len(sel) == 0:
            continue
        vidx, local = np.unique(sel, return_inverse=True)
        groups.append(FaceGroup(k, vidx, local.reshape(-1, 3)))
    return groups


def _swatch(rgb: tuple[int, int, int], text: str) -> str:
    r, g, b = rgb
    return (
        f'<span style="display:inline-block;width:0.9em;height:0.9em;'
        f'background:rgb({r},{g},{b});margin:0 3px 0 8px;vertical-align:middle"></span>{text}'
    )


def rings_legend_html() -> str:
    """Legend of the r view."""
    items = [
        _swatch(c, f"{k + 1}" + ("+" if k == len(RING_COLORS) - 1 else ""))
        for k, c in enumerate(RING_COLORS)
    ]
    return "<div style='font-size:0.8em'>r: " + "".join(items) + "</div>"


def energy_legend_html(vmax: float, bins: int = ENERGY_BINS) -> str:
    """Legend of the energy view (bin edges)."""
    cols = energy_colors(bins)
    items = [_swatch(cols[0], "0"), _swatch(cols[-1], f"&ge;{vmax * (bins - 1) / bins:.3g}")]
    return "<div style='font-size:0.8em'>vertex energy: " + "".join(items) + "</div>"
