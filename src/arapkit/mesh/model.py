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

from ..errors import InputError
from ..validate import real_array
from .attributes import MeshAttributes

__all__ = [
    "COORDINATE_RANGE",
    "Mesh",
    "check_number_range",
    "load_mesh",
    "scale_free_vertices",
    "weld",
]

#: Coordinates (and the mesh's extent) inside ``[1/COORDINATE_RANGE, COORDINATE_RANGE]``
#: keep every squared length and area of the solver a normal double.
COORDINATE_RANGE = 1e150


def check_number_range(vertices: np.ndarray, name: str = "mesh") -> None:
    """Refuse coordinates whose squares would overflow or underflow a double.

    Loading and validation work at any finite scale (they normalise first), but the
    solver squares lengths: a coordinate beyond ``COORDINATE_RANGE`` (1e150) in size, or
    a mesh smaller than its inverse, is outside the numbers it can represent.

    Raises
    ------
    InputError
        Naming ``name``, the size found and the range.

    Examples
    --------
    >>> check_number_range(np.array([[0.0, 0, 0], [1e200, 0, 0]]), "big.off")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: big.off: coordinates reach 1e+200, beyond the number range ...
    """
    V = np.asarray(vertices, dtype=np.float64)
    big = float(np.max(np.abs(V))) if V.size else 0.0
    extent = float(np.max(_extent(V))) if V.size else 0.0
    lo, hi = 1.0 / COORDINATE_RANGE, COORDINATE_RANGE
    rng = f"(sizes from {lo:.0e} to {hi:.0e}; squared lengths overflow above about 1e154)"
    if big > hi:
        raise InputError(
            f"{name}: coordinates reach {big:.3g}, beyond the number range arapkit "
            f"computes in {rng}; rescale the mesh"
        )
    if 0 < extent < lo:
        raise InputError(
            f"{name}: the mesh is only {extent:.3g} across, below the number range arapkit "
            f"computes in {rng}; rescale the mesh"
        )


def _extent(V: np.ndarray) -> np.ndarray:
    """Per-axis extent computed without overflow (ptp of ±1e308 is inf)."""
    if len(V) == 0:
        return np.zeros(3)
    hi, lo = V.max(axis=0), V.min(axis=0)
    return 2.0 * (0.5 * hi - 0.5 * lo)


def scale_free_vertices(vertices: np.ndarray) -> np.ndarray:
    """The vertices moved and rescaled by powers of two to about unit size.

    Angles, cotangents and relative tolerances are the same as the input's, and no
    squared quantity over- or underflows, whatever the input's units.

    Examples
    --------
    >>> scale_free_vertices(np.array([[0.0, 0, 0], [3e200, 0, 0]])).tolist()
    [[0.0, 0.0, 0.0], [0.9798151324726952, 0.0, 0.0]]
    """
    return _normalised(np.asarray(vertices, dtype=np.float64))[0]


def _normalised(V: np.ndarray) -> tuple[np.ndarray, float]:
    """Coordinates rescaled by powers of two (exact) to about unit size, and the factor.

    The translation to the minimum corner keeps far-from-origin meshes accurate; all
    squared quantities of the result lie near 1, so no tolerance over- or underflows.
    """
    big = float(np.max(np.abs(V))) if V.size else 0.0
    if big == 0.0:
        return np.zeros_like(V), 1.0
    e1 = np.frexp(big)[1]
    W = np.ldexp(V, -e1)
    W = W - W.min(axis=0)
    ext = float(np.max(W))
    if ext == 0.0:
        return W, 1.0
    e2 = np.frexp(ext)[1]
    return np.ldexp(W, -e2), float(np.ldexp(1.0, e1 + e2))


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


class EdgeTopology:
    """Vertex adjacency and connected components of anything with ``n_vertices`` and
    ``edges`` (a :class:`Mesh`, or the solver's :class:`arapkit.arap.problem.EdgeGraph`).

    Examples
    --------
    >>> Mesh(np.eye(3), [[0, 1, 2]]).n_components
    1
    """

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
        """Number of connected components (an isolated vertex is its own)."""
        return int(self._components[0])

    @property
    def component_labels(self) -> np.ndarray:
        """Connected-component label of each vertex."""
        return self._components[1]


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
        # one rule for every entry point: text, objects, complex numbers and booleans are
        # refused (numpy would parse strings and drop imaginary parts without a word)
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
        if not hasattr(faces, "__len__") or isinstance(faces, (str, bytes)):
            raise InputError(f"{self.name}: faces must be an (m, 3) array or a list of polygons")
        if isinstance(faces, np.ndarray) and faces.dtype != object and faces.ndim != 2:
            raise InputError(
                f"{self.name}: faces must be an (m, 3) array or a list of polygons, "
                f"got an array of shape {faces.shape}"
            )
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
        W, _ = _normalised(V)
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
        """Length of the bounding-box diagonal (the mesh's scale), computed without overflow."""
        W, factor = _normalised(self.vertices)
        return float(np.linalg.norm(np.ptp(W, axis=0))) * factor

    def check_number_range(self) -> None:
        """:func:`check_number_range` on this mesh's vertices (message names the mesh)."""
        check_number_range(self.vertices, self.name)

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
    except (ValueError, OverflowError):  # the slow path names the line at fault
        return None


def _parse_off(text: str, path: str) -> tuple[np.ndarray, np.ndarray | list, MeshAttributes]:
    """Strict OFF reader: header counts are checked, so a truncated file is caught.

    Numbers after x y z on vertex lines (COFF colours) are kept in the attributes.
    """
    rows: list[tuple[int, list[str]]] = []
    for lineno, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if line:
            rows.append((lineno, line.split()))
    if not rows or not rows[0][1][0].endswith("OFF"):
        raise InputError(f"{path}: not an OFF file (missing OFF header)")
    keyword = rows[0][1][0]
    head = rows[0][1][1:] or (rows[1][1] if len(rows) > 1 else [])
    body = rows[1:] if rows[0][1][1:] else rows[2:]
    try:
        nv, nf = int(head[0]), int(head[1])
    except (IndexError, ValueError):
        raise InputError(f"{path}: OFF header has no vertex/face counts") from None
    if nv < 0 or nf < 0:
        raise InputError(
            f"{path}: OFF header has a negative count ({nv} vertices, {nf} faces)"
        )
    if len(body) < nv + nf:
        raise InputError(
            f"{path}: truncated: header promises {nv} vertices and {nf} faces, "
            f"file has {len(body)} data lines"
        )
    vrows, frows = body[:nv], body[nv : nv + nf]
    short = next(((ln, t) for ln, t in vrows if len(t) < 3), None)
    if short is not None:
        raise InputError(
            f"{path}: line {short[0]}: a vertex needs 3 coordinates, found {len(short[1])}"
        )
    V = _uniform_block([t for _, t in vrows], float)
    if V is None:
        V = _number_rows(vrows, path, width=3)
    extra = V[:, 3:] if V.shape[1] > 3 else None
    V = np.ascontiguousarray(V[:, :3])
    tri = _uniform_block([t for _, t in frows], int)
    if tri is not None and tri.shape[1] >= 4 and (tri[:, 0] == 3).all():
        sizes = np.full(len(tri), 3, dtype=np.int64)
        faces: np.ndarray | list = tri[:, 1:4]
        corners = tri[:, 1:4].ravel()
    else:
        polys = []
        for i, (ln, row) in enumerate(frows):
            try:
                k = int(row[0])
                idx = [int(t) for t in row[1 : k + 1]]
            except ValueError:
                raise InputError(f"{path}: line {ln}: face {i}: malformed number") from None
            if k < 0:
                raise InputError(f"{path}: line {ln}: face {i} has a negative corner count")
            if len(idx) < k:
                raise InputError(f"{path}: line {ln}: face {i} lists fewer than its {k} corners")
            polys.append(idx)
        faces = polys
        sizes = np.array([len(p) for p in polys], dtype=np.int64)
        corners = _corner_array(polys, path)
    attrs = MeshAttributes("off", sizes, corners, vertex_extra=extra, off_keyword=keyword)
    if len({len(t) for _, t in vrows}) > 1:
        attrs.lost.append("numbers after x y z found on only some vertex lines")
    if "N" in keyword[:-3] and extra is not None and extra.shape[1] >= 3:
        # NOFF: per-vertex normals come first after x y z; keep them as normals (one per
        # vertex) so that they are recomputed on output instead of copied stale
        attrs.normals, attrs.corner_normal = extra[:, :3], corners.copy()
        attrs.vertex_extra = extra[:, 3:] if extra.shape[1] > 3 else None
    return V, faces, attrs


def _number_rows(rows: list[tuple[int, list[str]]], path: str, width: int) -> np.ndarray:
    """Rows of numbers (first ``width`` of each, plus extras when every row has them)."""
    lengths = {len(t) for _, t in rows}
    take = min(lengths) if rows else width
    out = np.empty((len(rows), take))
    for r, (ln, toks) in enumerate(rows):
        try:
            out[r] = [float(t) for t in toks[:take]]
        except ValueError:
            raise InputError(f"{path}: line {ln}: malformed number in {' '.join(toks)!r}") from None
    return out


def _corner_array(polys: list[list[int]], path: str) -> np.ndarray:
    """Flat int64 corner array; an index beyond int64 is named instead of overflowing."""
    try:
        return np.fromiter((v for p in polys for v in p), dtype=np.int64)
    except OverflowError:
        f = next(i for i, p in enumerate(polys) if any(abs(v) >= 2**63 for v in p))
        raise InputError(
            f"{path}: face {f} references a vertex index too large for any mesh"
        ) from None


# OBJ statements whose indices refer to vertices; they are kept verbatim, which is right
# because the vertex order never changes.
_OBJ_GEOMETRY = {"v", "vt", "vn", "f", "vp"}


def _obj_index(tok: str, count: int, what: str, path: str, lineno: int) -> int:
    """0-based index of an OBJ reference (1-based, or negative = relative to the end)."""
    try:
        i = int(tok)
    except ValueError:
        raise InputError(f"{path}: line {lineno}: malformed {what} index {tok!r}") from None
    if i == 0:
        raise InputError(f"{path}: line {lineno}: {what} index 0 (OBJ indices start at 1)")
    if i < 0:
        if -i > count:
            raise InputError(
                f"{path}: line {lineno}: relative {what} index {i} reaches before the first "
                f"{what} ({count} defined so far)"
            )
        return count + i
    if i > 2**62:
        raise InputError(f"{path}: line {lineno}: {what} index {tok} is too large")
    return i - 1


def _parse_obj(text: str, path: str) -> tuple[np.ndarray, np.ndarray | list, MeshAttributes]:
    """OBJ reader that keeps vertex order and everything else the file says.

    Texture seams are not split: a position is one vertex whatever ``vt`` its corners
    use, and the corner -> ``vt`` / ``vn`` tables are kept in the attributes.
    """
    verts: list[list[str]] = []
    vlines: list[int] = []
    uvs: list[list[float]] = []
    nrms: list[list[float]] = []
    sizes: list[int] = []
    corners: list[int] = []
    cuv: list[int] = []
    cnrm: list[int] = []
    face_lines: list[int] = []
    statements: list[tuple[int, str]] = []
    elements = 0  # l / p statements: curves and points, which arapkit does not deform
    for lineno, raw in enumerate(text.splitlines(), 1):
        toks = raw.split()
        if not toks or toks[0].startswith("#"):
            continue
        key = toks[0]
        if key == "v":
            verts.append(toks[1:])
            vlines.append(lineno)
        elif key == "f":
            if len(toks) < 4:
                raise InputError(
                    f"{path}: line {lineno}: face {len(sizes)} has {len(toks) - 1} corners "
                    "(need at least 3)"
                )
            for t in toks[1:]:
                parts = t.split("/")
                corners.append(_obj_index(parts[0], len(verts), "vertex", path, lineno))
                has_uv = len(parts) > 1 and parts[1] != ""
                has_n = len(parts) > 2 and parts[2] != ""
                cuv.append(_obj_index(parts[1], len(uvs), "texture", path, lineno)
                           if has_uv else -1)
                cnrm.append(_obj_index(parts[2], len(nrms), "normal", path, lineno)
                            if has_n else -1)
            sizes.append(len(toks) - 1)
            face_lines.append(lineno)
        elif key == "vt" or key == "vn":
            try:
                vals = [float(t) for t in toks[1:]]
            except ValueError:
                raise InputError(f"{path}: line {lineno}: malformed number in {key!r}") from None
            (uvs if key == "vt" else nrms).append(vals)
        elif key not in _OBJ_GEOMETRY:
            elements += key in ("l", "p")
            statements.append((len(sizes), raw.strip()))
    if not sizes:
        what = (f"only line/point elements ({elements})" if elements else "no 'f' lines")
        raise InputError(f"{path}: no faces: the file has {what}; arapkit deforms surfaces")
    C = np.asarray(corners, dtype=np.int64)
    bad = np.flatnonzero(C >= len(verts))
    if len(bad):
        f = int(np.searchsorted(np.cumsum(sizes), bad[0], side="right"))
        ln = face_lines[f]
        tok = text.splitlines()[ln - 1].split()[1 + bad[0] - int(np.sum(sizes[:f]))]
        raise InputError(
            f"{path}: line {ln}: face {f} references vertex {tok.split('/')[0]} but the file "
            f"defines {len(verts)} vertices"
        )
    V = _obj_vertices(verts, vlines, path)
    extra = V[:, 3:] if V.shape[1] > 3 else None
    if len({len(t) for t in verts}) > 1:
        lost = ["numbers after x y z found on only some 'v' lines"]
    else:
        lost = []
    attrs = MeshAttributes(
        "obj",
        np.asarray(sizes, dtype=np.int64),
        C,
        vertex_extra=extra,
        statements=statements,
        lost=lost,
    )
    for vals, idx, key in ((uvs, cuv, "vt"), (nrms, cnrm, "vn")):
        ix = np.asarray(idx, dtype=np.int64)
        if not np.any(ix >= 0):
            continue
        if ix.max() >= len(vals):
            f = int(np.searchsorted(np.cumsum(sizes), np.flatnonzero(ix >= len(vals))[0],
                                    "right"))
            raise InputError(
                f"{path}: line {face_lines[f]}: face {f} references a '{key}' index beyond the "
                f"{len(vals)} defined"
            )
        if len({len(v) for v in vals}) != 1:
            attrs.lost.append(f"'{key}' lines of unequal length")
            continue
        arr = np.asarray(vals, dtype=np.float64)
        if key == "vt":
            attrs.uv, attrs.corner_uv = arr, ix
        else:
            attrs.normals, attrs.corner_normal = arr, ix
    sizes_a = attrs.face_sizes
    faces = C.reshape(-1, 3) if np.all(sizes_a == 3) else attrs.polygons()
    return np.ascontiguousarray(V[:, :3]), faces, attrs


def _obj_vertices(verts: list[list[str]], vlines: list[int], path: str) -> np.ndarray:
    """Vertex rows as floats: x y z, plus the extra numbers when every line has as many."""
    if not verts:
        return np.zeros((0, 3))
    short = next((i for i, t in enumerate(verts) if len(t) < 3), None)
    if short is not None:
        raise InputError(
            f"{path}: line {vlines[short]}: vertex {short + 1} needs 3 coordinates, "
            f"found {len(verts[short])}"
        )
    fast = _uniform_block(verts, float)
    if fast is not None:
        return fast
    return _number_rows(list(zip(vlines, verts, strict=True)), path, width=3)


def _load_with_trimesh(data: bytes, ext: str, path: str):
    import trimesh

    try:
        m = trimesh.load(io.BytesIO(data), file_type=ext, process=False, force="mesh")
    except Exception as exc:  # trimesh raises many exception types for bad files
        raise InputError(f"{path}: cannot parse as {ext.upper()} ({exc})") from None
    if not hasattr(m, "faces") or len(m.faces) == 0:
        raise InputError(f"{path}: no triangles found")
    return m


def _ply_header_counts(data: bytes, path: str) -> dict[str, int]:
    head = data[: data.find(b"end_header")].decode("ascii", "replace")
    counts = {}
    for line in head.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0] == "element":
            try:
                counts[parts[1]] = int(parts[2])
            except ValueError:
                raise InputError(
                    f"{path}: PLY header: element {parts[1]!r} has count {parts[2]!r}, "
                    "not a whole number"
                ) from None
    return counts


def _ply_columns(element: dict) -> dict[str, np.ndarray]:
    """Columns of a trimesh ``_ply_raw`` element, each with its file type."""
    data, types = element.get("data"), element.get("properties", {})
    if data is None:
        return {}
    names = data.dtype.names if hasattr(data, "dtype") else list(data)
    out = {}
    for name in names or ():
        col = np.asarray(data[name])
        if col.dtype.names:
            # a fixed-length list in a binary file: (count, values) records
            col = np.asarray(col[col.dtype.names[-1]])
        elif col.ndim == 2 and col.shape[1] == 1:
            col = col[:, 0]
        t = types.get(name)
        if col.dtype != object and col.ndim == 1 and t is not None:
            try:
                col = col.astype(np.dtype(t).newbyteorder("="))
            except TypeError:  # a list type string: keep what trimesh read
                pass
        out[name] = col
    return out


def _lists_consistent(raw: dict) -> bool:
    """Whether every fixed-length list trimesh read has the length each record declares.

    trimesh reads binary lists with the first record's length for all of them; a file
    mixing triangles and quads whose total happens to fit is then read as garbage.
    """
    for element in raw.values():
        data = element.get("data")
        if not hasattr(data, "dtype") or data.dtype.names is None:
            continue
        for name in data.dtype.names:
            col = data[name]
            if col.dtype.names and len(col.dtype.names) == 2:
                count, values = col[col.dtype.names[0]], col[col.dtype.names[1]]
                width = values.shape[-1] if values.ndim > 1 else 1
                if np.any(np.asarray(count).ravel() != width):
                    return False
    return True


def _read_ply(data: bytes, path: str) -> dict:
    """Raw PLY elements as ``{name: {"data": columns, "properties": {name: dtype}}}``.

    trimesh reads uniform files fast; a binary file mixing polygon sizes is beyond its
    reader, so plyfile (which reads any valid PLY) takes over then.
    """
    try:
        m = _load_with_trimesh(data, "ply", path)
        raw = getattr(m, "metadata", {}).get("_ply_raw")
        if raw and _lists_consistent(raw):
            return raw
        first_error = f"{path}: cannot parse as PLY"
    except InputError as exc:
        first_error = str(exc)
    try:
        from plyfile import PlyData

        ply = PlyData.read(io.BytesIO(data))
    except Exception:  # plyfile raises several types for malformed files
        raise InputError(first_error) from None
    out = {}
    for el in ply.elements:
        cols = {p.name: el[p.name] for p in el.properties}
        types = {p.name: (p.val_dtype if not hasattr(p, "len_dtype") else "$LIST")
                 for p in el.properties}
        out[el.name] = {"data": cols, "properties": types, "length": len(el.data)}
    return out


def _ply_parts(raw: dict, path: str) -> tuple[np.ndarray, np.ndarray | list, MeshAttributes]:
    """Positions, faces (file order) and attributes from raw PLY elements."""
    vcols = _ply_columns(raw.get("vertex", {}))
    fcols = _ply_columns(raw.get("face", {}))
    if not all(c in vcols for c in "xyz"):
        raise InputError(f"{path}: PLY vertices have no x, y, z properties")
    V = np.stack([vcols.pop(c).astype(np.float64) for c in "xyz"], axis=1)
    key = next((k for k in ("vertex_indices", "vertex_index") if k in fcols), None)
    lost = [f"PLY element '{e}'" for e in raw if e not in ("vertex", "face")]
    if key is None:
        raise InputError(f"{path}: no faces (PLY has no face element with vertex_indices)")
    idx = fcols.pop(key)
    if idx.dtype != object and idx.ndim == 2:
        sizes = np.full(len(idx), idx.shape[1], dtype=np.int64)
        corners = idx.astype(np.int64).ravel()
    else:
        polys = [np.asarray(p, dtype=np.int64) for p in idx]
        sizes = np.array([len(p) for p in polys], dtype=np.int64)
        corners = np.concatenate(polys) if polys else np.zeros(0, np.int64)
    faces = (corners.reshape(-1, 3) if np.all(sizes == 3)
             else np.split(corners, np.cumsum(sizes)[:-1]))
    vprops = {k: v for k, v in vcols.items() if v.ndim == 1 and v.dtype != object}
    fprops = {k: v for k, v in fcols.items() if v.ndim == 1 and v.dtype != object}
    lost += [f"PLY list property '{k}'" for k in vcols if k not in vprops]
    lost += [f"PLY face list property '{k}'" for k in fcols if k not in fprops]
    attrs = MeshAttributes("ply", sizes, corners, vertex_properties=vprops,
                           face_properties=fprops, lost=lost)
    return V, faces, attrs


def load_mesh(path: str | os.PathLike) -> Mesh:
    """Load a mesh file (OFF, OBJ, PLY, STL; optionally ``.gz``) without reordering vertices.

    Everything else the file carries (polygons, UVs, normals, materials and groups,
    colours, PLY properties) is kept in ``mesh.attributes``
    (:class:`~arapkit.mesh.attributes.MeshAttributes`) for
    :func:`arapkit.io.fileio.save_mesh` ``(..., like=mesh)``.

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
        The file is missing, unreadable, truncated or invalid (never another exception
        for a bad file).

    Examples
    --------
    >>> m = load_mesh("../shared/data/meshes/plane.off")  # doctest: +SKIP
    >>> m.n_vertices  # doctest: +SKIP
    841
    """
    path = os.fspath(path)
    data, ext = _read_bytes(path)
    try:
        return _parse_mesh(data, ext, path)
    except InputError:
        raise
    except (ValueError, IndexError, KeyError, EOFError, UnicodeDecodeError, OverflowError) as e:
        # a parser tripping over a malformed file means the file is bad, not arapkit
        raise InputError(f"{path}: cannot read mesh ({type(e).__name__}: {e})") from None


def _parse_mesh(data: bytes, ext: str, path: str) -> Mesh:
    """The mesh in ``data`` (the bytes of ``path``, format ``ext``)."""
    name = os.path.basename(path)
    if ext in ("off", "obj"):
        text = data.decode("utf-8", "replace")
        V, F, attrs = (_parse_off if ext == "off" else _parse_obj)(text, path)
        return _mesh_with_attributes(V, F, name, attrs)
    if ext not in ("ply", "stl"):
        raise InputError(f"{path}: unsupported mesh format '.{ext}' (use OFF, OBJ, PLY or STL)")
    if ext == "ply":
        V, F, attrs = _ply_parts(_read_ply(data, path), path)
        counts = _ply_header_counts(data, path)
        if counts.get("vertex", len(V)) != len(V) or counts.get("face", 0) > attrs.n_faces:
            raise InputError(
                f"{path}: truncated: header promises {counts.get('vertex')} vertices and "
                f"{counts.get('face')} faces, read {len(V)} and {attrs.n_faces}"
            )
        return _mesh_with_attributes(V, F, name, attrs)
    m = _load_with_trimesh(data, ext, path)
    # STL stores every triangle with its own corners; without welding every triangle
    # would be a separate component.
    # Corners equal to 12 digits relative to the mesh's size are one vertex (an absolute
    # rounding would merge a whole millimetre-scale part at 1e-13 m).
    V = np.asarray(m.vertices, dtype=np.float64)
    _, first, inv = np.unique(np.round(scale_free_vertices(V), 12), axis=0,
                              return_index=True, return_inverse=True)
    V, F = V[first], inv.reshape(-1, 3)
    mesh = _mesh_with_attributes(V, F, name, MeshAttributes("stl", np.full(len(F), 3), F.ravel()))
    mesh.notes.insert(0, "STL corners were welded into shared vertices")
    return mesh


def _mesh_with_attributes(V, F, name: str, attrs: MeshAttributes) -> Mesh:
    mesh = Mesh(V, F, name=name, attributes=attrs)
    if attrs.lost:
        mesh.notes.append("not kept for output: " + ", ".join(attrs.lost))
    return mesh


def weld(mesh: Mesh, tol: float | None = None) -> Mesh:
    """Merge coincident vertices; see :func:`arapkit.mesh.welding.weld` (the same function)."""
    from .welding import weld as _weld

    return _weld(mesh, tol)
