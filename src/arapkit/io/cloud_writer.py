"""Writing point clouds: the deformed points with every per-point value the source carried.

:func:`save_points` (also what :func:`arapkit.io.writers.save_mesh` does with
``like=cloud``) writes the format named by the extension (:data:`CLOUD_WRITE_FORMATS`),
atomically, ``.gz`` compressed where asked:

* PLY (binary little-endian, no face element): the source's vertex properties with their
  types, colours of other sources as ``red green blue [alpha]`` uchar, normals as
  ``nx ny nz``, the caller's per-point values (``energy``, ``rings``) after them;
* OBJ: ``v x y z`` with the source's numbers after them (colours), its other statements;
* OFF: ``n 0 0`` with the source's keyword and extra numbers (COFF colours, NOFF normals);
* XYZ / XYZN / XYZRGB: rows of x y z (and the source's further columns, normals, colours);
* NPY: the (n, 3) positions.

Normals turn with the deformation: a solve's :class:`~arapkit.Result` carries each point's
fitted rotation ``R_k`` (the local step's), and the written normal is ``R_k n_k``. Given
positions alone, each point's rotation is fitted to its graph neighbourhood, rest to
deformed (:func:`fit_point_rotations`: the local step with uniform weights), so a rigid
motion turns the normals exactly. One warning line per kind of data the target format has
no place for, as for meshes.

Examples
--------
>>> import tempfile, pathlib
>>> from arapkit.mesh.cloud import PointCloud
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> c = PointCloud(np.eye(3), normals=np.tile([0.0, 0, 1], (3, 1)))
>>> save_points(d / "c.xyzn", c.points + [0, 0, 5], like=c)  # a translation: normals kept
[]
>>> from arapkit.io import load_points
>>> (np.round(load_points(d / "c.xyzn").normals[0], 12) + 0.0).tolist()
[0.0, 0.0, 1.0]
"""

from __future__ import annotations

import gzip
import io
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..mesh.attributes import MeshAttributes
from .atomic import atomic_write
from .ply import PLY_TYPES, ply_property_column

__all__ = ["CLOUD_WRITE_FORMATS", "cloud_format", "fit_point_rotations", "save_points",
           "turned_normals"]

#: output formats of a point cloud, by extension (``.gz`` may follow all but npy)
CLOUD_WRITE_FORMATS = ("ply", "obj", "off", "xyz", "xyzn", "xyzrgb", "npy")
#: a NumPy type code's PLY name (the standard names first)
_PLY_NAME = {code: name for name, code in reversed(PLY_TYPES.items())}
_NORMAL_PROPS = ("nx", "ny", "nz")
_COLOUR_PROPS = ("red", "green", "blue", "alpha")


def cloud_format(path: str | os.PathLike) -> tuple[str, bool]:
    """The point cloud format named by ``path``'s extension, and whether it ends in ``.gz``.

    Examples
    --------
    >>> cloud_format("out.XYZ.gz")
    ('xyz', True)
    """
    name = Path(path).name.lower()
    gz = name.endswith(".gz")
    name = name[:-3] if gz else name
    ext = name.rsplit(".", 1)[-1] if "." in name else ""
    if ext not in CLOUD_WRITE_FORMATS or (gz and ext == "npy"):
        shown = f"'.{ext}{'.gz' if gz else ''}'" if ext else "no extension"
        raise InputError(f"{path}: unsupported point cloud format {shown} (use one of: "
                         + ", ".join("." + f for f in CLOUD_WRITE_FORMATS) + ")")
    return ext, gz


def turned_normals(normals: np.ndarray, rotations: np.ndarray | None) -> np.ndarray:
    """``R_k n_k`` for every point (the normals as they were without rotations).

    Examples
    --------
    >>> Rz = np.array([[[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]])
    >>> turned_normals(np.array([[1.0, 0, 0]]), Rz).tolist()
    [[0.0, 1.0, 0.0]]
    """
    N = np.asarray(normals, dtype=np.float64)
    if rotations is None:
        return N
    return np.einsum("nij,nj->ni", np.asarray(rotations, dtype=np.float64), N)


def fit_point_rotations(rest: np.ndarray, edges: np.ndarray,
                        deformed: np.ndarray) -> np.ndarray:
    """Each point's rotation best fitting its graph edges, rest to deformed (n, 3, 3):
    ``argmin_R sum_j |e'_ij - R e_ij|^2`` (Kabsch; the ARAP local step with uniform
    weights). A point without edges keeps the identity.

    Examples
    --------
    >>> from scipy.spatial.transform import Rotation
    >>> P = np.random.default_rng(0).random((20, 3))
    >>> E = np.array([[i, j] for i in range(20) for j in range(i + 1, 20)])
    >>> R = Rotation.from_rotvec([0.1, 0.5, -0.2]).as_matrix()
    >>> bool(np.allclose(fit_point_rotations(P, E, P @ R.T), R))
    True
    """
    n = len(rest)
    E = np.asarray(edges, dtype=np.int64)
    d0 = rest[E[:, 0]] - rest[E[:, 1]]
    d1 = deformed[E[:, 0]] - deformed[E[:, 1]]
    outer = np.einsum("ei,ej->eij", d0, d1)
    S = np.zeros((n, 3, 3))
    np.add.at(S, E[:, 0], outer)
    np.add.at(S, E[:, 1], outer)  # an edge is in both ends' neighbourhoods, same sign
    U, _, Vt = np.linalg.svd(S)
    R = np.einsum("nji,nkj->nik", Vt, U)  # V U^T
    flip = np.linalg.det(R) < 0
    if flip.any():  # a reflection: turn the last axis of V around
        Vt[flip, 2] *= -1
        R[flip] = np.einsum("nji,nkj->nik", Vt[flip], U[flip])
    alone = np.abs(S).reshape(n, 9).max(axis=1) == 0
    R[alone] = np.eye(3)
    return R


def _colours(attrs: MeshAttributes | None) -> np.ndarray | None:
    return None if attrs is None else attrs.colors()


def _extra(attrs: MeshAttributes | None) -> np.ndarray | None:
    """Numbers after x y z that are neither normals nor colours (kept verbatim)."""
    if attrs is None or attrs.vertex_extra is None:
        return None
    if attrs.source_format in ("obj", "off") and attrs.colors() is not None:
        return None  # those numbers are the colours
    return attrs.vertex_extra


def _ply(V, attrs, normals, props) -> tuple[bytes, list[str]]:
    n = len(V)
    cols: dict[str, np.ndarray] = {"x": V[:, 0], "y": V[:, 1], "z": V[:, 2]}
    lost: list[str] = []
    if attrs is not None and attrs.source_format == "ply":
        cols.update(attrs.vertex_properties)
        if normals is not None and all(c in cols for c in _NORMAL_PROPS):
            for i, c in enumerate(_NORMAL_PROPS):  # the source's own type kept
                cols[c] = normals[:, i].astype(cols[c].dtype)
    else:
        rgb = _colours(attrs)
        if rgb is not None:
            q = np.clip(np.round(rgb * 255.0), 0, 255).astype(np.uint8)
            cols.update({c: q[:, i] for i, c in enumerate(_COLOUR_PROPS[:rgb.shape[1]])})
        extra = _extra(attrs)
        if extra is not None:
            cols.update({f"extra_{i}": extra[:, i] for i in range(extra.shape[1])})
    if normals is not None and not all(c in cols for c in _NORMAL_PROPS):
        cols.update({c: normals[:, i] for i, c in enumerate(_NORMAL_PROPS)})
    for name, values in props.items():
        cols[name] = ply_property_column(name, values, n)
    dt = [(k, np.dtype(v.dtype).newbyteorder("<").str) for k, v in cols.items()]
    rec = np.empty(n, dtype=dt)
    for k, v in cols.items():
        rec[k] = v
    header = ["ply", "format binary_little_endian 1.0", "comment written by arapkit"]
    if attrs is not None and attrs.source_format == "ply":
        header += [c for c in attrs.comments if c != header[2]]
    header.append(f"element vertex {n}")
    header += [f"property {_PLY_NAME[np.dtype(t).str[1:]]} {k}" for k, t in dt]
    header.append("end_header")
    return ("\n".join(header) + "\n").encode("latin-1") + rec.tobytes(), lost


def _rows(V: np.ndarray, *more: np.ndarray | None) -> list[str]:
    parts = [V] + [m for m in more if m is not None]
    A = np.hstack([np.asarray(p, dtype=np.float64) for p in parts])
    return [" ".join(f"{x:.17g}" for x in row) for row in A.tolist()]


def _text(fmt: str, V, attrs, normals) -> tuple[bytes, set[str]]:
    """OBJ, OFF and the XYZ family; the kinds of data it kept."""
    kept: set[str] = set()
    src = attrs.source_format if attrs is not None else None
    if fmt == "obj":
        extra = attrs.vertex_extra if src == "obj" else _colours(attrs)
        kept |= {"colours", "extra"} if src == "obj" else {"colours"}
        lines = ["# written by arapkit"]
        if attrs is not None and src == "obj":
            lines += [s for _, s in sorted(attrs.statements, key=lambda t: t[0])]
            kept.add("statements")
        lines += ["v " + r for r in _rows(V, extra)]
        return ("\n".join(lines) + "\n").encode("utf-8"), kept
    if fmt == "off":
        keyword, extra = "OFF", None
        if src == "off":
            keyword, extra = attrs.off_keyword, attrs.vertex_extra
            kept |= {"colours", "extra"}
            if normals is not None and attrs.normals is not None:  # NOFF: normals first
                extra = normals if extra is None else np.hstack([normals, extra])
                kept.add("normals")
        lines = [keyword, f"{len(V)} 0 0", *_rows(V, extra)]
        return ("\n".join(lines) + "\n").encode("ascii"), kept
    extra = None
    if fmt == "xyzn" and normals is not None:
        extra, _ = normals, kept.add("normals")
    elif fmt == "xyzrgb" and _colours(attrs) is not None:
        p = attrs.vertex_properties
        # a source that counted to 255 is written so again
        extra = (np.stack([p[c] for c in ("red", "green", "blue")], axis=1)
                 if src == "xyzrgb" and p["red"].dtype.kind in "iu" else _colours(attrs)[:, :3])
        kept.add("colours")
    elif fmt == "xyz" and src == "xyz":
        extra, _ = _extra(attrs), kept.add("extra")
        if normals is not None and attrs.normals is not None:  # x y z nx ny nz rows again
            extra = normals if extra is None else np.hstack([normals, extra])
            kept.add("normals")
    if fmt in ("xyzn", "xyzrgb") and extra is None:
        raise InputError(f"{fmt}: this point cloud has no "
                         f"{'normals' if fmt == 'xyzn' else 'colours'} to write")
    return ("\n".join(_rows(V, extra)) + "\n").encode("ascii"), kept


def _warnings(fmt: str, attrs, normals, kept: set[str], props) -> list[str]:
    have = {
        "normals": normals is not None,
        "colours": _colours(attrs) is not None,
        "extra": _extra(attrs) is not None,
        "statements": attrs is not None and bool(attrs.statements),
        "properties": attrs is not None and any(
            k not in (*_NORMAL_PROPS, *_COLOUR_PROPS) for k in attrs.vertex_properties),
        "values": bool(props),
    }
    text = {"normals": "normals", "colours": "colours",
            "extra": "the extra numbers of each point", "statements": "OBJ statements",
            "properties": "PLY vertex properties", "values": "per-point values ("
            + ", ".join(props) + ")"}
    out = [f"{fmt.upper()} cannot carry them: {text[k]} were not written"
           for k, v in have.items() if v and k not in kept]
    return out + [f"not kept from the input: {w}" for w in (attrs.lost if attrs else [])]


def save_points(path: str | os.PathLike, points, like=None, *, normals=None,
                vertex_properties: Mapping[str, Any] | None = None) -> list[str]:
    """Write a point cloud atomically, in the format named by the extension.

    Parameters
    ----------
    path : path
        ``.ply``, ``.obj``, ``.off``, ``.xyz``, ``.xyzn``, ``.xyzrgb`` (optionally ``.gz``)
        or ``.npy``.
    points : (n, 3) float, a PointCloud, or a solve's Result
        The positions; a :class:`~arapkit.Result` also turns the normals by its rotations
        (positions alone: by rotations fitted to each point's neighbourhood).
    like : PointCloud, optional
        The cloud ``points`` belong to: its normals, colours and properties are written
        with them (``save_points(path, cloud)`` writes a cloud as it is).
    normals : (n, 3), optional
        Normals to write instead of ``like``'s (turned or not).
    vertex_properties : dict of name -> (n,) array, optional
        Extra per-point values (``energy``, ``rings``); only PLY stores them.

    Returns
    -------
    list of str
        One warning line per kind of data the format cannot carry (empty if none).
    """
    fmt, gz = cloud_format(path)
    if like is None and hasattr(points, "points") and getattr(points, "faces", 0) is None:
        like = points
    rotations = getattr(points, "rotations", None)
    V = points if isinstance(points, np.ndarray) else getattr(points, "vertices", points)
    V = np.ascontiguousarray(V, dtype=np.float64).reshape(-1, 3)
    bad = np.flatnonzero(~np.isfinite(V).all(axis=1))
    if len(bad):
        raise InputError(f"{path}: not written: point {bad[0]} has a non-finite coordinate "
                         f"({len(bad)} such points)")
    if like is not None and len(V) != like.n_vertices:
        raise ValueError(f"{len(V)} points for a cloud of {like.n_vertices}")
    attrs = getattr(like, "attributes", None)
    props = dict(vertex_properties or {})
    N = None
    if normals is not None:
        N = np.asarray(normals, dtype=np.float64).reshape(len(V), 3)
    elif like is not None and like.normals is not None:
        if rotations is None or np.shape(rotations) != (len(V), 3, 3):
            # positions alone: each point's rotation fitted to its neighbourhood
            rotations = fit_point_rotations(np.asarray(like.points, np.float64),
                                            like.edges, V)
        N = turned_normals(like.normals, rotations)
    if fmt == "npy":
        buf = io.BytesIO()
        np.save(buf, V, allow_pickle=False)
        data, warn = buf.getvalue(), _warnings(fmt, attrs, N, set(), props)
    elif fmt == "ply":
        data, lost = _ply(V, attrs, N, props)
        kept = {"normals", "colours", "extra", "properties", "values"}
        warn = lost + _warnings(fmt, attrs, N, kept, {})
    else:
        data, kept = _text(fmt, V, attrs, N)
        warn = _warnings(fmt, attrs, N, kept, props)
    if gz:
        data = gzip.compress(data, mtime=0)
    atomic_write(path, data)
    return [f"{Path(path).name}: {w}" for w in warn]
