"""Reading mesh files: OFF and OBJ parsed strictly here, PLY by :mod:`arapkit.io.ply`, STL
through trimesh, all without reordering vertices.

Everything a file carries besides positions and triangles is kept in ``mesh.attributes``
for :func:`arapkit.io.writers.save_mesh` ``(..., like=mesh)``. Every problem with a file is
one :class:`~arapkit.errors.InputError` line naming it.

Examples
--------
>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "tri.off"
>>> _ = p.write_text("OFF\\n3 1 0\\n0 0 0\\n1 0 0\\n0 1 0\\n3 0 1 2\\n")
>>> load_mesh(p)
Mesh('tri.off', 3 vertices, 1 faces)
"""

from __future__ import annotations

import gzip
import io
import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..mesh.attributes import MeshAttributes
from ..mesh.model import Mesh, scale_free_vertices
from .formats import READ_FORMATS, readable_formats
from .ply import PlyFile, PlyList, read_ply

__all__ = ["PARTS_FORMATS", "load_mesh", "mesh_from_parts", "read_file", "read_parts",
           "read_ply_vertex_properties"]


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


def _parse_obj(text: str, path: str, faces_required: bool = True
               ) -> tuple[np.ndarray, np.ndarray | list, MeshAttributes]:
    """OBJ reader that keeps vertex order and everything else the file says.

    Texture seams are not split: a position is one vertex whatever ``vt`` its corners
    use, and the corner -> ``vt`` / ``vn`` tables are kept in the attributes. Without
    ``faces_required`` a file of ``v`` lines only is read (a point cloud).
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
    if not sizes and faces_required:
        what = (f"only line/point elements ({elements})" if elements else "no 'f' lines")
        raise InputError(f"{path}: no faces: the file has {what}; arapkit deforms surfaces")
    if not verts:
        raise InputError(f"{path}: no vertices ('v' lines)")
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
    if not len(sizes_a):
        faces = np.zeros((0, 3), dtype=np.int64)
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


def _ply_parts(ply: PlyFile, path: str, faces_required: bool = True
               ) -> tuple[np.ndarray, np.ndarray | list, MeshAttributes]:
    """Positions, faces (file order) and attributes of a read PLY file (without
    ``faces_required``: no faces where it has no face element, or an empty one)."""
    vertex = ply.elements.get("vertex")
    vcols = dict(vertex.data) if vertex is not None else {}
    if not all(isinstance(vcols.get(c), np.ndarray) for c in "xyz"):
        raise InputError(f"{path}: PLY vertices have no x, y, z properties")
    with np.errstate(invalid="ignore"):  # a signalling NaN (refused by the Mesh, by vertex)
        V = np.stack([vcols.pop(c).astype(np.float64) for c in "xyz"], axis=1)
    face = ply.elements.get("face")
    fcols = dict(face.data) if face is not None else {}
    key = next((k for k in ("vertex_indices", "vertex_index")
                if isinstance(fcols.get(k), PlyList)), None)
    if key is None and faces_required:
        raise InputError(f"{path}: no faces (PLY has no face element with vertex_indices)")
    if key is not None and face.count == 0 and faces_required:
        raise InputError(f"{path}: no faces (the PLY face element is empty)")
    # an empty element loses nothing; one with records is not written back
    lost = [f"PLY element '{e}'" for e, el in ply.elements.items()
            if e not in ("vertex", "face") and el.count]
    if key is None:  # a point cloud: a face element without indices is not written back
        if face is not None and face.count:
            lost.append("PLY element 'face' (no vertex_indices)")
        fcols = {}
        idx = PlyList(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
    else:
        idx = fcols.pop(key)
    sizes, corners = idx.sizes.astype(np.int64), idx.values.astype(np.int64)
    if np.all(sizes == 3):  # no faces too: a (0, 3) array
        faces: np.ndarray | list = corners.reshape(-1, 3)
    else:
        # lists of Python ints: what the Mesh's polygon checks walk fastest (3x np.split's)
        flat, ends = corners.tolist(), np.cumsum(sizes).tolist()
        faces = [flat[a:b] for a, b in zip([0, *ends[:-1]], ends, strict=True)]
    vprops = {k: v for k, v in vcols.items() if isinstance(v, np.ndarray)}
    fprops = {k: v for k, v in fcols.items() if isinstance(v, np.ndarray)}
    lost += [f"PLY list property '{k}'" for k in vcols if k not in vprops]
    lost += [f"PLY face list property '{k}'" for k in fcols if k not in fprops]
    attrs = MeshAttributes("ply", sizes, corners, vertex_properties=vprops,
                           face_properties=fprops, lost=lost, comments=ply.header_notes)
    return V, faces, attrs


def load_mesh(path: str | os.PathLike) -> Mesh:
    """Load a mesh file (OFF, OBJ, PLY, STL; optionally ``.gz``) without reordering vertices.

    Everything else the file carries (polygons, UVs, normals, materials and groups,
    colours, PLY properties) is kept in ``mesh.attributes``
    (:class:`~arapkit.mesh.attributes.MeshAttributes`) for
    :func:`arapkit.io.writers.save_mesh` ``(..., like=mesh)``.

    Parameters
    ----------
    path : str or path-like
        Mesh file. OFF and OBJ are parsed strictly here (a truncated file is an
        error); PLY is read whole by :mod:`arapkit.io.ply`, STL through trimesh.

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


#: the formats :func:`read_parts` reads (a file of these may have no faces)
PARTS_FORMATS = ("off", "obj", "ply")


def read_file(path: str | os.PathLike) -> tuple[bytes, str]:
    """The bytes of a file (gunzipped for ``.gz``) and its format's extension, lower case;
    a one-line InputError for a missing, folder or unreadable file.

    Examples
    --------
    >>> read_file("no/such/file.ply")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: no/such/file.ply: no such file
    """
    return _read_bytes(os.fspath(path))


def read_parts(data: bytes, ext: str, path: str, faces_required: bool = True
               ) -> tuple[np.ndarray, np.ndarray | list, MeshAttributes]:
    """Positions, faces (file order; (0, 3) where there are none and ``faces_required`` is
    False) and attributes of an OFF, OBJ or PLY file's bytes, unchecked by :class:`Mesh`.

    Examples
    --------
    >>> V, F, a = read_parts(b"OFF\\n2 0 0\\n0 0 0\\n1 0 0\\n", "off", "two.off", False)
    >>> V.shape, len(F), a.source_format
    ((2, 3), 0, 'off')
    """
    try:
        if ext == "ply":
            return _ply_parts(read_ply(data, path), path, faces_required)
        text = data.decode("utf-8", "replace")
        if ext == "off":
            V, F, attrs = _parse_off(text, path)
            if faces_required and not len(F):
                raise InputError(f"{path}: mesh has no faces")
            return V, (F if len(F) else np.zeros((0, 3), dtype=np.int64)), attrs
        return _parse_obj(text, path, faces_required)
    except InputError:
        raise
    except (ValueError, IndexError, KeyError, EOFError, UnicodeDecodeError, OverflowError) as e:
        raise InputError(f"{path}: cannot read ({type(e).__name__}: {e})") from None


def mesh_from_parts(V, F, name: str, attrs: MeshAttributes) -> Mesh:
    """The :class:`Mesh` :func:`load_mesh` makes of a file's parts (notes included)."""
    return _mesh_with_attributes(V, F, name, attrs)


def _parse_mesh(data: bytes, ext: str, path: str) -> Mesh:
    """The mesh in ``data`` (the bytes of ``path``, format ``ext``)."""
    name = os.path.basename(path)
    if ext in ("off", "obj"):
        text = data.decode("utf-8", "replace")
        V, F, attrs = (_parse_off if ext == "off" else _parse_obj)(text, path)
        return _mesh_with_attributes(V, F, name, attrs)
    if ext not in READ_FORMATS:
        raise InputError(
            f"{path}: unsupported mesh format '.{ext}' (use {readable_formats(' or ')})"
        )
    if ext == "ply":
        V, F, attrs = _ply_parts(read_ply(data, path), path)
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


def read_ply_vertex_properties(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """All scalar vertex properties of a PLY file (ASCII or binary, optionally ``.gz``).

    Returns
    -------
    dict of name -> (n,) array, including ``x``, ``y``, ``z``.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.ply"
    >>> from arapkit.io.writers import save_mesh
    >>> save_mesh(p, np.eye(3), np.array([[0, 1, 2]]), {"energy": np.array([0.5, 1, 2])})
    []
    >>> read_ply_vertex_properties(p)["energy"].tolist()
    [0.5, 1.0, 2.0]
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
        if path.name.lower().endswith(".gz"):
            raw = gzip.decompress(raw)
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except (OSError, EOFError) as e:
        raise InputError(f"{path}: cannot read ({e})") from None
    vertex = read_ply(raw, str(path)).elements.get("vertex")
    if vertex is None:
        raise InputError(f"{path}: PLY file has no vertex element")
    return {k: v for k, v in vertex.data.items() if isinstance(v, np.ndarray)}
