"""Which way is up: bounding box, an up-axis guess and named camera views.

Mesh files do not say which axis points up: scanned and game models are mostly y-up,
CAD and animation rigs (Blender, Panda3D, MakeHuman) mostly z-up. Figures, the editor and
``arapkit info`` all use :func:`guess_up`, so a model looks the same way up everywhere.

The rule (measured on every mesh of ``../shared/data``, see ``docs/figures.md``):

1. Candidates are +y and +z, the two conventions (files stored upside down or x-up are
   rare; ``--up`` overrides).
2. For each candidate, the *contact patch* is the set of vertices within 3 % of the
   extent above the lowest point. The object *stands* on that axis when the centroid's
   projection lies inside the patch's convex hull (feet, a base, a belly); its *support*
   is then the hull's area over the box's cross-section, else 0.
3. The candidate with clearly more support wins (confidence = relative difference of the
   two supports). When neither stands, or both stand about equally (a box), the axis
   of larger extent wins, ties to +z (confidence at most 0.5: a guess from the shape of
   the box only).

Examples
--------
>>> import numpy as np
>>> from arapkit.mesh.shapes import bar
>>> guess_up(bar().vertices).axis            # a square bar: a tie, +z by convention
'+z'
>>> bounding_box(np.array([[0.0, 0, 0], [1, 2, 3]])).extents.tolist()
[1.0, 2.0, 3.0]
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import InputError
from ..validate import positions_of
from .model import bounding_box_diagonal

__all__ = [
    "AXES",
    "VIEWS",
    "BoundingBox",
    "UpGuess",
    "bounding_box",
    "guess_up",
    "parse_axis",
    "view_frame",
]

#: Signed axis names accepted by ``--up``.
AXES = ("+x", "-x", "+y", "-y", "+z", "-z")
#: Camera views accepted by ``--view``.
VIEWS = ("front", "side", "back", "top", "iso")
_CONTACT = 0.03  # contact patch: this fraction of the extent above the lowest point
_CLEAR = 0.1  # supports closer than this (relative) count as a tie
# (turn about up, tilt down) in degrees: a little of both keeps depth readable under the
# headlight shading (a face-on view of a box is one flat colour)
_TURN_TILT = {"front": (15.0, 10.0), "side": (105.0, 10.0), "back": (195.0, 10.0),
              "top": (0.0, 90.0), "iso": (40.0, 30.0)}


@dataclasses.dataclass(frozen=True)
class BoundingBox:
    """Axis-aligned box: ``min``, ``max`` and ``extents`` (max - min), each (3,)."""

    min: np.ndarray
    max: np.ndarray

    @property
    def extents(self) -> np.ndarray:
        return self.max - self.min

    @property
    def diagonal(self) -> float:
        """Length of the diagonal (:func:`arapkit.mesh.model.bounding_box_diagonal`)."""
        return bounding_box_diagonal(np.stack([self.min, self.max]))


@dataclasses.dataclass(frozen=True)
class UpGuess:
    """An up-axis guess: ``axis`` ('+y' or '+z'), ``confidence`` in [0, 1], ``reason``."""

    axis: str
    confidence: float
    reason: str


def bounding_box(vertices: np.ndarray) -> BoundingBox:
    """Axis-aligned bounding box of ``vertices`` (n, 3).

    Examples
    --------
    >>> bounding_box(np.array([[1.0, 0, -1], [2, 5, 1]])).max.tolist()
    [2.0, 5.0, 1.0]
    """
    V = np.asarray(positions_of(vertices), dtype=np.float64).reshape(-1, 3)
    if len(V) == 0:
        z = np.zeros(3)
        return BoundingBox(z, z.copy())
    return BoundingBox(V.min(axis=0), V.max(axis=0))


def parse_axis(text: str) -> np.ndarray:
    """Unit vector of a signed axis name ('+y', '-z', 'x' = '+x').

    Examples
    --------
    >>> parse_axis("-z").tolist()
    [0.0, 0.0, -1.0]
    """
    t = str(text).strip().lower()
    if t in ("x", "y", "z"):
        t = "+" + t
    if t not in AXES:
        raise InputError(f"up axis {text!r}: expected one of {', '.join(AXES)}")
    v = np.zeros(3)
    v["xyz".index(t[1])] = 1.0 if t[0] == "+" else -1.0
    return v


def _support(V: np.ndarray, axis: int) -> float:
    """Contact-hull area over box cross-section if the shape stands on ``axis``'s minimum."""
    from scipy.spatial import ConvexHull, Delaunay, QhullError

    h = V[:, axis]
    ext = float(np.ptp(h))
    others = [k for k in range(3) if k != axis]
    span = np.ptp(V[:, others], axis=0)
    if ext <= 0 or np.any(span <= 0):
        return 0.0
    patch = V[h <= h.min() + _CONTACT * ext][:, others]
    centre = V.mean(axis=0)[others]
    try:
        hull = ConvexHull(patch)
        inside = Delaunay(patch[hull.vertices]).find_simplex(centre) >= 0
    except (QhullError, ValueError):  # fewer than 3 points, or all on a line
        return 0.0
    return float(hull.volume / (span[0] * span[1])) if inside else 0.0


def guess_up(vertices: np.ndarray) -> UpGuess:
    """Guess the up axis of a model (+y or +z) from where it stands (see module notes).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> table = rng.random((2000, 3)) * [2, 0.1, 1] + [0, 1, 0]      # a y-up table top ...
    >>> legs = np.concatenate([rng.random((200, 3)) * [0.1, 1, 0.1] + [x, 0, z]
    ...                        for x in (0, 1.9) for z in (0, 0.9)])  # ... on four legs
    >>> g = guess_up(np.concatenate([table, legs]))  # it also "stands" on its long edge,
    >>> g.axis, g.confidence < 0.5                   # so the taller side decides: low confidence
    ('+y', True)
    """
    V = np.asarray(positions_of(vertices), dtype=np.float64).reshape(-1, 3)
    if len(V) < 4:
        return UpGuess("+z", 0.0, "too few vertices: +z by convention")
    s = {"+y": _support(V, 1), "+z": _support(V, 2)}
    hi, lo = sorted(s, key=s.get, reverse=True)
    if s[hi] > 0 and s[hi] - s[lo] > _CLEAR * s[hi]:
        conf = (s[hi] - s[lo]) / s[hi]
        why = f"stands on its {hi[1]}-minimum (support {s[hi]:.2f} vs {s[lo]:.2f})"
        return UpGuess(hi, round(float(conf), 2), why)
    e = bounding_box(V).extents
    axis = "+y" if e[1] > e[2] else "+z"
    conf = 0.5 * abs(e[1] - e[2]) / max(e[1], e[2], 1e-300)
    why = (
        "stands on neither y nor z" if s[hi] == 0 else "stands on y and z alike"
    ) + f": the taller of y ({e[1]:.3g}) and z ({e[2]:.3g}), ties to +z"
    return UpGuess(axis, round(float(conf), 2), why)


def _signed_axis(k: int, sign: float) -> np.ndarray:
    v = np.zeros(3)
    v[k] = sign
    return v


def view_frame(
    vertices: np.ndarray, view: str = "front", up: str | None = None
) -> tuple[np.ndarray, str]:
    """Orthonormal camera basis (rows: screen right, screen up, towards the viewer).

    ``up`` (a signed axis, default :func:`guess_up`) points up on screen. *front* looks
    along the axis of least extent among the other two, from the side that puts a
    positive axis on the screen's right, turned 15 degrees about up and tilted 10 degrees
    down so that depth shows; *side* and *back* are front turned a further 90 and 180
    degrees; *top* looks straight down (front's top edge away from the viewer); *iso* is
    turned 40 degrees and tilted 30 degrees down.

    Returns
    -------
    basis : (3, 3), up : the up axis used (e.g. '+y').

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[0.0, 0, 0], [4, 0, 0], [0, 1, 0], [0, 0, 2]])
    >>> B, up = view_frame(V, "top", "+y")      # x is long, z in between: front looks along z
    >>> (B.round(6) + 0.0).tolist(), up
    ([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]], '+y')
    >>> B = view_frame(V, "front", "+y")[0]
    >>> bool(B[1] @ [0, 1, 0] > 0.98), bool(B[2] @ [0, 0, 1] > 0.95)  # upright, looking along z
    (True, True)
    """
    if view not in VIEWS:
        raise InputError(f"view {view!r}: expected one of {', '.join(VIEWS)}")
    if up is None:
        up = guess_up(vertices).axis
    u = parse_axis(up)
    k_up = int(np.argmax(np.abs(u)))
    ext = bounding_box(vertices).extents
    others = [k for k in range(3) if k != k_up]
    k_look = min(others, key=lambda k: (ext[k], k))
    towards = _signed_axis(k_look, 1.0)
    if np.cross(u, towards).sum() < 0:  # keep a positive axis pointing right
        towards = -towards
    turn, tilt = _TURN_TILT[view]
    towards = _rotate(towards, u, turn)
    right = np.cross(u, towards)
    if view == "top":
        B = np.stack([right, -towards, u])
    else:
        t = np.radians(tilt)
        B = np.stack([right, np.cos(t) * u - np.sin(t) * towards,
                      np.sin(t) * u + np.cos(t) * towards])
    B = B / np.linalg.norm(B, axis=1, keepdims=True)
    return B, ("+" if u[k_up] > 0 else "-") + "xyz"[k_up]


def _rotate(v: np.ndarray, axis: np.ndarray, degrees: float) -> np.ndarray:
    """Rotate ``v`` about the unit ``axis`` (Rodrigues)."""
    a = np.radians(degrees)
    return v * np.cos(a) + np.cross(axis, v) * np.sin(a) + axis * (axis @ v) * (1 - np.cos(a))
