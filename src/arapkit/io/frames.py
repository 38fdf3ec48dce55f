"""Animations on disk: the frames of a simulation as one ``.npz`` or a mesh sequence.

* ``frames.npz``: one NumPy archive with ``V`` (frames, n, 3) float64, ``F`` (m, 3) int64
  and ``times`` (frames,) float64 seconds: what a script loads with ``np.load``.
* ``frames.obj`` (or any mesh format of :func:`arapkit.io.mesh_format`): one file per
  frame, ``frames_0000.obj``, ``frames_0001.obj`` ... (four digits, more when there are
  more frames), which Blender's and Houdini's sequence importers read.

Every file is written atomically (:func:`arapkit.io.atomic_open`): a frame is whole or
absent.

Examples
--------
>>> import tempfile, pathlib, numpy as np
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> V = np.zeros((2, 3, 3)); V[1] += 1.0
>>> [p.name for p in save_frames(d / "f.obj", V, np.array([[0, 1, 2]]))]
['f_0000.obj', 'f_0001.obj']
>>> save_frames(d / "f.npz", V, np.array([[0, 1, 2]]), [0.0, 0.5])[0].name
'f.npz'
>>> load_frames(d / "f.npz")[2].tolist()
[0.0, 0.5]
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..validate import read_input
from .atomic import atomic_open
from .formats import mesh_format
from .writers import save_mesh

__all__ = ["FRAME_ARCHIVE", "frame_paths", "load_frames", "save_frames"]

#: the one-file format of a trajectory
FRAME_ARCHIVE = ".npz"


def frame_paths(path: str | os.PathLike, count: int) -> list[Path]:
    """The files :func:`save_frames` writes for ``count`` frames at ``path``.

    Examples
    --------
    >>> [p.name for p in frame_paths("out/a.ply.gz", 2)]
    ['a_0000.ply.gz', 'a_0001.ply.gz']
    >>> frame_paths("a.npz", 300)[0].name
    'a.npz'
    """
    p = Path(path)
    if p.suffix.lower() == FRAME_ARCHIVE:
        return [p]
    mesh_format(p)  # a one-line error for anything else
    name = p.name
    gz = name.lower().endswith(".gz")
    base = name[:-3] if gz else name
    stem, ext = base.rsplit(".", 1)
    digits = max(4, len(str(max(count - 1, 0))))
    tail = f".{ext}" + (name[-3:] if gz else "")
    return [p.with_name(f"{stem}_{k:0{digits}d}{tail}") for k in range(count)]


def save_frames(path: str | os.PathLike, vertices, faces, times=None, *,
                like: Any = None, warnings: list[str] | None = None) -> list[Path]:
    """Write frames to ``path``: one ``.npz``, or a numbered file per frame.

    Parameters
    ----------
    path : path
        ``*.npz``, or a mesh file name whose stem the frames' names extend.
    vertices : (frames, n, 3)
    faces : (m, 3)
    times : (frames,), optional
        Seconds (stored in the ``.npz``; default 0, 1, 2 ...).
    like : Mesh, optional
        The mesh the frames deform: each frame of a sequence is written with everything
        its file carried (UVs, polygons, colours: :func:`arapkit.io.save_mesh`).
    warnings : list, optional
        Receives, once each, the lines of :func:`arapkit.io.save_mesh` about data the
        sequence's format cannot carry.

    Returns
    -------
    list of Path, the files written.
    """
    V = np.asarray(vertices, dtype=np.float64)
    if V.ndim != 3 or V.shape[2] != 3 or len(V) == 0:
        raise InputError(f"{path}: frames must have shape (frames, n, 3), got {V.shape}")
    F = np.asarray(faces, dtype=np.int64)
    t = np.arange(len(V), dtype=np.float64) if times is None else np.asarray(times, float)
    if t.shape != (len(V),):
        raise InputError(f"{path}: expected {len(V)} times, got shape {t.shape}")
    paths = frame_paths(path, len(V))
    if len(paths) == 1 and paths[0].suffix.lower() == FRAME_ARCHIVE:
        with atomic_open(paths[0], "wb") as f:
            np.savez(f, V=V, F=F, times=t)
        return paths
    for p, Vk in zip(paths, V):
        lost = save_mesh(p, Vk, F) if like is None else save_mesh(p, Vk, like=like)
        if warnings is not None:
            warnings.extend(w for w in lost if w not in warnings)
    return paths


def load_frames(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read a trajectory ``.npz`` written by :func:`save_frames`: ``(V, F, times)``."""
    import io
    import zipfile

    data = read_input(path, "frame archives")
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            V, F = z["V"], z["F"]
            t = z["times"] if "times" in z.files else np.arange(len(V), dtype=np.float64)
    except (KeyError, ValueError, OSError, zipfile.BadZipFile) as e:
        raise InputError(f"{path}: not a frame archive with V and F ({e})") from None
    return V, F, t
