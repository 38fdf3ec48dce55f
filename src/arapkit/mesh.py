"""Triangle mesh model: loading, validation and cached topology.

A :class:`Mesh` keeps the vertex order of its source exactly (handles and rigidity
maps refer to vertex indices), repairs what it can while saying so in
:attr:`Mesh.notes`, and raises :class:`~arapkit.errors.InputError` with a one-line
message for what it cannot.
"""

from __future__ import annotations

import gzip
import io
import os
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .errors import InputError
from .validate import real_array

__all__ = ["Mesh", "load_mesh"]


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


class Mesh:
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

    def __init__(self, vertices, faces, name: str = "mesh") -> None:
        self.name = str(name)
        self.notes: list[str] = []
        #: faces dropped by validation, by reason ("repeated_vertex", "zero_area", "duplicate")
        self.dropped_faces: dict[str, int] = {}
        self.vertices = self._check_vertices(vertices)
        self.faces = self._check_faces(faces)
        self.vertices.setflags(write=False)
        self.faces.setflags(write=False)

    # -- validation -------------------------------------------------------
    def _check_vertices(self, vertices) -> np.ndarray:
        # real_array refuses text, objects and complex values (numpy would convert them)
        V = np.array(real_array(vertices, f"{self.name}: vertices"), dtype=np.float64)
        if V.ndim != 2 or V.shape[1] != 3:
            raise InputError(f"{self.name}: vertices must have shape (n, 3), got {V.shape}")
        if len(V) == 0:
            raise InputError(f"{self.name}: mesh has no vertices")
        bad = np.flatnonzero(~np.isfinite(V).all(axis=1))
        if len(bad):
            raise InputError(
                f"{self.name}: vertex {bad[0]} has a non-finite coordinate {V[bad[0]].tolist()}"
                + (f" ({len(bad)} such vertices)" if len(bad) > 1 else "")
            )
        return V

    def _check_faces(self, faces) -> np.ndarray:
        n = len(self.vertices)
        if isinstance(faces, np.ndarray) and faces.ndim != 2:
            raise InputError(f"{self.name}: faces must have shape (m, 3) or be a list of "
                             f"polygons, got an array of shape {faces.shape}")
        if not isinstance(faces, np.ndarray) and (
                isinstance(faces, (str, bytes)) or not hasattr(faces, "__len__") or any(
                    isinstance(f, (str, bytes)) or not hasattr(f, "__len__") for f in faces)):
            raise InputError(f"{self.name}: faces must be a list of vertex index lists")
        if len(faces) == 0:
            raise InputError(f"{self.name}: mesh has no faces")
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
        F = np.asarray(F, dtype=np.int64)
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
        cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
        dbl_area = np.linalg.norm(cross, axis=1)
        scale = np.max(np.ptp(V, axis=0)) if len(V) > 1 else 1.0
        zero_area = (dbl_area <= 1e-14 * max(scale, 1e-300) ** 2) & ~repeated_vertex
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

    @cached_property
    def _half_edges(self) -> np.ndarray:
        F = self.faces
        return np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])

    @cached_property
    def _edge_keys(self) -> tuple[np.ndarray, np.ndarray]:
        """Sorted unique keys ``i * n + j`` (i < j) and the edge id of every half edge."""
        he = self._half_edges
        n = np.int64(self.n_vertices)
        keys = np.minimum(he[:, 0], he[:, 1]) * n + np.maximum(he[:, 0], he[:, 1])
        ukeys, inverse = np.unique(keys, return_inverse=True)
        return ukeys, inverse

    @cached_property
    def edges(self) -> np.ndarray:
        """Unique undirected edges ``(i, j)`` with ``i < j``, sorted lexicographically."""
        ukeys = self._edge_keys[0]
        n = self.n_vertices
        return np.stack([ukeys // n, ukeys % n], axis=1)

    @property
    def face_edges(self) -> np.ndarray:
        """(m, 3) id in :attr:`edges` of edge ``(F[f, c], F[f, c+1])`` of each face."""
        return self._edge_keys[1].reshape(3, -1).T

    @cached_property
    def edge_face_counts(self) -> np.ndarray:
        """Number of faces on each edge of :attr:`edges` (1 = boundary, >2 = non-manifold)."""
        ukeys, inverse = self._edge_keys
        return np.bincount(inverse, minlength=len(ukeys))

    @cached_property
    def adjacency(self) -> sp.csr_matrix:
        """Symmetric vertex adjacency matrix (CSR, ones on edges)."""
        E = self.edges
        n = self.n_vertices
        A = sp.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n))
        return (A + A.T).tocsr()

    @cached_property
    def _components(self) -> tuple[int, np.ndarray]:
        return connected_components(self.adjacency, directed=False)

    @property
    def n_components(self) -> int:
        """Number of connected components (an unreferenced vertex is its own)."""
        return int(self._components[0])

    @property
    def component_labels(self) -> np.ndarray:
        """Connected-component label of each vertex."""
        return self._components[1]

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
    def bounding_box_diagonal(self) -> float:
        """Length of the bounding-box diagonal (the mesh's scale)."""
        return float(np.linalg.norm(np.ptp(self.vertices, axis=0)))

    def __repr__(self) -> str:
        return f"Mesh({self.name!r}, {self.n_vertices} vertices, {self.n_faces} faces)"


# -- loading ---------------------------------------------------------------------


def _read_bytes(path: str) -> tuple[bytes, str]:
    """Read a file (transparently gunzipped) and return its bytes and real extension."""
    if not os.path.exists(path):
        raise InputError(f"{path}: no such file")
    if os.path.isdir(path):
        raise InputError(f"{path}: is a folder, not a mesh file")
    name = path[:-3] if path.lower().endswith(".gz") else path
    ext = os.path.splitext(name)[1].lower().lstrip(".")
    try:
        with open(path, "rb") as fh:
            data = fh.read()
        if path.lower().endswith(".gz"):
            data = gzip.decompress(data)
    except (OSError, EOFError) as exc:
        raise InputError(f"{path}: cannot read ({exc})") from None
    return data, ext


def _uniform_block(rows: list[list[str]], kind: type) -> np.ndarray | None:
    """Rows of equal length as one array (one C-level conversion), else None."""
    if not rows:
        return None
    width = len(rows[0])
    flat = [t for row in rows for t in row]
    if len(flat) != width * len(rows) or any(len(r) != width for r in rows):
        return None
    try:
        return np.array(flat, dtype=np.float64 if kind is float else np.int64).reshape(-1, width)
    except ValueError:
        return None


def _parse_off(text: str, path: str) -> tuple[np.ndarray, list[list[int]]]:
    """Strict OFF reader: header counts are checked, so a truncated file is caught."""
    tokens_lines = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            tokens_lines.append(line.split())
    if not tokens_lines or not tokens_lines[0][0].endswith("OFF"):
        raise InputError(f"{path}: not an OFF file (missing OFF header)")
    head = tokens_lines[0][1:] or (tokens_lines[1] if len(tokens_lines) > 1 else [])
    body = tokens_lines[1:] if tokens_lines[0][1:] else tokens_lines[2:]
    try:
        nv, nf = int(head[0]), int(head[1])
    except (IndexError, ValueError):
        raise InputError(f"{path}: OFF header has no vertex/face counts") from None
    if len(body) < nv + nf:
        raise InputError(
            f"{path}: truncated: header promises {nv} vertices and {nf} faces, "
            f"file has {len(body)} data lines"
        )
    fast = _uniform_block(body[:nv], float)
    if fast is not None and fast.shape[1] >= 3:
        V = fast[:, :3]
        tri = _uniform_block(body[nv : nv + nf], int)
        if tri is not None and tri.shape[1] >= 4 and (tri[:, 0] == 3).all():
            return V, tri[:, 1:4]
    try:
        V = np.array([[float(t) for t in row[:3]] for row in body[:nv]], dtype=np.float64)
        faces = []
        for i, row in enumerate(body[nv : nv + nf]):
            k = int(row[0])
            if len(row) < k + 1:
                raise InputError(f"{path}: face {i} lists fewer than its {k} corners")
            faces.append([int(t) for t in row[1 : k + 1]])
    except ValueError as exc:
        raise InputError(f"{path}: malformed number ({exc})") from None
    if V.shape != (nv, 3):
        raise InputError(f"{path}: a vertex line has fewer than 3 coordinates")
    return V, faces


def _parse_obj(text: str, path: str) -> tuple[np.ndarray, list[list[int]]]:
    """OBJ reader that keeps vertex order (texture seams are not split)."""
    verts: list[list[float]] = []
    faces: list[list[int]] = []
    try:
        for line in text.splitlines():
            if line.startswith("v "):
                verts.append([float(t) for t in line.split()[1:4]])
            elif line.startswith("f "):
                idx = [int(t.split("/")[0]) for t in line.split()[1:]]
                n = len(verts)
                faces.append([i - 1 if i > 0 else n + i for i in idx])
    except ValueError as exc:
        raise InputError(f"{path}: malformed OBJ line ({exc})") from None
    if any(len(v) != 3 for v in verts):
        raise InputError(f"{path}: a vertex line has fewer than 3 coordinates")
    return np.asarray(verts, dtype=np.float64).reshape(-1, 3), faces


def _load_with_trimesh(data: bytes, ext: str, path: str):
    import trimesh

    try:
        m = trimesh.load(io.BytesIO(data), file_type=ext, process=False, force="mesh")
    except Exception as exc:  # trimesh raises many exception types for bad files
        raise InputError(f"{path}: cannot parse as {ext.upper()} ({exc})") from None
    if not hasattr(m, "faces") or len(m.faces) == 0:
        raise InputError(f"{path}: no triangles found")
    return np.asarray(m.vertices), np.asarray(m.faces)


def _ply_header_counts(data: bytes) -> dict[str, int]:
    head = data[: data.find(b"end_header")].decode("ascii", "replace")
    counts = {}
    for line in head.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0] == "element":
            counts[parts[1]] = int(parts[2])
    return counts


def load_mesh(path: str | os.PathLike) -> Mesh:
    """Load a mesh file (OFF, OBJ, PLY, STL; optionally ``.gz``) without reordering vertices.

    Parameters
    ----------
    path : str or path-like
        Mesh file. OFF and OBJ are parsed strictly here (a truncated file is an
        error); PLY and STL go through trimesh with processing disabled.

    Returns
    -------
    Mesh

    Raises
    ------
    InputError
        The file is missing, unreadable, truncated or invalid.

    Examples
    --------
    >>> m = load_mesh("../shared/data/meshes/plane.off")  # doctest: +SKIP
    >>> m.n_vertices
    841
    """
    path = os.fspath(path)
    data, ext = _read_bytes(path)
    name = os.path.basename(path)
    if ext in ("off", "obj"):
        text = data.decode("utf-8", "replace")
        V, F = (_parse_off if ext == "off" else _parse_obj)(text, path)
        return Mesh(V, F, name=name)
    if ext not in ("ply", "stl"):
        raise InputError(f"{path}: unsupported mesh format '.{ext}' (use OFF, OBJ, PLY or STL)")
    V, F = _load_with_trimesh(data, ext, path)
    if ext == "ply":
        counts = _ply_header_counts(data)
        if counts.get("vertex", len(V)) != len(V) or counts.get("face", 0) > len(F):
            raise InputError(
                f"{path}: truncated: header promises {counts.get('vertex')} vertices and "
                f"{counts.get('face')} faces, read {len(V)} and {len(F)}"
            )
    mesh_notes = []
    if ext == "stl":
        # STL stores every triangle with its own corners; without welding every
        # triangle would be a separate component.
        V, inv = np.unique(np.round(V, 12), axis=0, return_inverse=True)
        F = inv.reshape(-1, 3)
        mesh_notes.append("STL corners were welded into shared vertices")
    mesh = Mesh(V, F, name=name)
    mesh.notes[:0] = mesh_notes
    return mesh
