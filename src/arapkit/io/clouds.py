"""Reading point clouds: files without faces, with every per-point value they carry.

A PLY, OBJ or OFF file with vertices and no faces, a ``.xyz`` text file (``.xyzn`` with
normals, ``.xyzrgb`` with colours, Open3D's conventions; ``.txt`` and ``.pts`` read as
``.xyz``) and a ``.npy`` array of shape (n, 3), or (n, 6) with normals, load as a
:class:`~arapkit.mesh.cloud.PointCloud` (:func:`load_points`). Normals (PLY ``nx ny nz``,
``.xyzn``, NOFF, a ``.xyz`` whose rows are ``x y z nx ny nz``), colours and every other PLY
vertex property are kept in
the cloud's :class:`~arapkit.mesh.attributes.MeshAttributes`, so that
``save_mesh(path, result, like=cloud)`` writes them back (:mod:`arapkit.io.cloud_writer`).
:func:`load_shape` is what the doors read: a file with faces is a mesh, loaded by
:func:`~arapkit.io.readers.load_mesh` exactly as before; one without is a point cloud.

Examples
--------
>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "three.xyz"
>>> _ = p.write_text("0 0 0\\n1 0 0\\n0 1 0\\n")
>>> load_points(p)
PointCloud('three.xyz', 3 points, kNN, k = 10)
>>> q = p.with_suffix(".off")
>>> _ = q.write_text("OFF\\n3 1 0\\n0 0 0\\n1 0 0\\n0 1 0\\n3 0 1 2\\n")
>>> load_shape(q), load_shape(p).n_vertices
(Mesh('three.off', 3 vertices, 1 faces), 3)
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import InputError
from ..mesh.attributes import MeshAttributes
from ..mesh.cloud import PointCloud
from ..mesh.model import Mesh
from .arrays import load_numpy
from .cloud_writer import CLOUD_WRITE_FORMATS, cloud_format
from .formats import MESH_FORMATS, mesh_format, readable_formats
from .readers import PARTS_FORMATS, load_mesh, mesh_from_parts, read_file, read_parts

__all__ = ["CLOUD_READ_FORMATS", "XYZ_ALIASES", "XYZ_FORMATS", "check_shape_output",
           "cloud_formats_text",
           "is_cloud_file", "load_points", "load_shape", "normals_of", "shape_formats_text"]

#: the text formats of points, one row a point (Open3D's names): x y z [anything], with
#: normals, with colours
XYZ_FORMATS = ("xyz", "xyzn", "xyzrgb")
#: other names of ``.xyz`` text that scanners and the template fit's first reader used
XYZ_ALIASES = ("txt", "pts")
#: every format :func:`load_points` reads (a ``.gz`` suffix may follow the text ones),
#: besides :data:`XYZ_ALIASES`
CLOUD_READ_FORMATS = (*PARTS_FORMATS, *XYZ_FORMATS, "npy")
#: a ``.xyz`` row's numbers 4-6 are read as its normal when every row's have about unit
#: length (``x y z nx ny nz``, as CloudCompare and MeshLab write): colours or other values
#: are not unit vectors; the slack allows for normals rounded to a few decimals
_UNIT_SLACK = 0.02
#: PLY's names of a vertex normal
_NORMAL_PROPS = ("nx", "ny", "nz")


def _ext(path: str) -> str:
    name = path[:-3] if path.lower().endswith(".gz") else path
    return os.path.splitext(name)[1].lower().lstrip(".")


def is_cloud_file(path: str | os.PathLike) -> bool:
    """Whether the extension names a format only point clouds come in (xyz, npy; not the
    generic ``.txt`` / ``.pts`` that :func:`load_points` also reads as ``.xyz``).

    Examples
    --------
    >>> is_cloud_file("scan.XYZ"), is_cloud_file("scan.txt"), is_cloud_file("scan.ply")
    (True, False, False)
    """
    return _ext(os.fspath(path)) in (*XYZ_FORMATS, "npy")


def normals_of(attrs: MeshAttributes) -> np.ndarray | None:
    """The per-point normals a file carried: PLY ``nx ny nz``, the ``.xyzn`` columns or
    NOFF's, else None.

    Examples
    --------
    >>> a = MeshAttributes("ply", np.zeros(0, int), np.zeros(0, int), vertex_properties={
    ...     "nx": np.zeros(2), "ny": np.zeros(2), "nz": np.ones(2)})
    >>> normals_of(a).tolist()
    [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]
    """
    p = attrs.vertex_properties
    if all(isinstance(p.get(c), np.ndarray) for c in _NORMAL_PROPS):
        return np.stack([p[c].astype(np.float64) for c in _NORMAL_PROPS], axis=1)
    if attrs.normals is not None and attrs.source_format in ("off", "xyzn", "xyz", "npy"):
        # NOFF's, .xyzn's, a .xyz's or a .npy's with normals: one per point
        return np.asarray(attrs.normals, dtype=np.float64)
    return None


def _xyz(data: bytes, ext: str, path: str) -> tuple[np.ndarray, MeshAttributes]:
    """Rows of numbers: x y z, then (``.xyzn``) normals or (``.xyzrgb``) colours or,
    for ``.xyz``, normals where every row is ``x y z`` and a unit vector, else whatever
    else every row carries (kept verbatim)."""
    text = data.decode("utf-8", "replace")
    rows, lines = [], []
    for lineno, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if line:
            rows.append(line.replace(",", " ").split())
            lines.append(lineno)
    if not rows:
        raise InputError(f"{path}: the point cloud is empty (no rows of numbers)")
    width = {"xyzn": 6, "xyzrgb": 6}.get(ext, 3)
    short = next((i for i, r in enumerate(rows) if len(r) < width), None)
    if short is not None:
        raise InputError(f"{path}: line {lines[short]} has {len(rows[short])} numbers: a "
                         f"row of .{ext} needs {width}")
    take = min(len(r) for r in rows)
    try:
        A = np.array([r[:take] for r in rows], dtype=np.float64)
    except ValueError:
        bad = next(i for i, r in enumerate(rows) if not _numeric(r[:take]))
        raise InputError(f"{path}: line {lines[bad]}: malformed number in "
                         f"{' '.join(rows[bad])!r}") from None
    none = np.zeros(0, dtype=np.int64)
    attrs = MeshAttributes(ext, none, none)
    if ext == "xyz" and take == 6 and all(len(r) == 6 for r in rows):
        length = np.linalg.norm(A[:, 3:6], axis=1)
        if bool((np.abs(length - 1.0) <= _UNIT_SLACK).all()):
            attrs.normals = A[:, 3:6] / length[:, None]
    first = 6 if ext in ("xyzn", "xyzrgb") or attrs.normals is not None else 3
    if ext == "xyzn":  # normals, one per point (no corner table: a cloud has no corners)
        attrs.normals = A[:, 3:6].copy()
    elif ext == "xyzrgb":  # colours as PLY's: bytes where the file counts to 255
        rgb = A[:, 3:6]
        big = rgb.size and float(rgb.max()) > 1.0
        rgb = np.clip(np.round(rgb), 0, 255).astype(np.uint8) if big else rgb.copy()
        attrs.vertex_properties = {c: rgb[:, i] for i, c in enumerate(("red", "green", "blue"))}
    attrs.vertex_extra = A[:, first:].copy() if take > first else None
    if len({len(r) for r in rows}) > 1:
        attrs.lost.append("numbers after the first columns found on only some rows")
    return np.ascontiguousarray(A[:, :3]), attrs


def _numeric(tokens: list[str]) -> bool:
    try:
        [float(t) for t in tokens]
    except ValueError:
        return False
    return True


def _npy(path: str) -> tuple[np.ndarray, MeshAttributes]:
    """Positions (n, 3), or positions then normals (n, 6)."""
    A = load_numpy(path)
    if A.ndim != 2 or A.shape[1] not in (3, 6):
        raise InputError(f"{path}: a point cloud array must have shape (n, 3), or (n, 6) "
                         f"with normals, got {A.shape}")
    if A.dtype.kind not in "iuf":
        raise InputError(f"{path}: a point cloud array must hold numbers, got {A.dtype}")
    A = A.astype(np.float64)
    attrs = MeshAttributes("npy", np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
    if A.shape[1] == 6:
        attrs.normals = np.ascontiguousarray(A[:, 3:])
    return np.ascontiguousarray(A[:, :3]), attrs


def _cloud(V, attrs: MeshAttributes, name: str, neighbours, radius) -> PointCloud:
    cloud = PointCloud(V, normals_of(attrs), name=name, attributes=attrs,
                       neighbours=neighbours, radius=radius)
    if attrs.lost:
        cloud.notes.append("not kept for output: " + ", ".join(attrs.lost))
    return cloud


def _read_cloud(path: str, neighbours, radius, faces_ok: bool) -> Mesh | PointCloud:
    """A mesh (where the file has faces and ``faces_ok``) or a point cloud of ``path``."""
    ext = _ext(path)
    name = os.path.basename(path)
    if not os.path.exists(path):
        raise InputError(f"{path}: no such file")
    if os.path.isdir(path):
        what = "mesh file" if faces_ok else "point cloud file"
        raise InputError(f"{path}: is a folder, not a {what}")
    if ext == "npy":
        if path.lower().endswith(".gz"):
            raise InputError(f"{path}: a .npy array cannot be gzipped (save it as .npy)")
        V, attrs = _npy(path)
        return _cloud(V, attrs, name, neighbours, radius)
    if ext in XYZ_ALIASES:
        data, _ = read_file(path)
        V, attrs = _xyz(data, "xyz", path)
        return _cloud(V, attrs, name, neighbours, radius)
    if ext not in CLOUD_READ_FORMATS:
        if faces_ok:  # STL and unknown extensions: the mesh reader's own words
            return load_mesh(path)
        shown = f"'.{ext}'" if ext else "no extension"
        raise InputError(f"{path}: unsupported point cloud format {shown} (use "
                         + ", ".join("." + f for f in CLOUD_READ_FORMATS) + ")")
    data, ext = read_file(path)
    if ext in XYZ_FORMATS:
        V, attrs = _xyz(data, ext, path)
        return _cloud(V, attrs, name, neighbours, radius)
    V, F, attrs = read_parts(data, ext, path, faces_required=False)
    if len(F) and faces_ok:
        return mesh_from_parts(V, F, name, attrs)
    cloud = _cloud(V, attrs, name, neighbours, radius)
    if len(F):
        cloud.notes.insert(0, f"the file's {len(F)} face(s) were not used: read as points")
    return cloud


def load_points(path: str | os.PathLike, *, neighbours: int | None = None,
                radius: float | None = None) -> PointCloud:
    """Load a point cloud: the vertices of a PLY, OBJ or OFF file (its faces, if any, are
    not used), the rows of a ``.xyz`` / ``.xyzn`` / ``.xyzrgb`` file (``.txt`` and
    ``.pts`` are read as ``.xyz``, whose rows may be ``x y z nx ny nz``), or a ``.npy`` of
    shape (n, 3), or (n, 6) with normals.

    Every other per-point value the file carries (normals, colours, PLY properties of any
    name and type, numbers after x y z) is kept in ``cloud.attributes`` and written back
    by ``save_mesh(path, result, like=cloud)``; normals are also ``cloud.normals``.

    Parameters
    ----------
    path : str or path-like
        The file (text formats may be ``.gz``).
    neighbours, radius :
        The cloud's graph (:class:`~arapkit.mesh.cloud.PointCloud`): k nearest neighbours
        (default 10), or every pair closer than ``radius``.

    Returns
    -------
    PointCloud
        ``cloud.points`` (n, 3), ``cloud.normals`` (n, 3) or None, ``cloud.attributes``.

    Raises
    ------
    InputError
        A missing, unreadable, empty or malformed file, a point with NaN (one line naming
        the file).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "n.xyzn"
    >>> _ = p.write_text("0 0 0 0 0 1\\n1 0 0 0 0 1\\n")
    >>> load_points(p).normals.tolist()
    [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]
    """
    return _read_cloud(os.fspath(path), neighbours, radius, faces_ok=False)


def load_shape(path: str | os.PathLike, *, neighbours: int | None = None,
               radius: float | None = None) -> Mesh | PointCloud:
    """Load what a file holds: a mesh where it has faces (exactly
    :func:`~arapkit.io.readers.load_mesh`), else a point cloud (:func:`load_points`).

    What ``arapkit deform``, ``compare``, ``edit`` and batch jobs read. ``neighbours`` and
    ``radius`` apply to a point cloud only.
    """
    path = os.fspath(path)
    shape = _read_cloud(path, neighbours, radius, faces_ok=True)
    if isinstance(shape, Mesh) and (neighbours is not None or radius is not None):
        given = "neighbours" if neighbours is not None else "radius"
        raise InputError(f"{path}: {given} sets a point cloud's graph; this file is a "
                         "triangle mesh")
    return shape


def cloud_formats_text() -> str:
    """The point cloud formats, for help texts: ``PLY, OBJ, OFF, XYZ, XYZN, XYZRGB, NPY``.

    Examples
    --------
    >>> cloud_formats_text()
    'PLY, OBJ, OFF, XYZ, XYZN, XYZRGB, NPY'
    """
    order = ("ply", "obj", "off", *XYZ_FORMATS, "npy")
    return ", ".join(f.upper() for f in order)


def shape_formats_text() -> str:
    """What :func:`load_shape` reads, for help texts.

    Examples
    --------
    >>> shape_formats_text()
    'meshes OFF, OBJ, PLY, STL; point clouds PLY, OBJ, OFF, XYZ, XYZN, XYZRGB, NPY'
    """
    return f"meshes {readable_formats()}; point clouds {cloud_formats_text()}"


def check_shape_output(output: str | os.PathLike, shape) -> str:
    """The output format for ``shape`` (a loaded Mesh or PointCloud, or the input's file
    name before it is read), or a one-line error: a mesh is written as a mesh
    (:data:`~arapkit.io.formats.MESH_FORMATS`), a point cloud as a cloud
    (:data:`~arapkit.io.cloud_writer.CLOUD_WRITE_FORMATS`); a file name that could hold
    either allows both until it is read.

    Examples
    --------
    >>> check_shape_output("out.xyz", "scan.npy"), check_shape_output("out.ply", "x.off")
    ('xyz', 'ply')
    >>> check_shape_output("out.stl", "scan.xyz")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: out.stl: unsupported point cloud format '.stl' (use one of: ...)
    """
    if isinstance(shape, (str, os.PathLike)):
        if is_cloud_file(shape):
            return cloud_format(output)[0]
        try:
            return mesh_format(output)[0]
        except InputError:
            if _ext(os.fspath(output)) not in CLOUD_WRITE_FORMATS:
                raise InputError(f"{output}: unsupported output format (a mesh: "
                                 + ", ".join("." + f for f in MESH_FORMATS)
                                 + "; a point cloud: "
                                 + ", ".join("." + f for f in CLOUD_WRITE_FORMATS)
                                 + ")") from None
            return cloud_format(output)[0]
    if getattr(shape, "faces", 0) is None:
        return cloud_format(output)[0]
    return mesh_format(output)[0]
