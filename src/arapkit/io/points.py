"""Point-cloud files for a template fit's target: ``.npy``, ``.xyz`` text, and PLY without faces.

A small reader kept apart on purpose: point clouds as general inputs of arapkit come with
their own loader, and this one is meant to be folded into it.

* ``.npy``: an (n, 3) array of positions, or (n, 6) positions then normals;
* ``.xyz`` (also ``.txt``, ``.pts``): one point a line, ``x y z`` or ``x y z nx ny nz``;
* ``.ply`` with a ``vertex`` element and no faces: ``x y z`` and, if present, ``nx ny nz``.

Examples
--------
>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "scan.xyz"
>>> _ = p.write_text("0 0 0\\n1 0 0\\n0 1 0\\n")
>>> P, N = load_points(p)
>>> P.shape, N is None
((3, 3), True)
"""

from __future__ import annotations

import io
import os

import numpy as np

from ..errors import InputError
from ..validate import read_input
from .arrays import load_numpy

__all__ = ["POINT_FORMATS", "is_point_file", "load_points", "ply_points"]

#: extensions read as point clouds (a .ply is one when it has no faces)
POINT_FORMATS = (".npy", ".xyz", ".txt", ".pts")


def is_point_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` names a point-cloud format (by extension; PLY is checked on read).

    Examples
    --------
    >>> is_point_file("scan.NPY"), is_point_file("scan.off")
    (True, False)
    """
    return str(path).lower().endswith(POINT_FORMATS)


def _split(A: np.ndarray, path) -> tuple[np.ndarray, np.ndarray | None]:
    if A.ndim != 2 or A.shape[1] not in (3, 6):
        raise InputError(f"{path}: expected points of shape (n, 3) or (n, 6) with normals, "
                         f"got {A.shape}")
    if A.dtype.kind not in "fiu":
        raise InputError(f"{path}: expected numbers, got {A.dtype}")
    A = A.astype(np.float64)
    return np.ascontiguousarray(A[:, :3]), (np.ascontiguousarray(A[:, 3:]) if A.shape[1] == 6
                                            else None)


def ply_points(path) -> tuple[np.ndarray, np.ndarray | None] | None:
    """Positions (and normals, from ``nx ny nz``) of a PLY without faces; None when it has
    faces (a mesh). Read by trimesh, as the mesh reader does."""
    import trimesh

    try:
        loaded = trimesh.load(io.BytesIO(read_input(path, "point clouds")), file_type="ply",
                              process=False)
    except InputError:
        raise
    except Exception as e:  # trimesh raises many types on malformed PLY
        raise InputError(f"{path}: not a readable PLY file ({e})") from None
    if len(getattr(loaded, "faces", ())):
        return None
    data = getattr(loaded, "metadata", {}).get("_ply_raw", {}).get("vertex", {}).get("data")
    names = list(data) if isinstance(data, dict) else getattr(
        getattr(data, "dtype", None), "names", None) or []
    if not {"x", "y", "z"} <= set(names):
        raise InputError(f"{path}: PLY has no vertices with x, y, z")

    def cols(keys):
        return np.stack([np.asarray(data[k], dtype=np.float64).reshape(-1) for k in keys], 1)

    normals = cols(("nx", "ny", "nz")) if {"nx", "ny", "nz"} <= set(names) else None
    return cols("xyz"), normals


def load_points(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray | None]:
    """Read a point cloud: ``(points (n, 3), normals (n, 3) or None)``.

    Positions and normals are returned as read; :class:`arapkit.methods.fit.FitTarget`
    checks them (finite, not empty). A PLY file with faces is refused here: load it with
    :func:`arapkit.load_mesh`.
    """
    p = str(path)
    low = p.lower()
    if low.endswith(".npy"):
        return _split(np.asarray(load_numpy(p)), p)
    if low.endswith(".ply"):
        out = ply_points(p)
        if out is None:
            raise InputError(f"{p}: a PLY with faces is a mesh (load it with load_mesh)")
        return out
    text = read_input(p, "point clouds").decode("utf-8", errors="replace")
    numbered = [(i + 1, line.split("#", 1)[0].replace(",", " ").split())
                for i, line in enumerate(text.splitlines())]
    numbered = [(i, r) for i, r in numbered if r]
    if not numbered:
        raise InputError(f"{p}: the point cloud is empty")
    width = len(numbered[0][1])
    for i, r in numbered:
        if len(r) != width:
            raise InputError(f"{p}: line {i} has {len(r)} numbers, the first has {width}")
    rows = [r for _, r in numbered]
    try:
        A = np.array(rows, dtype=np.float64)
    except ValueError:
        raise InputError(f"{p}: expected numbers (x y z [nx ny nz] a line)") from None
    return _split(A, p)
