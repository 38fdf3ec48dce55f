"""Landmark files of a template fit: template vertices with the positions they must reach.

A landmarks file is JSON, a list of ``{"vertex": i, "target": [x, y, z]}`` (a vertex index of
the template, and where it goes in the target's coordinates). In Python the same list, a
``{vertex: [x, y, z]}`` mapping or a ``(vertices, targets)`` pair are accepted.

Examples
--------
>>> v, t = parse_landmarks([{"vertex": 2, "target": [0, 0, 1]}], 10)
>>> v.tolist(), t.tolist()
([2], [[0.0, 0.0, 1.0]])
>>> parse_landmarks({12: [0, 0, 0]}, 10)
Traceback (most recent call last):
...
arapkit.errors.InputError: landmarks: landmark 0 is vertex 12, out of range (the template has \
10 vertices)
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping

import numpy as np

from ..errors import InputError
from ..validate import parse_json, read_input, real_array
from .atomic import atomic_write

__all__ = ["load_landmarks", "parse_landmarks", "save_landmarks"]

_KEYS = ("vertex", "target")


def _entry(item, i: int, source: str) -> tuple[object, object]:
    if not isinstance(item, Mapping):
        raise InputError(f"{source}: landmark {i} must be an object "
                         f'{{"vertex": i, "target": [x, y, z]}}, got {type(item).__name__}')
    unknown = sorted(str(k) for k in item if k not in _KEYS)
    if unknown:
        raise InputError(f"{source}: landmark {i} has unknown key {unknown[0]!r} "
                         "(allowed: vertex, target)")
    missing = [k for k in _KEYS if k not in item]
    if missing:
        raise InputError(f"{source}: landmark {i} has no {missing[0]!r}")
    return item["vertex"], item["target"]


def parse_landmarks(value, n_vertices: int,
                    source: str = "landmarks") -> tuple[np.ndarray, np.ndarray]:
    """Landmarks as ``(vertices (k,) int64, targets (k, 3) float64)``, checked.

    Indices must be integers in ``0..n_vertices-1``, each once; targets finite. ``None``
    gives no landmarks.
    """
    if value is None:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    if isinstance(value, Mapping):
        pairs = list(value.items())
    elif isinstance(value, tuple) and len(value) == 2 and not isinstance(value[0], Mapping):
        idx, tgt = value
        idx = np.atleast_1d(real_array(idx, f"{source}: vertices", dtype=None))
        pairs = list(zip(idx.tolist(), np.asarray(real_array(tgt, f"{source}: targets"))
                         .reshape(-1, 3).tolist())) if len(idx) == np.size(tgt) // 3 else None
        if pairs is None:
            raise InputError(f"{source}: {len(idx)} vertices for {np.size(tgt) // 3} targets")
    elif isinstance(value, (list, tuple)):
        pairs = [_entry(item, i, source) for i, item in enumerate(value)]
    else:
        raise InputError(f"{source}: expected a list of {{'vertex': i, 'target': [x, y, z]}}, "
                         f"got {type(value).__name__}")
    verts = np.zeros(len(pairs), dtype=np.int64)
    targets = np.zeros((len(pairs), 3))
    for i, (v, t) in enumerate(pairs):
        if isinstance(v, str) and v.strip().lstrip("-").isdigit():  # JSON object keys
            v = int(v)
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) and not (
                isinstance(v, float) and v.is_integer()):
            raise InputError(f"{source}: landmark {i} vertex must be an integer, got {v!r}")
        if not 0 <= int(v) < n_vertices:
            raise InputError(f"{source}: landmark {i} is vertex {int(v)}, out of range "
                             f"(the template has {n_vertices} vertices)")
        T = np.asarray(real_array(t, f"{source}: landmark {i} target"), dtype=np.float64)
        if T.shape != (3,) or not np.isfinite(T).all():
            raise InputError(f"{source}: landmark {i} (vertex {int(v)}) target must be three "
                             f"finite numbers, got {np.asarray(t).tolist()}")
        verts[i], targets[i] = int(v), T
    uniq, counts = np.unique(verts, return_counts=True)
    if (counts > 1).any():
        raise InputError(f"{source}: vertex {uniq[counts > 1][0]} is listed twice as a landmark")
    return verts, targets


def load_landmarks(path: str | os.PathLike, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """Read a landmarks JSON file (see the module docstring) for a template of
    ``n_vertices`` vertices."""
    return parse_landmarks(parse_json(read_input(path, "landmarks file"), str(path)),
                           n_vertices, str(path))


def save_landmarks(path: str | os.PathLike, vertices, targets) -> None:
    """Write landmarks as JSON (atomically).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "lm.json"
    >>> save_landmarks(p, [3], [[0.5, 0, 1]])
    >>> load_landmarks(p, 10)[0].tolist()
    [3]
    """
    v, t = parse_landmarks((np.asarray(vertices), np.asarray(targets)), 1 << 62, str(path))
    # one landmark a line: a file people read and edit
    rows = [json.dumps({"vertex": int(i), "target": [float(c) for c in x]})
            for i, x in zip(v, t)]
    atomic_write(path, "[\n" + ",\n".join(f"  {r}" for r in rows) + "\n]\n")
