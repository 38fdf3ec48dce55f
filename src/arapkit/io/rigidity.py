"""Rigidity map files: one integer ring size r >= 1 per vertex, as plain text, ``.npy`` or a
PLY vertex property named ``rings``.

Examples
--------
>>> import tempfile, pathlib, numpy as np
>>> p = pathlib.Path(tempfile.mkdtemp()) / "r.txt"
>>> save_rings(p, np.array([1, 3, 2]))
>>> load_rings(p, 3).tolist()
[1, 3, 2]
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..validate import check_input_size, ring_sizes
from .arrays import load_numpy
from .atomic import atomic_write
from .formats import existing_file
from .readers import read_ply_vertex_properties
from .text import int_tokens

__all__ = ["load_rings", "save_rings"]


def _validate_rings(values: Any, n_vertices: int, path: Path) -> np.ndarray:
    """One r per vertex, each in ``1..MAX_RINGS`` (:func:`arapkit.validate.ring_sizes`)."""
    arr = values if isinstance(values, list) else np.asarray(values)
    if isinstance(arr, np.ndarray) and arr.ndim != 1:
        raise InputError(f"{path}: rigidity map must be 1-D (one r per vertex), got {arr.shape}")
    if len(arr) != n_vertices:
        raise InputError(f"{path}: {len(arr)} rigidity values for a mesh of {n_vertices} vertices")
    return ring_sizes(arr, n_vertices, str(path)).astype(np.int64)


def _rings_from_ply(path: Path) -> np.ndarray:
    props = read_ply_vertex_properties(path)
    if "rings" not in props:
        names = ", ".join(sorted(props)) or "none"
        raise InputError(f"{path}: no vertex property 'rings' (found: {names})")
    return props["rings"]


def load_rings(path: str | os.PathLike, n_vertices: int) -> np.ndarray:
    """Read a per-vertex rigidity map (ring size r >= 1 for each vertex).

    Parameters
    ----------
    path : path
        ``.npy`` (1-D integer array), ``.ply`` / ``.ply.gz`` (vertex property ``rings``),
        or plain text with one integer per line (``#`` comments and blank lines allowed).
    n_vertices : int
        Vertex count of the mesh; the map must have exactly this length.

    Returns
    -------
    (n_vertices,) int64

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "r.txt"
    >>> _ = p.write_text("1\\n2\\n6\\n")
    >>> load_rings(p, 3).tolist()
    [1, 2, 6]
    """
    path = existing_file(path)
    name = path.name.lower()
    if name.endswith(".npy"):
        check_input_size(path.stat().st_size, path, "rings files")
        values = load_numpy(path)
    elif name.endswith((".ply", ".ply.gz")):
        values = _rings_from_ply(path)
    else:
        values = int_tokens(path, "rigidity value", "rings files", int(n_vertices))
    return _validate_rings(values, int(n_vertices), path)


def save_rings(path: str | os.PathLike, rings: np.ndarray) -> None:
    """Write a rigidity map as ``.npy`` or plain text (one integer per line), atomically.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "r.npy"
    >>> save_rings(p, np.array([1, 3]))
    >>> load_rings(p, 2).tolist()
    [1, 3]
    """
    path = Path(path)
    r = np.asarray(rings)
    r = _validate_rings(r, len(r), path)
    if path.name.lower().endswith(".npy"):
        buf = io.BytesIO()
        np.save(buf, r)
        atomic_write(path, buf.getvalue())
    elif path.name.lower().endswith((".ply", ".ply.gz")):
        raise InputError(
            f"{path}: a PLY rigidity map needs the mesh; use arapkit.io.writers.save_mesh with "
            "vertex_properties={'rings': ...}"
        )
    else:
        atomic_write(path, "\n".join(str(int(x)) for x in r) + "\n")
