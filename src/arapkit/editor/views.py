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

import numba as nb
import numpy as np

from arapkit.mesh.model import kernel_input
from arapkit.plots.colors import ENERGY_CMAP, RING_COLORS

ENERGY_BINS = 8
SHADED_COLOR = (190, 195, 205)
#: strains below this are not worth a colour: the energy scale never reads lower
VISIBLE_STRAIN = 1e-3


@dataclasses.dataclass(frozen=True)
class FaceGroup:
    """Faces of one colour, re-indexed into their own vertex list."""

    label: int
    vertices: np.ndarray  # (k,) indices into the full vertex array
    faces: np.ndarray  # (m, 3) uint32 indices into ``vertices``


def ring_labels(rings: np.ndarray) -> np.ndarray:
    """Colour bin (0..5) of each vertex's r."""
    return np.clip(np.asarray(rings, dtype=np.int64), 1, len(RING_COLORS)) - 1


def energy_floor(unit: float) -> float:
    """The lowest top of the energy colour bar, for a mesh whose energy unit is ``unit``.

    ``unit`` is the energy of one vertex at rest scale, ``sum_e D_e |e|^2`` over the
    vertices (what a vertex's term would be if every edge doubled): a uniform strain
    ``s`` gives about ``s^2 * unit`` per vertex.  Below :data:`VISIBLE_STRAIN` the colours
    would show round-off and the last digits of a stopped solve, not a deformation.

    Examples
    --------
    >>> energy_floor(2.0)
    2e-06
    >>> energy_floor(float("nan"))
    0.0
    """
    return VISIBLE_STRAIN**2 * unit if np.isfinite(unit) and unit > 0 else 0.0


def energy_scale(vertex_energy: np.ndarray, floor: float = 0.0) -> float:
    """Top of the energy colour bar: the 99th percentile (robust to a few spikes), at
    least ``floor`` (:func:`energy_floor`), so that a shape at rest reads uniformly 0.

    Examples
    --------
    >>> energy_scale(np.array([1e-12, 3e-12]), floor=1e-6)
    1e-06
    """
    e = np.asarray(vertex_energy, dtype=np.float64)
    e = e[np.isfinite(e)]
    if e.size == 0:
        return max(1.0, floor)
    top = float(np.percentile(e, 99))
    return max(top if top > 0 else max(float(e.max()), 1e-30), floor)


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
    colour, so a single painted vertex is still visible. Within a group the faces keep
    their order and the vertices are sorted (what ``np.unique(..., return_inverse=True)``
    gives).

    Examples
    --------
    >>> import numpy as np
    >>> g = face_groups(np.array([[0, 1, 2], [2, 3, 4]]), np.array([0, 0, 0, 1, 0]), 2)
    >>> [(x.label, x.vertices.tolist(), x.faces.tolist()) for x in g]
    [(0, [0, 1, 2], [[0, 1, 2]]), (1, [2, 3, 4], [[0, 1, 2]])]
    """
    # Every repaint in the r view rebuilds these: at 1.75M vertices (3.5M faces) the
    # np.unique version took 2.5 s and a boolean-mask one 0.4 s; two compiled passes per
    # group take 0.1 s
    F, labels = kernel_input(faces, np.int64), kernel_input(vertex_labels, np.int64)
    flab, count = _face_labels(F, labels, n_labels)
    groups = []
    for k in range(n_labels):
        if count[k]:
            vidx, local = _one_group(F, flab, k, int(count[k]), len(labels))
            groups.append(FaceGroup(k, vidx, local))
    return groups


@nb.njit(cache=True, nogil=True)
def _face_labels(F, labels, n_labels):
    """Each face's label (the largest of its corners') and the number of faces per label."""
    flab = np.empty(F.shape[0], dtype=np.int16)
    count = np.zeros(n_labels, dtype=np.int64)
    for f in range(F.shape[0]):
        a = max(labels[F[f, 0]], labels[F[f, 1]], labels[F[f, 2]])
        flab[f] = a
        count[a] += 1
    return flab, count


@nb.njit(cache=True, nogil=True)
def _one_group(F, flab, k, size, n_vertices):
    """Label k's vertices (sorted) and its faces numbered into them, in face order."""
    local = np.zeros(n_vertices, dtype=np.int64)
    for f in range(F.shape[0]):
        if flab[f] == k:
            local[F[f, 0]] = 1
            local[F[f, 1]] = 1
            local[F[f, 2]] = 1
    n_used = 0
    for v in range(n_vertices):
        if local[v]:
            n_used += 1
    vidx = np.empty(n_used, dtype=np.int64)
    j = 0
    for v in range(n_vertices):
        if local[v]:
            vidx[j] = v
            local[v] = j
            j += 1
    out = np.empty((size, 3), dtype=np.uint32)  # what the scene takes: no copy to send
    i = 0
    for f in range(F.shape[0]):
        if flab[f] == k:
            out[i, 0] = local[F[f, 0]]
            out[i, 1] = local[F[f, 1]]
            out[i, 2] = local[F[f, 2]]
            i += 1
    return vidx, out


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


def energy_legend_html(vmax: float, bins: int = ENERGY_BINS, floor: float = 0.0,
                       top: float | None = None) -> str:
    """Legend of the energy view (bin edges).

    ``floor`` is :func:`energy_floor`; ``top`` the largest vertex energy shown.  When the
    scale sits on the floor the legend says so, and when every vertex is in the lowest
    bin it says that the energy is zero to the strain the colours show.

    Examples
    --------
    >>> "0 everywhere" in energy_legend_html(1e-6, floor=1e-6, top=4e-10)
    True
    """
    cols = energy_colors(bins)
    head = "<div style='font-size:0.8em'>vertex energy: "
    strain = f"{100 * VISIBLE_STRAIN:g} %"
    if top is not None and top < vmax / bins:
        return head + _swatch(cols[0], f"0 everywhere (strain below {strain})") + "</div>"
    items = [_swatch(cols[0], "0"), _swatch(cols[-1], f"&ge;{vmax * (bins - 1) / bins:.3g}")]
    note = f" (scale floor: strain {strain})" if floor > 0 and vmax <= floor else ""
    return head + "".join(items) + note + "</div>"
