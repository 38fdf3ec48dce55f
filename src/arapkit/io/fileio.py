"""Writing meshes, reports and other outputs safely; reading numpy array files.

Every writer here is atomic: it writes a temporary file in the destination folder and
then ``os.replace``-s it over the target, so a crash or Ctrl-C never leaves a half-written
output (and an existing file is either untouched or fully replaced).

PLY, OFF and OBJ are written by this module with full double precision (PLY as binary
little-endian, carrying extra per-vertex properties such as ``energy`` and ``rings``);
STL and GLB, which store float32 anyway, go through trimesh. The format is chosen by the
extension, and a trailing ``.gz`` compresses any of them.

Examples
--------
>>> import tempfile, pathlib, numpy as np
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]); F = np.array([[0, 1, 2]])
>>> save_mesh(d / "t.ply", V, F, vertex_properties={"rings": np.array([1, 2, 3])})
[]
>>> read_ply_vertex_properties(d / "t.ply")["rings"].tolist()
[1, 2, 3]
"""

from __future__ import annotations

import contextlib
import gzip
import io
import json
import math
import os
import tempfile
import zipfile
import zlib
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

from arapkit.errors import InputError

__all__ = [
    "MESH_FORMATS",
    "atomic_open",
    "atomic_write",
    "FIGURE_FORMATS",
    "check_figure_format",
    "check_output_path",
    "load_numpy",
    "mesh_format",
    "read_ply_vertex_properties",
    "save_mesh",
    "to_jsonable",
    "write_json",
]

#: Output mesh formats, by extension (a ``.gz`` suffix may follow any of them).
MESH_FORMATS = ("ply", "obj", "off", "stl", "glb")
#: Figure formats every figure writer accepts (matplotlib writes them all).
FIGURE_FORMATS = ("png", "pdf", "svg", "jpg", "jpeg")


def check_figure_format(path: str | os.PathLike) -> str:
    """The figure format named by ``path``'s extension, or a one-line error.

    Examples
    --------
    >>> check_figure_format("fig.PDF")
    'pdf'
    """
    fmt = Path(path).suffix.lower().lstrip(".")
    if fmt not in FIGURE_FORMATS:
        raise InputError(f"{path}: unsupported figure format '.{fmt}' (use "
                         + ", ".join("." + f for f in FIGURE_FORMATS[:-1])
                         + f" or .{FIGURE_FORMATS[-1]})")
    return fmt

_PLY_TYPES = {
    np.dtype(np.float64): "double",
    np.dtype(np.float32): "float",
    np.dtype(np.int32): "int",
    np.dtype(np.uint32): "uint",
    np.dtype(np.int16): "short",
    np.dtype(np.uint16): "ushort",
    np.dtype(np.int8): "char",
    np.dtype(np.uint8): "uchar",
}


# --------------------------------------------------------------------------- atomic writes


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "wb") -> Iterator[IO]:
    """Open a temporary file next to ``path``; on success move it over ``path``.

    On any exception the temporary file is removed and ``path`` is left as it was.

    Parameters
    ----------
    path : path
        Final destination; its folder must exist.
    mode : {"wb", "w"}
        Binary or text (UTF-8) mode.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.txt"
    >>> with atomic_open(p, "w") as f:
    ...     _ = f.write("hello")
    >>> p.read_text()
    'hello'
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"{path}: folder {str(folder)!r} does not exist")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    except OSError as e:  # name the user's file, not the temporary one
        raise InputError(f"{path}: cannot write ({e.strerror or e})") from None
    try:
        kwargs = {"encoding": "utf-8", "newline": "\n"} if "b" not in mode else {}
        with os.fdopen(fd, mode, **kwargs) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        # mkstemp creates 0600 files; give outputs the usual umask-based permissions
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        try:
            os.replace(tmp, path)
        except OSError as e:
            raise InputError(f"{path}: cannot write ({e.strerror or e})") from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def atomic_write(path: str | os.PathLike, data: bytes | str) -> None:
    """Write ``data`` (bytes, or text as UTF-8) to ``path`` atomically.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.bin"
    >>> atomic_write(p, b"xy"); p.read_bytes()
    b'xy'
    """
    with atomic_open(path, "wb") as f:
        f.write(data.encode("utf-8") if isinstance(data, str) else data)


def check_output_path(
    path: str | os.PathLike,
    inputs: Sequence[str | os.PathLike | None] = (),
    force: bool = False,
    what: str = "output",
) -> Path:
    """Check that ``path`` can be written, before any expensive work is done.

    Raises :class:`InputError` when the folder is missing, the path is a folder, or the
    path is one of ``inputs`` (unless ``force``).

    Examples
    --------
    >>> check_output_path("/no/such/out.ply")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: /no/such/out.ply: output folder '/no/such' does not exist
    """
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"{p}: {what} folder {str(folder)!r} does not exist")
    if p.is_dir():
        raise InputError(f"{p}: is a folder; give a file name for the {what}")
    if not force and p.exists():
        for inp in inputs:
            if inp is not None and Path(inp).exists() and os.path.samefile(p, inp):
                raise InputError(f"{p}: {what} would overwrite an input file (use --force)")
    _probe_writable(p, folder, what)
    return p


def _probe_writable(p: Path, folder: Path, what: str) -> None:
    """Create and remove a scratch file next to ``p``: the only test that also sees
    read-only mounts, immutable folders and root's limits (``os.access`` does not)."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".probe", dir=folder)
    except OSError as e:
        raise InputError(
            f"{p}: cannot write the {what} in folder {str(folder)!r} ({e.strerror or e})"
        ) from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(tmp)
    if p.exists():
        try:  # opening for update changes neither content nor times
            with open(p, "r+b"):
                pass
        except OSError as e:
            raise InputError(f"{p}: cannot overwrite the {what} ({e.strerror or e})") from None


# --------------------------------------------------------------------------- JSON


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays, paths and non-finite floats into plain JSON values.

    Non-finite floats become ``None`` so that the output is strict JSON.

    Examples
    --------
    >>> import numpy as np
    >>> to_jsonable({"a": np.arange(2), "b": float("nan"), "c": np.float32(1.5)})
    {'a': [0, 1], 'b': None, 'c': 1.5}
    """
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer, int)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    return obj


def write_json(path: str | os.PathLike, obj: Any, indent: int = 2) -> None:
    """Write ``obj`` as strict JSON, atomically (numpy values are converted).

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "r.json"
    >>> write_json(p, {"iterations": np.int64(3)}); p.read_text()
    '{\\n  "iterations": 3\\n}\\n'
    """
    text = json.dumps(to_jsonable(obj), indent=indent, allow_nan=False) + "\n"
    atomic_write(path, text)


# --------------------------------------------------------------------------- meshes


def mesh_format(path: str | os.PathLike) -> tuple[str, bool]:
    """Mesh format named by a file's extension, and whether it ends in ``.gz``.

    Examples
    --------
    >>> mesh_format("out.OFF.gz")
    ('off', True)
    """
    name = Path(path).name.lower()
    gz = name.endswith(".gz")
    if gz:
        name = name[:-3]
    ext = name.rsplit(".", 1)[-1] if "." in name else ""
    if ext not in MESH_FORMATS:
        shown = f"'.{ext}'" if ext else "no extension"
        raise InputError(
            f"{path}: unsupported mesh format {shown} (use one of: "
            + ", ".join("." + f for f in MESH_FORMATS)
            + ")"
        )
    return ext, gz


def ply_property_column(name: str, values, n: int) -> np.ndarray:
    """A vertex property as PLY can hold it: n values, int32 for integers, else double.

    Examples
    --------
    >>> ply_property_column("rings", [1, 2], 2).dtype.name
    'int32'
    """
    arr = np.asarray(values)
    if arr.shape != (n,):
        raise ValueError(f"vertex property {name!r} has shape {arr.shape}, expected ({n},)")
    if not name.isidentifier():
        raise ValueError(f"vertex property name {name!r} is not a plain identifier")
    # PLY has no 64-bit integers: integers as int32, everything else as double
    return arr.astype(np.int32 if arr.dtype.kind in "iub" else np.float64)


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
    header += [f"property {_PLY_TYPES[np.dtype(t).newbyteorder('=')]} {f}" for f, t in fields]
    header += [f"element face {m}", "property list uchar int vertex_indices", "end_header"]
    return ("\n".join(header) + "\n").encode("ascii") + vert.tobytes() + face.tobytes()


def _rows(fmt: str, arr: np.ndarray) -> str:
    buf = io.StringIO()
    np.savetxt(buf, arr, fmt=fmt)
    return buf.getvalue()


def _text_bytes(vertices: np.ndarray, faces: np.ndarray, fmt: str) -> bytes:
    # %.17g round-trips every double exactly; generic exporters round to fixed decimals
    if fmt == "off":
        head = f"OFF\n{len(vertices)} {len(faces)} 0\n"
        body = _rows("%.17g", vertices) + _rows("3 %d %d %d", faces)
    else:
        head = "# written by arapkit\n"
        body = _rows("v %.17g %.17g %.17g", vertices) + _rows("f %d %d %d", faces + 1)
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
    vertices : (n, 3) float
    faces : (m, 3) int, optional
        Triangles; not needed (and not used) when ``like`` is given.
    vertex_properties : dict of name -> (n,) array, optional
        Extra per-vertex values (``energy``, ``rings`` ...). Only PLY stores them; other
        formats drop them because they have no place for them.
    like : Mesh, optional
        The mesh ``vertices`` belong to (the loaded input, or a mesh made by
        :func:`arapkit.mesh.welding.weld`, whose values are then written to the input's own
        vertices). Everything its file carried is written again: the original polygons
        (also faces dropped as degenerate), UVs with their seams, normals recomputed
        from ``vertices``, OBJ materials and groups, colours, PLY properties. See
        ``docs/io.md`` for what each format keeps.

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
    fmt, gz = mesh_format(path)
    V = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
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
        from arapkit.io.meshwriters import write_with_attributes

        data, warnings = write_with_attributes(fmt, V, attrs, props, _trimesh_bytes)
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


def read_ply_vertex_properties(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """All scalar vertex properties of a PLY file (ASCII or binary, optionally ``.gz``).

    Returns
    -------
    dict of name -> (n,) array, including ``x``, ``y``, ``z``.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.ply"
    >>> save_mesh(p, np.eye(3), np.array([[0, 1, 2]]), {"energy": np.array([0.5, 1, 2])})
    []
    >>> read_ply_vertex_properties(p)["energy"].tolist()
    [0.5, 1.0, 2.0]
    """
    import trimesh

    path = Path(path)
    try:
        raw = path.read_bytes()
        if path.name.lower().endswith(".gz"):
            raw = gzip.decompress(raw)
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except (OSError, EOFError) as e:
        raise InputError(f"{path}: cannot read ({e})") from None
    try:
        loaded = trimesh.load(io.BytesIO(raw), file_type="ply", process=False)
    except Exception as e:  # trimesh raises many types on malformed PLY
        raise InputError(f"{path}: not a readable PLY file ({e})") from None
    ply_raw = getattr(loaded, "metadata", {}).get("_ply_raw", {})
    data = ply_raw.get("vertex", {}).get("data")
    # trimesh gives a structured array, or a dict of arrays for some binary layouts
    if isinstance(data, dict):
        names = list(data)
    else:
        names = getattr(getattr(data, "dtype", None), "names", None)
    if not names:
        raise InputError(f"{path}: PLY file has no vertex element")
    cols = {name: np.asarray(data[name]) for name in names}
    return {name: a.reshape(-1) for name, a in cols.items() if a.ndim == 1 or a.shape[1:] == (1,)}


# --------------------------------------------------------------------------- numpy arrays


#: what np.load raises on a damaged or foreign file: a file that starts like a zip archive
#: (every .npz) and then holds garbage fails inside zipfile or zlib, not in numpy
_NUMPY_ERRORS = (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile, zlib.error)


def load_numpy(
    path: str | os.PathLike, names: Sequence[str] | None = None
) -> np.ndarray | dict[str, np.ndarray]:
    """Read a ``.npy`` array, or the arrays ``names`` of a ``.npz`` archive, from user input.

    Every way a damaged file fails becomes one :class:`InputError` line naming the file;
    pickled objects are never loaded.

    Parameters
    ----------
    path : path
    names : sequence of str, optional
        For a ``.npz`` archive: the arrays to read (all must be present). Without it the
        file must be a single ``.npy`` array.

    Returns
    -------
    ndarray, or dict of name -> ndarray when ``names`` is given.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.npz"
    >>> np.savez(p, V=np.zeros((2, 3)))
    >>> load_numpy(p, ["V"])["V"].shape
    (2, 3)
    >>> _ = p.write_bytes(b"PK\\x03\\x04garbage")
    >>> load_numpy(p, ["V"])
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: ...a.npz: not a readable .npz file (BadZipFile: File is not a \
zip file)
    """
    kind = ".npy" if names is None else ".npz"
    try:
        with contextlib.ExitStack() as stack:
            data = np.load(path, allow_pickle=False)
            if isinstance(data, np.lib.npyio.NpzFile):
                stack.enter_context(data)
                if names is None:
                    raise InputError(f"{path}: a .npz archive, expected a single .npy array")
                missing = [n for n in names if n not in data.files]
                if missing:
                    raise InputError(f"{path}: expected arrays {', '.join(map(repr, names))}, "
                                     f"found {', '.join(data.files) or 'none'}")
                return {n: np.asarray(data[n]) for n in names}
            if names is not None or not isinstance(data, np.ndarray):
                raise InputError(f"{path}: not a .npz archive (a single array)")
            return data
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except _NUMPY_ERRORS as e:
        raise InputError(f"{path}: not a readable {kind} file ({type(e).__name__}: {e})") from None
