"""Writing meshes: plain positions and triangles, or everything the source file carried.

PLY, OFF and OBJ are written here with full double precision (PLY as binary little-endian,
carrying extra per-vertex properties such as ``energy`` and ``rings``); STL and GLB, which
store float32 anyway, go through trimesh. The format is chosen by the extension
(:data:`arapkit.io.formats.MESH_FORMATS`), a trailing ``.gz`` compresses any of them, and
every file is written atomically (:func:`arapkit.io.atomic.atomic_open`).

With ``like=mesh`` (a mesh whose :class:`~arapkit.mesh.attributes.MeshAttributes` the reader
kept), :func:`save_mesh` writes the deformed positions together with everything the source
carried, with one warning per kind of data the target format has no place for.

What goes where (``docs/io.md`` has the table):

* OBJ: polygons; ``vt`` and the corner -> ``vt`` table unchanged; ``vn`` recomputed from
  the deformed shape in the file's own corner -> ``vn`` layout; every other statement
  (``mtllib``, ``usemtl``, ``g``, ``o``, ``s``, ``l`` ...) verbatim at its place between
  faces; numbers after x y z on ``v`` lines (colours) verbatim; PLY colours as
  ``v x y z r g b``.
* PLY: polygons; every vertex and face property of a PLY source with its type;
  colours of an OBJ/OFF source as ``red green blue [alpha]`` uchar; the caller's
  per-vertex values (``energy``, ``rings``) after them.
* OFF: polygons; the source's OFF keyword and numbers after x y z (COFF colours).
* STL/GLB: triangles only (polygons fan-triangulated).
"""

from __future__ import annotations

import gzip
import io
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..mesh.attributes import MeshAttributes, recompute_normals
from ..mesh.model import Mesh, faces_of
from ..validate import positions_of
from .atomic import atomic_write
from .cloud_writer import save_points
from .formats import mesh_format
from .ply import ply_property_column

__all__ = ["ply_property_column", "save_mesh", "write_with_attributes"]

_PLY_NAMES = {
    "f8": "double", "f4": "float", "i4": "int", "u4": "uint", "i2": "short",
    "u2": "ushort", "i1": "char", "u1": "uchar",
    # beyond the standard, as trimesh writes them (a source file's own types, kept)
    "i8": "int64", "u8": "uint64", "f2": "float16",
}


def _num(x: float) -> str:
    """Shortest text that reads back as the same double ('0.5', not '0.50000000000000000')."""
    return repr(float(x))


def _rows(prefix: str, arr: np.ndarray) -> list[str]:
    return [prefix + " ".join(map(_num, row)) for row in np.asarray(arr, dtype=float).tolist()]


def _lost(attrs: MeshAttributes, fmt: str, keep: set[str]) -> list[str]:
    """Warnings for every kind of source data that is present and not in ``keep``."""
    have = {
        "polygons": not attrs.all_triangles,
        "uv": attrs.uv is not None,
        "normals": attrs.normals is not None,
        "statements": bool(attrs.statements),
        "colors": attrs.colors() is not None,
        "vertex_extra": attrs.vertex_extra is not None and attrs.colors() is None,
        "vertex_properties": bool(_plain_props(attrs)),
        "face_properties": bool(attrs.face_properties),
    }
    text = {
        "polygons": "polygons were split into triangles",
        "uv": "texture coordinates (vt) were not written",
        "normals": "normals (vn) were not written",
        "statements": "OBJ materials/groups ("
        + ", ".join(sorted({s.split()[0] for _, s in attrs.statements}))
        + ") were not written",
        "colors": "vertex colours were not written",
        "vertex_extra": "extra numbers on vertex lines were not written",
        "vertex_properties": "PLY vertex properties ("
        + ", ".join(_plain_props(attrs))
        + ") were not written",
        "face_properties": "PLY face properties ("
        + ", ".join(attrs.face_properties)
        + ") were not written",
    }
    out = [f"{fmt.upper()} cannot carry them: {text[k]}" for k, v in have.items()
           if v and k not in keep]
    return out + [f"not kept from the input: {what}" for what in attrs.lost]


def _plain_props(attrs: MeshAttributes) -> list[str]:
    """PLY vertex properties other than the colour channels."""
    colour = {"red", "green", "blue", "alpha"} if attrs.colors() is not None else set()
    return [k for k in attrs.vertex_properties if k not in colour]


def _obj(V: np.ndarray, attrs: MeshAttributes) -> bytes:
    lines = ["# written by arapkit"]
    stmts = sorted(attrs.statements, key=lambda s: s[0])  # stable: file order per position
    head = [s for pos, s in stmts if pos == 0]
    lines += head
    # an OBJ's own numbers verbatim; colours of other sources as 0..1 floats
    extra = attrs.vertex_extra if attrs.source_format == "obj" else attrs.colors()
    if extra is None:
        buf = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in V.tolist()]
    else:
        buf = [f"v {x:.17g} {y:.17g} {z:.17g} " + " ".join(map(_num, e))
               for (x, y, z), e in zip(V.tolist(), extra.tolist(), strict=True)]
    lines += buf
    if attrs.uv is not None:
        lines += _rows("vt ", attrs.uv)
    cn = attrs.corner_normal
    if attrs.normals is not None:
        N = recompute_normals(V, attrs.face_sizes, attrs.face_corners, cn, attrs.normals)
        lines += [f"vn {x:.17g} {y:.17g} {z:.17g}" for x, y, z in N.tolist()]
    cv = (attrs.face_corners + 1).tolist()
    cu = (attrs.corner_uv + 1).tolist() if attrs.corner_uv is not None else None
    cnl = (cn + 1).tolist() if cn is not None else None
    corner = []
    for c, v in enumerate(cv):
        t = cu[c] if cu is not None else 0
        n = cnl[c] if cnl is not None else 0
        corner.append(f"{v}/{t or ''}/{n}" if n else (f"{v}/{t}" if t else str(v)))
    rest = [(pos, s) for pos, s in stmts if pos > 0]
    r = 0
    off = attrs.face_offsets.tolist()
    for f in range(attrs.n_faces):
        while r < len(rest) and rest[r][0] == f:
            lines.append(rest[r][1])
            r += 1
        lines.append("f " + " ".join(corner[off[f] : off[f + 1]]))
    lines += [s for _, s in rest[r:]]
    return ("\n".join(lines) + "\n").encode("utf-8")


def _off(V: np.ndarray, attrs: MeshAttributes) -> bytes:
    src_off = attrs.source_format == "off"
    extra = attrs.vertex_extra if src_off else None
    keyword = attrs.off_keyword if src_off else "OFF"
    if src_off and attrs.normals is not None:
        # NOFF normals, recomputed per vertex from the deformed shape, go first
        N = recompute_normals(V, attrs.face_sizes, attrs.face_corners, attrs.corner_normal,
                              attrs.normals)
        extra = N if extra is None else np.hstack([N, extra])
    lines = [keyword, f"{len(V)} {attrs.n_faces} 0"]
    if extra is None:
        lines += [f"{x:.17g} {y:.17g} {z:.17g}" for x, y, z in V.tolist()]
    else:
        lines += [f"{x:.17g} {y:.17g} {z:.17g} " + " ".join(map(_num, e))
                  for (x, y, z), e in zip(V.tolist(), extra.tolist(), strict=True)]
    lines += [f"{len(p)} " + " ".join(map(str, p.tolist())) for p in attrs.polygons()]
    return ("\n".join(lines) + "\n").encode("ascii")


def _ply_type(dt: np.dtype) -> str:
    return _PLY_NAMES[np.dtype(dt).str[1:]]


def _ply(V: np.ndarray, attrs: MeshAttributes, props: Mapping[str, np.ndarray]) -> bytes:
    n = len(V)
    cols: dict[str, np.ndarray] = {"x": V[:, 0], "y": V[:, 1], "z": V[:, 2]}
    if attrs.source_format == "ply":
        cols.update(attrs.vertex_properties)
    else:
        rgb = attrs.colors()
        if rgb is not None:
            names = ["red", "green", "blue", "alpha"][: rgb.shape[1]]
            q = np.clip(np.round(rgb * 255.0), 0, 255).astype(np.uint8)
            cols.update({c: q[:, i] for i, c in enumerate(names)})
    for name, values in props.items():
        cols[name] = ply_property_column(name, values, n)
    vdt = [(k, np.dtype(v.dtype).newbyteorder("<").str) for k, v in cols.items()]
    vert = np.empty(n, dtype=vdt)
    for k, v in cols.items():
        vert[k] = v
    sizes = attrs.face_sizes
    big = int(sizes.max(initial=3)) > 255
    count_t = np.dtype("<i4") if big else np.dtype("u1")
    fprops = attrs.face_properties if attrs.source_format == "ply" else {}
    pdt = [(k, np.dtype(v.dtype).newbyteorder("<").str) for k, v in fprops.items()]
    header = ["ply", "format binary_little_endian 1.0", "comment written by arapkit"]
    if attrs.source_format == "ply":
        # the source's comments and obj_info (a TextureFile among them), once each
        header += [c for c in attrs.comments if c != header[2]]
    header.append(f"element vertex {n}")
    header += [f"property {_ply_type(t)} {k}" for k, t in vdt]
    header += [f"element face {attrs.n_faces}",
               f"property list {'int' if big else 'uchar'} int vertex_indices"]
    header += [f"property {_ply_type(t)} {k}" for k, t in pdt]
    header.append("end_header")
    body = _ply_faces(attrs, count_t, fprops, pdt)
    # latin-1: the source's header bytes are written back as they were read
    return ("\n".join(header) + "\n").encode("latin-1") + vert.tobytes() + body


def _ply_faces(attrs, count_t, fprops, pdt) -> bytes:
    """Face records: corner count, indices, then the face's own properties."""
    sizes = attrs.face_sizes
    if len(set(sizes.tolist())) <= 1:
        k = int(sizes[0]) if len(sizes) else 3
        rec = np.empty(len(sizes), dtype=[("k", count_t.str), ("i", "<i4", (k,)), *pdt])
        rec["k"] = k
        rec["i"] = attrs.face_corners.reshape(-1, k)
        for name, v in fprops.items():
            rec[name] = v
        return rec.tobytes()
    tail = np.empty(len(sizes), dtype=pdt) if pdt else None
    for name, v in fprops.items():
        tail[name] = v
    parts = []
    for f, poly in enumerate(attrs.polygons()):
        parts.append(np.asarray(len(poly), dtype=count_t).tobytes())
        parts.append(poly.astype("<i4").tobytes())
        if tail is not None:
            parts.append(tail[f : f + 1].tobytes())
    return b"".join(parts)


def _fan(attrs: MeshAttributes) -> np.ndarray:
    tris = []
    for p in attrs.polygons():
        tris += [(p[0], p[t], p[t + 1]) for t in range(1, len(p) - 1)]
    return np.asarray(tris, dtype=np.int64).reshape(-1, 3)


def write_with_attributes(
    fmt: str,
    V: np.ndarray,
    attrs: MeshAttributes,
    props: Mapping[str, np.ndarray],
    trimesh_bytes: Callable[[np.ndarray, np.ndarray, str], bytes] | None = None,
) -> tuple[bytes, list[str]]:
    """Bytes of ``fmt`` for positions ``V`` with ``attrs``, and the warnings.

    STL and GLB go through ``trimesh_bytes(V, triangles, fmt)`` (trimesh by default).

    Examples
    --------
    >>> a = MeshAttributes("obj", np.array([3]), np.arange(3),
    ...                    statements=[(0, "mtllib m.mtl")])
    >>> data, warn = write_with_attributes("off", np.eye(3), a, {})
    >>> warn
    ['OFF cannot carry them: OBJ materials/groups (mtllib) were not written']
    """
    if fmt == "obj":
        keep = {"polygons", "uv", "normals", "statements", "colors"}
        if attrs.source_format == "obj":
            keep.add("vertex_extra")
        return _obj(V, attrs), _lost(attrs, fmt, keep)
    if fmt == "ply":
        keep = {"polygons", "colors", "vertex_properties", "face_properties"}
        return _ply(V, attrs, props), _lost(attrs, fmt, keep)
    if fmt == "off":
        keep = {"polygons"}
        if attrs.source_format == "off":
            keep |= {"colors", "vertex_extra", "normals"}
        return _off(V, attrs), _lost(attrs, fmt, keep)
    return (trimesh_bytes or _trimesh_bytes)(V, _fan(attrs), fmt), _lost(attrs, fmt, set())


# --------------------------------------------------------------------------- plain meshes


def _ply_bytes(vertices: np.ndarray, faces: np.ndarray, props: Mapping[str, np.ndarray]) -> bytes:
    n, m = len(vertices), len(faces)
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    columns: list[np.ndarray] = [vertices[:, 0], vertices[:, 1], vertices[:, 2]]
    for name, values in props.items():
        col = ply_property_column(name, values, n)
        fields.append((name, col.dtype.newbyteorder("<").str))
        columns.append(col)
    vert = np.empty(n, dtype=fields)
    for (name, _), col in zip(fields, columns, strict=True):
        vert[name] = col
    face = np.empty(m, dtype=[("k", "u1"), ("i", "<i4", (3,))])
    face["k"] = 3
    face["i"] = faces
    header = ["ply", "format binary_little_endian 1.0", "comment written by arapkit"]
    header.append(f"element vertex {n}")
    header += [f"property {_ply_type(t)} {f}" for f, t in fields]
    header += [f"element face {m}", "property list uchar int vertex_indices", "end_header"]
    return ("\n".join(header) + "\n").encode("ascii") + vert.tobytes() + face.tobytes()


def _savetxt(fmt: str, arr: np.ndarray) -> str:
    buf = io.StringIO()
    np.savetxt(buf, arr, fmt=fmt)
    return buf.getvalue()


def _text_bytes(vertices: np.ndarray, faces: np.ndarray, fmt: str) -> bytes:
    # %.17g round-trips every double exactly; generic exporters round to fixed decimals
    if fmt == "off":
        head = f"OFF\n{len(vertices)} {len(faces)} 0\n"
        body = _savetxt("%.17g", vertices) + _savetxt("3 %d %d %d", faces)
    else:
        head = "# written by arapkit\n"
        body = _savetxt("v %.17g %.17g %.17g", vertices) + _savetxt("f %d %d %d", faces + 1)
    return (head + body).encode("ascii")


def _trimesh_bytes(vertices: np.ndarray, faces: np.ndarray, fmt: str) -> bytes:
    import trimesh

    tm = trimesh.Trimesh(vertices=vertices, faces=faces, process=False, validate=False)
    data = trimesh.exchange.export.export_mesh(tm, None, file_type=fmt)
    return data.encode("utf-8") if isinstance(data, str) else bytes(data)


def save_mesh(
    path: str | os.PathLike,
    vertices: np.ndarray,
    faces: np.ndarray | None = None,
    vertex_properties: Mapping[str, np.ndarray] | None = None,
    *,
    like: Any = None,
) -> list[str]:
    """Write a mesh atomically, in the format named by the extension.

    Parameters
    ----------
    path : path
        ``.ply``, ``.obj``, ``.off``, ``.stl`` or ``.glb``, optionally followed by ``.gz``.
    vertices : (n, 3) float, or a mesh or a solve's result
        The positions; a :class:`~arapkit.Mesh` or a ``trimesh.Trimesh`` is written whole
        (``save_mesh(path, mesh)``), a :class:`~arapkit.Result` stands for its vertices.
    faces : (m, 3) int, optional
        Triangles; not needed (and not used) when ``like`` is given.
    vertex_properties : dict of name -> (n,) array, optional
        Extra per-vertex values (``energy``, ``rings`` ...). Only PLY stores them; other
        formats drop them because they have no place for them.
    like : Mesh or PointCloud, optional
        A point cloud (or ``save_mesh(path, cloud)``) is written as one, with its normals
        turned by a :class:`~arapkit.Result`'s rotations, its colours and properties
        (:func:`arapkit.io.cloud_writer.save_points`: ``.ply``, ``.obj``, ``.off``,
        ``.xyz``, ``.xyzn``, ``.xyzrgb``, ``.npy``). A mesh: the mesh ``vertices`` belong
        to (the loaded input, or a mesh made by :func:`arapkit.mesh.welding.weld`, whose
        values are then written to the input's own vertices). Everything its file
        carried is written again: the original polygons (also faces dropped as
        degenerate), UVs with their seams, normals recomputed from ``vertices``, OBJ
        materials and groups, colours, PLY properties. See ``docs/io.md`` for what each
        format keeps.

    Returns
    -------
    list of str
        One warning line per kind of data the output format cannot carry (empty when
        nothing was lost). The CLI prints them on stderr.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.off"
    >>> save_mesh(p, np.eye(3), np.array([[0, 1, 2]]))
    []
    >>> p.read_text().splitlines()[0]
    'OFF'
    """
    cloud = like if like is not None else vertices
    if faces is None and getattr(cloud, "faces", 0) is None and hasattr(cloud, "points"):
        # a point cloud (like=cloud, or the cloud itself): its own formats and attributes
        return save_points(path, vertices, like=cloud, vertex_properties=vertex_properties)
    fmt, gz = mesh_format(path)
    if faces is None and like is None:
        # save_mesh(path, mesh): a Mesh writes what its file carried, another library's
        # mesh its triangles
        if isinstance(vertices, Mesh):
            like = vertices
        else:
            faces = faces_of(vertices)
    V = np.ascontiguousarray(positions_of(vertices), dtype=np.float64).reshape(-1, 3)
    # no file with a NaN or infinite coordinate ever leaves the library
    bad = np.flatnonzero(~np.isfinite(V).all(axis=1))
    if len(bad):
        raise InputError(
            f"{path}: not written: vertex {bad[0]} has a non-finite coordinate "
            f"({len(bad)} such vertices)"
        )
    props = dict(vertex_properties or {})
    warnings: list[str] = []
    attrs = None
    if like is not None:
        wf = getattr(like, "welded_from", None)
        if wf is not None:
            if len(V) != like.n_vertices:
                raise ValueError(f"{len(V)} vertices for a welded mesh of {like.n_vertices}")
            V = V[wf.index]
            props = {k: np.asarray(v)[wf.index] for k, v in props.items()}
            like = wf.source
        if len(V) != like.n_vertices:
            raise ValueError(f"{len(V)} vertices for a mesh of {like.n_vertices}")
        attrs = getattr(like, "attributes", None)
        if faces is None or attrs is not None:
            faces = like.faces
    if faces is None:
        raise TypeError("save_mesh needs faces or like=mesh")
    F = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    if attrs is not None:
        data, warnings = write_with_attributes(fmt, V, attrs, props)
    elif fmt == "ply":
        data = _ply_bytes(V, F, props)
    elif fmt in ("off", "obj"):
        data = _text_bytes(V, F, fmt)
    else:
        data = _trimesh_bytes(V, F, fmt)
    if gz:
        # mtime=0: identical meshes give identical files
        data = gzip.compress(data, mtime=0)
    atomic_write(path, data)
    return [f"{Path(path).name}: {w}" for w in warnings]
