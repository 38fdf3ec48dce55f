"""The template fit's first point-cloud reader, now a thin door to :mod:`arapkit.io.clouds`.

Kept for one release (the fit's docs and scripts named it): :func:`load_points` here returns
``(points, normals)`` read by :func:`arapkit.io.clouds.load_points`, arapkit's one loader of
point clouds, which reads every format this module did (``.npy`` of shape (n, 3) or (n, 6),
``.xyz`` / ``.txt`` / ``.pts`` rows of ``x y z`` or ``x y z nx ny nz``, a PLY without faces)
and more (OBJ/OFF without faces, ``.xyzn``, ``.xyzrgb``). New code calls
:func:`arapkit.load_points`, which returns an :class:`arapkit.PointCloud` (``cloud.points``,
``cloud.normals``, and every per-point value the file had).

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

import os

import numpy as np

from .clouds import XYZ_ALIASES, XYZ_FORMATS
from .clouds import load_points as load_cloud

__all__ = ["POINT_FORMATS", "is_point_file", "load_points", "ply_points"]

#: extensions read as point clouds whatever they hold (a .ply, .obj or .off is one when it
#: has no faces)
POINT_FORMATS = tuple("." + f for f in ("npy", *XYZ_FORMATS, *XYZ_ALIASES))


def is_point_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` names a format only point clouds come in (by extension).

    Examples
    --------
    >>> is_point_file("scan.NPY"), is_point_file("scan.off")
    (True, False)
    """
    name = os.fspath(path).lower()
    return name.removesuffix(".gz").endswith(POINT_FORMATS)


def load_points(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray | None]:
    """Read a point cloud as ``(points (n, 3), normals (n, 3) or None)``: the
    :class:`~arapkit.PointCloud` of :func:`arapkit.load_points`, unpacked.

    A file with faces gives its vertices (use :func:`arapkit.load_mesh` for a mesh).
    """
    cloud = load_cloud(path)
    return np.array(cloud.points), None if cloud.normals is None else np.array(cloud.normals)


def ply_points(path) -> tuple[np.ndarray, np.ndarray | None] | None:
    """Positions and normals of a PLY without faces; None when it has faces (a mesh)."""
    from .clouds import load_shape

    shape = load_shape(path)
    if shape.faces is not None:
        return None
    return np.array(shape.points), None if shape.normals is None else np.array(shape.normals)
