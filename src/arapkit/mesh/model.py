"""Triangle mesh model: validation, repairs and cached topology.

Files are read by :func:`arapkit.io.readers.load_mesh`. A :class:`Mesh` keeps the vertex
order of its source exactly (handles and rigidity maps refer to vertex indices), repairs
what it can while saying so in :attr:`Mesh.notes`, and raises
:class:`~arapkit.errors.InputError` with a one-line message for what it cannot. The number
range and scale rules are :mod:`arapkit.mesh.numbers`, the compiled edge kernels
:mod:`arapkit.mesh.topology`.
"""

from __future__ import annotations

import hashlib
import os
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..errors import InputError
from ..validate import point_positions, real_array
from .attributes import MeshAttributes
from .numbers import (
    COORDINATE_RANGE,
    bounding_box_diagonal,
    check_number_range,
    extent,
    kernel_input,
    normalised,
    scale_free_vertices,
)
from .topology import (
    EdgeTopology,
    face_edge_length_sum,
    union_root,
    unique_edges,
    vertex_adjacency,
)

# the number rules and the topology kernels lived here before: their names stay importable
# from this module (old import paths keep working)
__all__ = [
    "COORDINATE_RANGE",
    "EdgeTopology",
    "Mesh",
    "as_mesh",
    "faces_of",
    "bounding_box_diagonal",
    "check_number_range",
    "extent",
    "kernel_input",
    "scale_free_vertices",
    "union_root",
    "vertex_adjacency",
]


def _fan_triangulate(polygons: list[list[int]]) -> tuple[np.ndarray, int]:
    """Split polygons into triangle fans; return triangles and how many polygons were split."""
    tris: list[tuple[int, int, int]] = []
    split = 0
    for poly in polygons:
        if len(poly) > 3:
            split += 1
        for t in range(1, len(poly) - 1):
            tris.append((poly[0], poly[t], poly[t + 1]))
    return np.asarray(tris, dtype=np.int64).reshape(-1, 3), split



class Mesh(EdgeTopology):
    """A validated triangle mesh.

    Parameters
    ----------
    vertices : (n, 3) array_like of float
        Vertex positions. Must be finite.
    faces : (m, 3) array_like of int, or a list of polygons
        Vertex indices per face. Polygons with more than three corners are split
        into triangle fans (and :attr:`notes` says so).
    name : str, optional
        Used in messages (usually the file name).

    Notes
    -----
    Validation policy (each repair is recorded in :attr:`notes`):

    * non-finite coordinates, out-of-range indices, faces with fewer than three
      corners and meshes without faces raise :class:`InputError`;
    * polygons are fan-triangulated;
    * faces that repeat a vertex, repeated faces (same vertex set) and faces of
      zero area are dropped, because their cotangent weights are undefined;
    * vertices referenced by no face are kept and stay fixed during deformation.

    Examples
    --------
    >>> import numpy as np
    >>> m = Mesh(np.eye(3), [[0, 1, 2]], name="tri")
    >>> m.n_vertices, m.n_faces, len(m.edges)
    (3, 1, 3)
    """

    def __init__(
        self,
        vertices,
        faces,
        name: str = "mesh",
        attributes: MeshAttributes | None = None,
    ) -> None:
        self.name = str(name)
        self.notes: list[str] = []
        #: faces dropped by validation, by reason ("repeated_vertex", "zero_area", "duplicate")
        self.dropped_faces: dict[str, int] = {}
        #: what the source file carried besides positions and triangles (set by the loader)
        self.attributes = attributes
        #: for a mesh made by :func:`weld`: the input mesh and each input vertex's vertex here
        self.welded_from = None
        self.vertices = self._check_vertices(vertices)
        self.faces = self._check_faces(faces)
        self.vertices.setflags(write=False)
        self.faces.setflags(write=False)

    # -- validation -------------------------------------------------------
    def _check_vertices(self, vertices) -> np.ndarray:
        # the point sets' one rule (a cloud's points are checked alike), worded for a mesh
        return point_positions(vertices, self.name, ("vertex", "vertices"),
                               "mesh has no vertices")

    def _check_faces(self, faces) -> np.ndarray:
        n = len(self.vertices)
        if not hasattr(faces, "__len__") or isinstance(faces, (str, bytes)):
            raise InputError(f"{self.name}: faces must be an (m, 3) array or a list of polygons")
        if isinstance(faces, np.ndarray) and faces.dtype != object and faces.ndim != 2:
            raise InputError(
                f"{self.name}: faces must be an (m, 3) array or a list of polygons, "
                f"got an array of shape {faces.shape}"
            )
        if len(faces) == 0:
            raise InputError(f"{self.name}: mesh has no faces")
        if not (isinstance(faces, np.ndarray) and faces.dtype != object):
            bad = next((i for i, f in enumerate(faces)
                        if not isinstance(f, (list, tuple, np.ndarray))), None)
            if bad is not None:  # None, a number, text: not a polygon
                raise InputError(f"{self.name}: face {bad} is not a list of vertex indices")
        if not isinstance(faces, np.ndarray) and len(faces) and all(len(f) == 3 for f in faces):
            faces = np.asarray(faces)
        if isinstance(faces, np.ndarray) and faces.ndim == 2:
            polys = None
            F = faces
        else:
            polys = [list(f) for f in faces]
            lengths = {len(p) for p in polys}
            F = np.asarray(polys) if lengths <= {3} else None
        if F is None or F.shape[1] != 3:
            polys = [list(f) for f in (polys if polys is not None else F.tolist())]
            short = [i for i, p in enumerate(polys) if len(p) < 3]
            if short:
                raise InputError(
                    f"{self.name}: face {short[0]} has {len(polys[short[0]])} corners "
                    "(need at least 3)"
                )
            flat = real_array([i for p in polys for i in p], f"{self.name}: faces")
            if flat.dtype.kind == "f" and (
                    not np.isfinite(flat).all() or (flat != np.round(flat)).any()
                    or (np.abs(flat) >= 2.0**62).any()):
                raise InputError(f"{self.name}: face indices must be integers in 0..{n - 1}")
            F, split = _fan_triangulate(polys)
            if split:
                self.notes.append(
                    f"{split} polygon(s) with more than 3 corners were split into triangles"
                )
        if len(F) == 0:
            raise InputError(f"{self.name}: mesh has no faces")
        if not np.issubdtype(np.asarray(F).dtype, np.integer):
            Ff = real_array(F, f"{self.name}: faces")
            if not np.all(np.isfinite(Ff)) or np.any(Ff != np.round(Ff)):
                raise InputError(f"{self.name}: face indices must be integers")
            # beyond int64 (e.g. 1e23): out of range whatever the mesh, and no overflow
            huge = np.abs(Ff) >= 2.0**62
            if huge.any():
                f = int(np.argmax(huge.any(axis=1)))
                raise InputError(f"{self.name}: face {f} references vertex "
                                 f"{Ff[f][huge[f]][0]:.3g} but the mesh has {n} vertices")
        try:
            F = np.asarray(F, dtype=np.int64)
        except OverflowError:
            # Python ints beyond int64 (an index like 10**23): find the face to name it
            big = next(i for i, f in enumerate(np.asarray(F, dtype=object).tolist())
                       if any(abs(int(v)) >= 2**63 for v in f))
            raise InputError(
                f"{self.name}: face {big} references a vertex index too large for any "
                f"mesh (the mesh has {n} vertices)"
            ) from None
        out = np.flatnonzero(((F < 0) | (F >= n)).any(axis=1))
        if len(out):
            f = out[0]
            raise InputError(
                f"{self.name}: face {f} references vertex {F[f][(F[f] < 0) | (F[f] >= n)][0]} "
                f"but the mesh has {n} vertices (indices 0..{n - 1})"
            )
        return self._drop_degenerate(F)

    def _drop_degenerate(self, F: np.ndarray) -> np.ndarray:
        repeated_vertex = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
        V = self.vertices
        # Areas of the mesh rescaled (exactly, by powers of two) to unit size: the relative
        # threshold then means the same at 1e-300 and 1e300, and nothing overflows.
        W, _ = normalised(V)
        cross = np.cross(W[F[:, 1]] - W[F[:, 0]], W[F[:, 2]] - W[F[:, 0]])
        dbl_area = np.linalg.norm(cross, axis=1)
        scale = float(np.max(np.ptp(W, axis=0))) if len(W) > 1 else 1.0
        zero_area = (dbl_area <= 1e-14 * scale**2) & ~repeated_vertex
        key = np.sort(F, axis=1)
        order = np.lexsort((key[:, 2], key[:, 1], key[:, 0]))
        same = np.all(key[order[1:]] == key[order[:-1]], axis=1)
        duplicate = np.zeros(len(F), dtype=bool)
        # lexsort is stable: within a run of equal faces the earliest comes first and stays
        duplicate[order[1:][same]] = True
        duplicate &= ~repeated_vertex & ~zero_area
        for mask, what, key in (
            (repeated_vertex, "repeat a vertex", "repeated_vertex"),
            (zero_area, "have zero area", "zero_area"),
            (duplicate, "repeat an earlier face", "duplicate"),
        ):
            self.dropped_faces[key] = int(mask.sum())
            if mask.any():
                idx = np.flatnonzero(mask)
                self.notes.append(
                    f"dropped {len(idx)} face(s) that {what} (first: face {idx[0]})"
                )
        keep = ~(repeated_vertex | zero_area | duplicate)
        if not keep.any():
            raise InputError(f"{self.name}: every face is degenerate (zero area or repeated)")
        F = np.ascontiguousarray(F[keep])
        unref = np.setdiff1d(np.arange(len(V)), F.ravel())
        if len(unref):
            self.notes.append(
                f"{len(unref)} vertex/vertices referenced by no face (first: vertex {unref[0]}) "
                "are kept and stay fixed"
            )
        return F

    # -- cached topology ----------------------------------------------------
    @property
    def n_vertices(self) -> int:
        """Number of vertices."""
        return len(self.vertices)

    @property
    def n_faces(self) -> int:
        """Number of triangles (after repairs)."""
        return len(self.faces)

    @property
    def half_edges(self) -> np.ndarray:
        """(3m, 2) vertex pairs of the faces' edges: every face's (0, 1), then (1, 2), then
        (2, 0). An edge shared by two faces appears twice (no sorting, unlike :attr:`edges`).

        Built on each access, not kept (160 MB at 1.75M vertices; a copy of the faces).

        Examples
        --------
        >>> Mesh(np.eye(3), [[0, 1, 2]]).half_edges.tolist()
        [[0, 1], [1, 2], [2, 0]]
        """
        F = self.faces
        return np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])

    @cached_property
    def _edge_ids(self) -> tuple[np.ndarray, np.ndarray]:
        """The unique edges (sorted ``(i, j)``, i < j) and the edge id of every half edge."""
        n = self.n_vertices
        ukeys, inverse = unique_edges(np.ascontiguousarray(self.half_edges, dtype=np.int64), n)
        # the keys themselves are not kept: 40 MB at 1.75M vertices, for nothing the edges
        # do not also say
        return np.stack([ukeys // n, ukeys % n], axis=1), inverse

    @property
    def edges(self) -> np.ndarray:
        """Unique undirected edges ``(i, j)`` with ``i < j``, sorted lexicographically."""
        return self._edge_ids[0]

    @property
    def _links(self) -> np.ndarray:
        # the faces connect what their edges do, without the unique edge list (0.1 s)
        return self.faces

    @property
    def face_edges(self) -> np.ndarray:
        """(m, 3) id in :attr:`edges` of edge ``(F[f, c], F[f, c+1])`` of each face."""
        return self._edge_ids[1].reshape(3, -1).T

    @cached_property
    def edge_face_counts(self) -> np.ndarray:
        """Number of faces on each edge of :attr:`edges` (1 = boundary, >2 = non-manifold)."""
        edges, inverse = self._edge_ids
        return np.bincount(inverse, minlength=len(edges))

    @cached_property
    def unreferenced(self) -> np.ndarray:
        """Indices of vertices that no face uses."""
        used = np.zeros(self.n_vertices, dtype=bool)
        used[self.faces.ravel()] = True
        return np.flatnonzero(~used)

    @cached_property
    def boundary_loops(self) -> list[np.ndarray]:
        """Vertex sets of the boundary curves (components of the boundary-edge graph)."""
        B = self.edges[self.edge_face_counts == 1]
        if len(B) == 0:
            return []
        verts, inv = np.unique(B.ravel(), return_inverse=True)
        inv = inv.reshape(-1, 2)
        g = sp.coo_matrix((np.ones(len(B)), (inv[:, 0], inv[:, 1])), shape=(len(verts),) * 2)
        k, lab = connected_components(g, directed=False)
        return [verts[lab == c] for c in range(k)]

    @property
    def n_nonmanifold_edges(self) -> int:
        """Edges shared by more than two faces."""
        return int(np.count_nonzero(self.edge_face_counts > 2))

    @cached_property
    def mean_edge_length(self) -> float:
        """Mean length of the faces' edges: the mesh's resolution (0 without faces).

        Over :attr:`half_edges`: an edge shared by two faces counts twice, and no sorted
        edge list is built (on a closed manifold mesh this is the mean over unique edges).

        Examples
        --------
        >>> import numpy as np
        >>> round(Mesh(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), [[0, 1, 2]])
        ...       .mean_edge_length, 6)
        1.138071
        """
        if self.n_faces == 0:
            return 0.0
        # one compiled pass over the faces: NumPy's gathers of 3f edge vectors took 2.2 s at
        # 1.75M vertices, on the editor's main thread while a mesh opens
        return face_edge_length_sum(self.vertices, self.faces) / (3 * self.n_faces)

    @cached_property
    def bounding_box_diagonal(self) -> float:
        """Length of the bounding-box diagonal (the mesh's scale): :func:`bounding_box_diagonal`."""
        return bounding_box_diagonal(self.vertices)

    @cached_property
    def content_hash(self) -> str:
        """SHA-1 (hex) of the vertices (float64) and faces (int64): a key for what depends
        on the mesh's content only (a proxy). Kept: 0.15 s at 1.75M vertices, asked by the
        decimation's start and again by its collection.

        Examples
        --------
        >>> import numpy as np
        >>> a = Mesh(np.eye(3), [[0, 1, 2]])
        >>> a.content_hash == Mesh(np.eye(3), [[0, 1, 2]]).content_hash, len(a.content_hash)
        (True, 40)
        """
        h = hashlib.sha1()
        for a in (np.ascontiguousarray(self.vertices, dtype=np.float64),
                  np.ascontiguousarray(self.faces, dtype=np.int64)):
            h.update(a.tobytes())
        return h.hexdigest()

    def check_number_range(self) -> None:
        """:func:`check_number_range` on this mesh's vertices (message names the mesh)."""
        check_number_range(self.vertices, self.name)

    def __repr__(self) -> str:
        return f"Mesh({self.name!r}, {self.n_vertices} vertices, {self.n_faces} faces)"


def faces_of(value) -> object | None:
    """A mesh object's triangles: ``faces`` (arapkit, trimesh) or ``triangles`` (Open3D's
    ``TriangleMesh``); None for anything else (an array, a result).

    Examples
    --------
    >>> class Open3DLike:
    ...     triangles = [[0, 1, 2]]
    >>> faces_of(Open3DLike()), faces_of(np.eye(3))
    ([[0, 1, 2]], None)
    """
    faces = getattr(value, "faces", None)
    return getattr(value, "triangles", None) if faces is None else faces


def as_mesh(value, what: str = "mesh") -> Mesh:
    """``value`` as a :class:`Mesh`: a Mesh itself, a ``(vertices, faces)`` pair, or a
    mesh object of another library that has ``vertices`` and ``faces`` (``trimesh.Trimesh``)
    or ``triangles`` (Open3D's ``TriangleMesh``).

    The doors that take a mesh (:class:`arapkit.Deformer`, :class:`arapkit.LaplacianEditor`,
    the torch layer) call this, so a trimesh or libigl user passes what they have, and
    anything else gets a one-line :class:`~arapkit.errors.InputError` naming ``what``
    instead of an ``AttributeError`` from deep inside.

    Examples
    --------
    >>> import numpy as np
    >>> as_mesh((np.eye(3), [[0, 1, 2]])).n_faces
    1
    >>> class Other:  # e.g. a trimesh.Trimesh
    ...     vertices, faces = np.eye(3), np.array([[0, 1, 2]])
    >>> as_mesh(Other()).n_vertices
    3
    >>> as_mesh("bunny.off")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: mesh: expected an arapkit.Mesh, ... got str (load a file ...)
    """
    if isinstance(value, Mesh):
        return value
    if isinstance(value, (tuple, list)) and len(value) == 2:
        return Mesh(value[0], value[1], name=what)
    V, F = getattr(value, "vertices", None), faces_of(value)
    if V is not None and F is not None:
        return Mesh(np.asarray(V), np.asarray(F), name=what)
    hint = " (load a file with arapkit.load_mesh)" if isinstance(value, (str, os.PathLike)) else ""
    raise InputError(f"{what}: expected an arapkit.Mesh, a (vertices, faces) pair or a mesh "
                     f"with vertices and faces (trimesh.Trimesh), got {type(value).__name__}"
                     + hint)
