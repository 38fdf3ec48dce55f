"""Editor session files: the format's name and version, reading and writing the JSON.

What a session holds is :meth:`arapkit.editor.state.EditorState.to_dict`; this module is
the file around it: a session is read whole with the input caps of :mod:`arapkit.validate`
(one-line errors naming the file) and written atomically.

Examples
--------
>>> import tempfile, pathlib
>>> path = pathlib.Path(tempfile.mkdtemp()) / "s.json"
>>> _ = write_session(path, {"format": SESSION_FORMAT, "n_vertices": 3})
>>> check_header(read_session(path), 3)
>>> check_header(read_session(path), 4)
Traceback (most recent call last):
...
arapkit.errors.InputError: session: made for a mesh of 3 vertices, the loaded mesh has 4
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from arapkit import validate
from arapkit.errors import InputError

__all__ = ["SESSION_FORMAT", "SESSION_VERSION", "check_header", "graph_of", "graph_options",
           "read_session", "write_session"]

SESSION_FORMAT = "arapkit-editor-session"
SESSION_VERSION = 1


def read_session(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Parse a session file, with a one-line error for a bad one.

    Examples
    --------
    >>> read_session("no-such-session.json")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: no-such-session.json: cannot read session (...)
    """
    try:
        d = validate.parse_json(validate.read_input(path, "sessions"), str(path))
    except InputError as exc:
        shown = repr(str(path)) if "\0" in str(path) else str(path)  # never print a NUL
        why = str(exc).removeprefix(f"{shown}: ")
        raise InputError(f"{shown}: cannot read session ({why})") from None
    if not isinstance(d, dict):
        raise InputError(f"{path}: a session must be a JSON object")
    return d


def write_session(path: str | os.PathLike[str], session: dict[str, Any]) -> Path:
    """Write ``session`` as JSON, atomically (a crash never leaves half a file)."""
    from arapkit.io import write_json

    path = Path(path)
    write_json(path, session, indent=1)
    return path


def check_header(d: Any, n_vertices: int) -> None:
    """Refuse what is not an editor session, or a session made for another vertex count."""
    if not isinstance(d, dict):
        raise InputError(f"session: expected a JSON object, got {type(d).__name__}")
    if d.get("format") != SESSION_FORMAT:
        raise InputError(
            f"session: not an arapkit editor session (format={d.get('format')!r:.40})")
    made_for = d.get("n_vertices", -1)
    if not isinstance(made_for, int) or isinstance(made_for, bool) or made_for != n_vertices:
        raise InputError(
            f"session: made for a mesh of {made_for!r:.40} vertices, "
            f"the loaded mesh has {n_vertices}"
        )


def graph_of(shape: Any) -> dict[str, Any] | None:
    """A point cloud's graph as a session keeps it (``{"neighbours": k}`` or
    ``{"radius": r}``); None for a mesh, whose graph is its triangles.

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.mesh.cloud import PointCloud
    >>> graph_of(PointCloud(np.eye(3), neighbours=2))
    {'neighbours': 2}
    """
    if getattr(shape, "faces", None) is not None:
        return None
    radius = getattr(shape, "radius", None)
    return {"radius": float(radius)} if radius is not None else {
        "neighbours": int(shape.neighbours)}


def graph_options(d: dict[str, Any], where: str) -> dict[str, Any]:
    """The ``neighbours`` / ``radius`` keywords of ``load_shape`` from a session's
    ``"graph"`` (absent in sessions of meshes and of clouds on the default graph).

    The values themselves are checked by the cloud, whose error names them.

    Examples
    --------
    >>> graph_options({"graph": {"radius": 0.5}}, "s.json")
    {'radius': 0.5}
    >>> graph_options({"graph": {"k": 3}}, "s.json")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: s.json: 'graph' must hold 'neighbours' or 'radius', got ['k']
    """
    g = d.get("graph")
    if g is None:
        return {}
    if not isinstance(g, dict) or not g or set(g) - {"neighbours", "radius"}:
        got = sorted(g) if isinstance(g, dict) else type(g).__name__
        raise InputError(f"{where}: 'graph' must hold 'neighbours' or 'radius', got {got!r:.60}")
    return dict(g)
