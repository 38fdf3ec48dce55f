"""Edge weights (cotangent, uniform) and mixed Voronoi vertex areas.

Weight kinds
------------
* ``"cotan-clamped"`` (the default, :data:`DEFAULT_WEIGHTS`): the cotangent weights below,
  then every weight below ``CLAMP_FRACTION`` times the mean absolute weight is raised to
  that floor. Every weight is positive, so eq. (1) is a sum of squares (E >= 0), the rest
  shape is an exact minimum (no drift when the handles stay put) and the reduced system is
  positive definite for every r. Where the mesh has no obtuse triangles it equals
  ``"cotan"`` up to the floor. ``docs/weights.md`` has the measurements (against raw
  cotangents and intrinsic-Delaunay weights) this choice was made from.
* ``"cotan"`` (paper eq. 2): ``w_ij = (cot a_ij + cot b_ij) / 2`` exactly. Each cotangent is
  capped at ``COT_CAP`` in absolute value so that needle triangles give large but finite
  weights. Obtuse triangles make weights negative: the energy can then be negative, the
  rest shape can drift, and the reduced system can be indefinite, in which case the solver
  stops with an :class:`~arapkit.errors.InputError` that names the remedy. Kept for the
  paper's experiments and for agreement with libigl.
* ``"cotan-clamped-each"``: ``w_ij = (max(cot a_ij, 0) + max(cot b_ij, 0)) / 2``: every
  cotangent is clamped at 0 *before* the two are summed, as CGAL's
  ``Surface_mesh_deformation`` does for ``ORIGINAL_ARAP`` and ``SRE_ARAP``
  (``CGAL::Weights::Cotangent_weight``). For porting from CGAL: it reproduces CGAL's problem
  (``docs/methods.md``). Weights are >= 0 (E >= 0); an edge whose two opposite angles are
  both obtuse gets weight 0 and drops out, where ``"cotan-clamped"`` keeps it with a small
  positive weight (it clamps the *sum*, and only below a floor).
* ``"uniform"``: ``w_ij = 1``.
* An array of per-edge weights aligned with ``mesh.edges`` (finite and > 0), for edge graphs
  whose weights come from elsewhere (e.g. the tetrahedral weights of
  :mod:`arapkit.methods.volumetric`).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..errors import InputError
from .model import Mesh

__all__ = [
    "WEIGHT_KINDS",
    "DEFAULT_WEIGHTS",
    "SOUND_WEIGHTS",
    "COT_CAP",
    "edge_weights",
    "given_weights",
    "corner_cotangents",
    "cotangent_weights",
    "voronoi_areas",
]

WEIGHT_KINDS = ("cotan", "cotan-clamped", "cotan-clamped-each", "uniform")
#: the weighting every interface uses unless the user names another (see docs/weights.md)
DEFAULT_WEIGHTS = "cotan-clamped"
#: what messages suggest when raw cotangent weights misbehave
SOUND_WEIGHTS = "cotan-clamped"
COT_CAP = 1e5
CLAMP_FRACTION = 1e-3


def corner_cotangents(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Cotangent of the angle at each corner, shape (m, 3); corner c faces edge (c+1, c+2).

    Computed scale-free and capped at ``COT_CAP`` in absolute value (needles stay finite).

    Examples
    --------
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> np.round(corner_cotangents(V, np.array([[0, 1, 2]])), 12).tolist()
    [[0.0, 1.0, 1.0]]
    """
    cots = np.empty(np.shape(F), dtype=np.float64)
    _corner_cotangents(np.ascontiguousarray(V, dtype=np.float64),
                       np.ascontiguousarray(F, dtype=np.int64), cots)
    return cots


_NO_RESCALE_BELOW, _NO_RESCALE_ABOVE = 2.0**-100, 2.0**100


@nb.njit(parallel=True, cache=True, nogil=True)
def _corner_cotangents(V, F, out):  # pragma: no cover - compiled
    # One pass over the faces (the NumPy version made ~40 temporaries of the face count:
    # 0.7 s of a 437K-vertex precomputation).
    for f in nb.prange(F.shape[0]):
        for c in range(3):
            o, i, j = F[f, c], F[f, (c + 1) % 3], F[f, (c + 2) % 3]
            a0, a1, a2 = V[i, 0] - V[o, 0], V[i, 1] - V[o, 1], V[i, 2] - V[o, 2]
            b0, b1, b2 = V[j, 0] - V[o, 0], V[j, 1] - V[o, 1], V[j, 2] - V[o, 2]
            # cot is scale-free: far from 1, divide both sides by a power of two near
            # their size (exact) so that dot and cross neither overflow (coordinates
            # ~1e200) nor underflow (~1e-160); in between the scaling changes no bit
            big = max(abs(a0), abs(a1), abs(a2), abs(b0), abs(b1), abs(b2))
            if not _NO_RESCALE_BELOW < big < _NO_RESCALE_ABOVE and math.isfinite(big):
                e = math.frexp(big)[1]
                a0, a1, a2 = math.ldexp(a0, -e), math.ldexp(a1, -e), math.ldexp(a2, -e)
                b0, b1, b2 = math.ldexp(b0, -e), math.ldexp(b1, -e), math.ldexp(b2, -e)
            dot = a0 * b0 + a1 * b1 + a2 * b2
            x, y, z = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
            cot = dot / math.sqrt(x * x + y * y + z * z)
            if math.isnan(dot):
                out[f, c] = dot
            elif not math.isfinite(cot):  # a degenerate corner: 0/0 or dot/0
                out[f, c] = 0.0 if dot == 0.0 else math.copysign(COT_CAP, dot)
            else:
                out[f, c] = min(max(cot, -COT_CAP), COT_CAP)


def cotangent_weights(mesh: Mesh, clamp_corners: bool = False) -> np.ndarray:
    """Cotangent weight ``(cot a + cot b) / 2`` of every edge in ``mesh.edges``.

    Boundary edges have one opposite angle and get half its cotangent. With
    ``clamp_corners`` every cotangent is first raised to at least 0 (CGAL's weights).

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit import Mesh
    >>> m = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> np.round(cotangent_weights(m), 6).tolist()   # edges (0,1), (0,2), (1,2)
    [0.5, 0.5, 0.0]
    >>> obtuse = Mesh([[0, 0, 0], [2, 0, 0], [1, 0.2, 0]], [[0, 1, 2]])
    >>> float(cotangent_weights(obtuse, clamp_corners=True)[0])  # (0,1) faces the obtuse corner
    0.0
    """
    F = mesh.faces
    cots = corner_cotangents(mesh.vertices, F)
    if clamp_corners:
        cots = np.maximum(cots, 0.0)
    # the edge opposite corner c is face edge c+1, from corner c+1 to corner c+2
    opposite = np.roll(mesh.face_edges, -1, axis=1)
    return np.bincount(opposite.ravel(), 0.5 * cots.ravel(), minlength=len(mesh.edges))


def edge_weights(mesh: Mesh, kind: str | np.ndarray = DEFAULT_WEIGHTS) -> np.ndarray:
    """Weight of every edge of ``mesh.edges`` for the given policy.

    Parameters
    ----------
    mesh : Mesh
    kind : {"cotan", "cotan-clamped", "cotan-clamped-each", "uniform"} or array
        A policy name (see the module's docstring), or the weights themselves (checked:
        finite, > 0, one per edge of ``mesh.edges``).

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.mesh.shapes import bar
    >>> w = edge_weights(bar(), "uniform")
    >>> bool((w == 1).all())
    True
    >>> edge_weights(bar(), np.full(len(bar().edges), 2.0))[:2].tolist()
    [2.0, 2.0]
    """
    if not isinstance(kind, str):
        return given_weights(mesh, kind)
    if kind == "uniform":
        return np.ones(len(mesh.edges))
    if kind not in WEIGHT_KINDS:
        raise InputError(f"unknown weights '{kind}' (choose one of {', '.join(WEIGHT_KINDS)})")
    w = cotangent_weights(mesh, clamp_corners=kind == "cotan-clamped-each")
    if kind == "cotan-clamped":
        floor = CLAMP_FRACTION * max(float(np.mean(np.abs(w))), 1e-300)
        w = np.maximum(w, floor)
    return w


def given_weights(mesh: Mesh, w) -> np.ndarray:
    """Validate explicit per-edge weights: one per edge of ``mesh.edges``, finite, > 0
    (``mesh``: anything with ``edges`` and ``name``, a point cloud's graph too).

    Examples
    --------
    >>> from arapkit import Mesh
    >>> given_weights(Mesh(np.eye(3), [[0, 1, 2]]), [1, 2, 3]).tolist()
    [1.0, 2.0, 3.0]
    """
    try:
        w = np.array(w, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{mesh.name}: weights must be a policy name or numbers") from None
    if w.shape != (len(mesh.edges),):
        raise InputError(
            f"{mesh.name}: expected {len(mesh.edges)} edge weights (one per edge), got shape "
            f"{w.shape}"
        )
    bad = np.flatnonzero(~(np.isfinite(w) & (w > 0)))
    if len(bad):
        i, j = mesh.edges[bad[0]]
        raise InputError(
            f"{mesh.name}: weight of edge {bad[0]} ({i}, {j}) is {float(w[bad[0]])!r}; explicit "
            "weights must be finite and > 0"
        )
    return w


def voronoi_areas(mesh: Mesh) -> np.ndarray:
    """Mixed Voronoi area of each vertex (Meyer, Desbrun, Schröder, Barr 2003).

    Non-obtuse triangles give each corner its Voronoi region; an obtuse triangle gives
    half its area to the obtuse corner and a quarter to each other corner. The areas
    sum to the surface area.

    Examples
    --------
    >>> from arapkit import Mesh
    >>> m = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> round(float(voronoi_areas(m).sum()), 12)
    0.5
    """
    V, F = mesh.vertices, mesh.faces
    cots = corner_cotangents(V, F)
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    # squared length of the edge opposite each corner
    l2 = np.stack(
        [np.sum((V[F[:, (c + 2) % 3]] - V[F[:, (c + 1) % 3]]) ** 2, axis=1) for c in range(3)],
        axis=1,
    )
    contrib = np.zeros(F.shape)
    for c in range(3):
        # corner c touches the edges opposite corners c+1 and c+2
        c1, c2 = (c + 1) % 3, (c + 2) % 3
        contrib[:, c] = (l2[:, c1] * cots[:, c1] + l2[:, c2] * cots[:, c2]) / 8.0
    obtuse = cots < 0
    any_obtuse = obtuse.any(axis=1)
    contrib[any_obtuse] = np.where(obtuse[any_obtuse], 0.5, 0.25) * area[any_obtuse, None]
    return np.bincount(F.ravel(), contrib.ravel(), minlength=mesh.n_vertices)
