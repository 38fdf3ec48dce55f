"""The Botsch–Sorkine / CGAL benchmark handle files: ``.sel`` (one status per vertex: 0
fixed, 1 free, 2 handle; nothing else) and ``.def`` (a 4x4 matrix applied to the handle
vertices).

Examples
--------
>>> import tempfile, pathlib, numpy as np
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> save_sel(d / "a.sel", 3, fixed=[0], handle=[2]); save_def(d / "a.def", np.eye(4))
>>> [g.name for g in load_sel(d / "a.sel", np.zeros((3, 3)), load_def(d / "a.def")).groups]
['fixed', 'handle']
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..mesh.selection import HandleContext, HandleGroup, HandleSet, check_target_reach
from ..validate import positions_of
from .atomic import atomic_write
from .text import int_tokens, text_tokens

__all__ = ["load_def", "load_sel", "save_def", "save_sel"]


def load_def(path: str | os.PathLike) -> np.ndarray:
    """Read a ``.def`` file: a 4x4 affine matrix acting on column vectors ``[x, y, z, 1]``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.def"
    >>> _ = p.write_text("1 0 0 5\\n0 1 0 0\\n0 0 1 0\\n0 0 0 1\\n")
    >>> float(load_def(p)[0, 3])
    5.0
    """
    path = Path(path)
    toks = [t for _, t in text_tokens(path, ".def files")]
    try:
        vals = [float(t) for t in toks[:17]]
    except ValueError:
        raise InputError(f"{path}: expected 16 numbers (a 4x4 matrix)") from None
    if len(vals) != 16 or not all(math.isfinite(v) for v in vals):
        raise InputError(f"{path}: expected 16 finite numbers (a 4x4 matrix), got {len(toks)}")
    M = np.asarray(vals).reshape(4, 4)
    if not np.allclose(M[3], [0, 0, 0, 1], atol=1e-9):
        raise InputError(f"{path}: last row must be 0 0 0 1 (an affine transform)")
    return M


def load_sel(
    path: str | os.PathLike,
    vertices: np.ndarray,
    matrix: np.ndarray | None = None,
    matrix_source: str | os.PathLike | None = None,
) -> HandleSet:
    """Read a ``.sel`` status file (0 fixed, 1 free, 2 handle).

    Parameters
    ----------
    path : path
        One integer per vertex; lines starting with ``#`` are comments.
    vertices : (n, 3) array_like
        Rest positions.
    matrix : (4, 4) array_like, optional
        Affine transform of the handle (status 2) vertices; identity when omitted.
    matrix_source : path, optional
        The ``.def`` file ``matrix`` came from, named when it moves a handle out of the
        number range (the ``.sel`` file is named otherwise).

    Returns
    -------
    HandleSet
        Group ``"fixed"`` (status 0, targets = rest) and group ``"handle"`` (status 2).

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.sel"
    >>> _ = p.write_text("# status\\n0\\n1\\n2\\n")
    >>> M = np.eye(4); M[2, 3] = 1.0
    >>> hs = load_sel(p, np.zeros((3, 3)), M)
    >>> [g.name for g in hs.groups], hs.targets[1].tolist()
    (['fixed', 'handle'], [0.0, 0.0, 1.0])
    """
    path = Path(path)
    V = np.asarray(positions_of(vertices), dtype=np.float64)
    # any other code is a typo or another format: refused, not silently "free"
    status = np.array(int_tokens(path, "status", ".sel files", len(V), range(3)), dtype=np.int8)
    if len(status) != len(V):
        raise InputError(f"{path}: {len(status)} vertex statuses for a mesh of {len(V)} vertices")
    fixed, moved = np.flatnonzero(status == 0), np.flatnonzero(status == 2)
    if fixed.size == 0 and moved.size == 0:
        raise InputError(f"{path}: no vertex has status 0 (fixed) or 2 (handle)")
    M = np.eye(4) if matrix is None else np.asarray(matrix, dtype=np.float64)
    groups = []
    if fixed.size:
        groups.append(HandleGroup("fixed", fixed, V[fixed].copy(), "fixed"))
    if moved.size:
        with np.errstate(over="ignore", invalid="ignore"):  # checked just below
            tgt = V[moved] @ M[:3, :3].T + M[:3, 3]
        err = HandleContext(str(matrix_source or path), len(groups) + 1, "handle")
        check_target_reach(tgt, moved, V, err)
        groups.append(HandleGroup("handle", moved, tgt, "moved"))
    return HandleSet(groups, source=str(path))


def save_sel(
    path: str | os.PathLike, n_vertices: int, fixed: Sequence[int], handle: Sequence[int]
) -> None:
    """Write a ``.sel`` file: status 0 for ``fixed``, 2 for ``handle``, 1 elsewhere.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.sel"
    >>> save_sel(p, 3, [0], [2])
    >>> p.read_text().splitlines()[-3:]
    ['0', '1', '2']
    """
    status = np.ones(int(n_vertices), dtype=np.int64)
    status[np.asarray(fixed, dtype=np.int64)] = 0
    status[np.asarray(handle, dtype=np.int64)] = 2
    header = "# per vertex status: 0=fixed, 1=deformable-region, 2=handle\n"
    header += f"# {n_vertices} vertices\n"
    atomic_write(path, header + "\n".join(str(s) for s in status) + "\n")


def save_def(path: str | os.PathLike, matrix: np.ndarray) -> None:
    """Write a 4x4 matrix as a ``.def`` file (full double precision).

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.def"
    >>> save_def(p, np.eye(4))
    >>> bool(np.all(load_def(p) == np.eye(4)))
    True
    """
    M = np.asarray(matrix, dtype=np.float64).reshape(4, 4)
    rows = [" ".join(repr(float(x)) for x in row) for row in M]
    atomic_write(path, "# 4x4 handle transformation matrix\n" + "\n".join(rows) + "\n")
