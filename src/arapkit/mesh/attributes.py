"""What a mesh file carries besides positions and triangles, kept for writing it back.

The solver works on positions and triangles only. Everything else a loader finds -- the
original polygons (before fan triangulation, including faces dropped as degenerate),
OBJ texture coordinates and normals with their per-corner index tables, OBJ statements
such as ``mtllib``/``usemtl``/``g``/``o``/``s``, extra numbers on vertex lines (the
``v x y z r g b`` colour extension), and every PLY vertex and face property with its
type -- is kept in a :class:`MeshAttributes` attached to the :class:`~arapkit.Mesh` as
``mesh.attributes``. :func:`arapkit.io.writers.save_mesh` with ``like=mesh`` writes the
deformed positions together with all of it.

Examples
--------
>>> import numpy as np
>>> a = MeshAttributes(source_format="obj", face_sizes=np.array([4]),
...                    face_corners=np.array([0, 1, 2, 3]))
>>> [p.tolist() for p in a.polygons()]
[[0, 1, 2, 3]]
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["MeshAttributes", "polygon_area_vectors", "recompute_normals"]


@dataclass
class MeshAttributes:
    """Extra data of a mesh file, in the file's own order.

    Attributes
    ----------
    source_format : str
        ``"obj"``, ``"ply"``, ``"off"`` or ``"stl"``; for a point cloud also ``"xyz"``,
        ``"xyzn"``, ``"xyzrgb"`` or ``"npy"`` (no faces: ``face_sizes`` is empty).
    face_sizes : (k,) int
        Number of corners of every face of the file, in file order (faces the
        :class:`~arapkit.Mesh` dropped as degenerate included).
    face_corners : (sum(face_sizes),) int
        Vertex index of every corner, face after face.
    uv, corner_uv : (t, 2 or 3) float and (corners,) int, optional
        OBJ ``vt`` values and the ``vt`` index of each corner (-1 where a corner has
        none). A position shared by several ``vt`` (a UV seam) is one vertex for the
        solver; the table keeps the seam.
    normals, corner_normal : (q, 3) float and (corners,) int, optional
        OBJ ``vn`` values and the ``vn`` index of each corner. On output the normals are
        recomputed from the deformed shape (see :func:`recompute_normals`).
    vertex_extra : (n, e) float, optional
        Numbers after x y z on OBJ ``v`` lines or OFF vertex lines (colours, or ``w``).
    statements : list of (int, str)
        OBJ lines other than ``v``/``vt``/``vn``/``f`` (``mtllib``, ``usemtl``, ``g``,
        ``o``, ``s``, ``l`` ...), verbatim, each with the number of faces before it.
    vertex_properties, face_properties : dict of name -> array
        PLY scalar properties of the ``vertex`` element beyond x, y, z and of the
        ``face`` element beyond ``vertex_indices``, with their file types.
    off_keyword : str
        Header keyword of an OFF file (``OFF``, ``COFF`` ...).
    comments : list of str
        The ``comment`` and ``obj_info`` header lines of a PLY file, verbatim and in order
        (``comment TextureFile tex.png`` names a texture).
    lost : list of str
        What the loader could not keep (said on load, and again on save).
    """

    source_format: str
    face_sizes: np.ndarray
    face_corners: np.ndarray
    uv: np.ndarray | None = None
    corner_uv: np.ndarray | None = None
    normals: np.ndarray | None = None
    corner_normal: np.ndarray | None = None
    vertex_extra: np.ndarray | None = None
    statements: list[tuple[int, str]] = field(default_factory=list)
    vertex_properties: dict[str, np.ndarray] = field(default_factory=dict)
    face_properties: dict[str, np.ndarray] = field(default_factory=dict)
    off_keyword: str = "OFF"
    comments: list[str] = field(default_factory=list)
    lost: list[str] = field(default_factory=list)

    @property
    def n_faces(self) -> int:
        """Number of faces in the file."""
        return len(self.face_sizes)

    @property
    def face_offsets(self) -> np.ndarray:
        """(k + 1,) start of every face in :attr:`face_corners`, and the end."""
        return np.concatenate([[0], np.cumsum(self.face_sizes)]).astype(np.int64)

    def polygons(self) -> list[np.ndarray]:
        """The faces as a list of vertex-index arrays (file order)."""
        return np.split(self.face_corners, self.face_offsets[1:-1])

    @property
    def all_triangles(self) -> bool:
        """Whether every face of the file is a triangle."""
        return bool(np.all(self.face_sizes == 3))

    def colors(self) -> np.ndarray | None:
        """Per-vertex colours as floats in 0..1, (n, 3) or (n, 4), or None.

        OBJ/OFF colours are the three or four numbers after x y z (taken as 0..255 when
        any exceeds 1); PLY colours are the ``red``/``green``/``blue`` (and ``alpha``)
        properties, scaled from 0..255 when they are integers.
        """
        p = self.vertex_properties
        if all(c in p for c in ("red", "green", "blue")):
            names = ["red", "green", "blue"] + (["alpha"] if "alpha" in p else [])
            cols = np.stack([np.asarray(p[c], dtype=np.float64) for c in names], axis=1)
            return cols / 255.0 if p["red"].dtype.kind in "iu" else cols
        # OFF says by its keyword (COFF, CNOFF ...) whether the numbers are colours; the
        # numbers of a point cloud's text rows (.xyz) are not taken for colours
        off_colour = self.source_format == "obj" or (
            self.source_format == "off" and "C" in self.off_keyword[:-3])
        if off_colour and self.vertex_extra is not None and self.vertex_extra.shape[1] in (3, 4):
            # OBJ colours are 0..1; OFF files often use 0..255
            big = self.vertex_extra.size and float(np.max(self.vertex_extra)) > 1.0
            return self.vertex_extra / 255.0 if big else self.vertex_extra
        return None


def polygon_area_vectors(vertices: np.ndarray, sizes: np.ndarray, corners: np.ndarray):
    """Area vector of every polygon (normal times area), by Newell's formula.

    Exact for planar polygons and the usual choice for non-planar ones; a polygon of zero
    area gets the zero vector.

    Examples
    --------
    >>> V = np.array([[0.0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]])
    >>> polygon_area_vectors(V, np.array([4]), np.arange(4)).tolist()
    [[0.0, 0.0, 2.0]]
    """
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    face_of = np.repeat(np.arange(len(sizes)), sizes)
    # the next corner of each corner, wrapping around inside its own face
    nxt = np.arange(len(corners)) + 1
    nxt[offsets[1:] - 1] = offsets[:-1]
    P, Q = vertices[corners], vertices[corners[nxt]]
    out = np.zeros((len(sizes), 3))
    np.add.at(out, face_of, np.cross(P, Q))
    return 0.5 * out


def recompute_normals(
    vertices: np.ndarray,
    sizes: np.ndarray,
    corners: np.ndarray,
    corner_normal: np.ndarray,
    old_normals: np.ndarray,
) -> np.ndarray:
    """Normals for a deformed shape, one per original normal id (the file's layout kept).

    Normal ``j`` becomes the normalised, area-weighted sum of the faces whose corners use
    ``j``: a smooth vertex (one id around it) gets the usual area-weighted vertex normal,
    and a crease (several ids at one position, one per side) stays a crease. Ids that no
    corner uses, or whose faces have zero area, keep their old value.

    Examples
    --------
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> recompute_normals(V, np.array([3]), np.arange(3), np.zeros(3, int),
    ...                   np.array([[1.0, 0, 0]])).tolist()
    [[0.0, 0.0, 1.0]]
    """
    area = polygon_area_vectors(vertices, sizes, corners)
    face_of = np.repeat(np.arange(len(sizes)), sizes)
    acc = np.zeros((len(old_normals), 3))
    used = corner_normal >= 0
    np.add.at(acc, corner_normal[used], area[face_of[used]])
    length = np.linalg.norm(acc, axis=1)
    out = np.array(old_normals, dtype=np.float64, copy=True)
    ok = length > 0
    out[ok] = acc[ok] / length[ok, None]
    return out
