"""Groups files: rigid parts and shared-rotation groups of a mesh's vertices.

A groups file is JSON in the language of handle files (:mod:`arapkit.io.handles`): a list
of entries (or ``{"groups": [...], "comment": ...}``), each with an optional ``name``, one
selector (``indices``, ``box``, ``sphere`` or ``nearest``, as in handle files) and
``"rigid"``: ``true`` (the default) for a **rigid part**, ``false`` for a **shared-rotation
group** (libigl's ``ARAPData.G``). Two entries may not select the same vertex::

    [{"name": "left arm", "box": {"min": [-5, 5, -2], "max": [-1.9, 12, 2]}, "rigid": true},
     {"name": "pot", "sphere": {"center": [0, 0, 0], "radius": 2.5}, "rigid": false}]

One id per vertex works too (``-1``: in no group; vertices with the same id ``>= 0`` form
a group): a ``.npy`` array or a text file of integers is libigl's ``G`` (shared rotations),
and a PLY file's vertex property ``group`` (shared rotations) and/or ``part`` (rigid parts)
give both kinds. Every problem is one :class:`~arapkit.errors.InputError` naming the file
and, for JSON, the entry.

Examples
--------
>>> import numpy as np
>>> V = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]])
>>> g = parse_groups([{"name": "end", "box": {"min": [1.5, -1, -1], "max": [4, 1, 1]}},
...                   {"indices": [0], "rigid": False}], V)
>>> g.ids.tolist(), g.names, g.rigid.tolist()
([1, -1, 0, 0], ('end', 'group 2'), [True, False])
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..mesh.groups import VertexGroups
from ..mesh.selection import short_name
from ..validate import check_input_size, parse_json, positions_of, read_input
from .arrays import load_numpy
from .atomic import write_json
from .formats import existing_file
from .handles import COMMENT_KEY, SELECTION_KEYS, select_vertices
from .readers import read_ply_vertex_properties
from .text import int_tokens

__all__ = ["ENTRY_KEYS", "GROUP_PROPERTIES", "groups_to_json", "load_groups", "parse_groups",
           "save_groups"]

#: the keys an entry of a groups file may have
ENTRY_KEYS = frozenset(("name", COMMENT_KEY, "rigid", *SELECTION_KEYS))
#: PLY vertex properties read as group ids, and whether each makes rigid parts
GROUP_PROPERTIES = {"group": False, "part": True}


class EntryContext:
    """Names an entry of a groups file in messages: ``file: group N ('name'): ...``.

    Examples
    --------
    >>> str(EntryContext("g.json", 2, "arm")("selects no vertices"))
    "g.json: group 2 ('arm'): selects no vertices"
    """

    def __init__(self, source: str, number: int, name: str | None) -> None:
        self.source, self.number, self.name = source, number, name

    def __call__(self, msg: str) -> InputError:
        label = f"group {self.number}" + (f" ({short_name(self.name)})" if self.name else "")
        return InputError(f"{self.source}: {label}: {msg}")


def _entries(data: Any, source: str) -> list:
    if isinstance(data, dict):
        unknown = sorted(set(data) - {"groups", COMMENT_KEY})
        if unknown:
            raise InputError(f"{source}: unknown top-level key {unknown[0]!r} (allowed: "
                             "groups, comment)")
        if "groups" not in data:
            raise InputError(f"{source}: expected a list of groups or {{'groups': [...]}}")
        data = data["groups"]
    if not isinstance(data, list):
        raise InputError(f"{source}: expected a list of groups")
    if not data:
        raise InputError(f"{source}: no groups")
    return data


def parse_groups(data: Any, vertices, source: str = "<groups>", welded: Any = None
                 ) -> VertexGroups:
    """Resolve a parsed groups description against rest vertex positions.

    Parameters
    ----------
    data : list of dict, or {"groups": list}
        Parsed JSON (schema in the module docstring and ``docs/groups.md``).
    vertices : (n, 3) array_like, or a mesh
        Rest positions; the selectors act on them.
    source : str
        Named in messages (normally the file name).
    welded : Mesh, optional
        A mesh welded (:func:`arapkit.mesh.welding.weld`) from the mesh of ``vertices``:
        the groups come back on its vertices (selected on the input's, so ``indices`` number
        the input's vertices).

    Returns
    -------
    VertexGroups

    Examples
    --------
    >>> parse_groups([{"indices": [1, 2], "rigid": True}], np.eye(3)).summary()
    '1 rigid part (2 vertices)'
    """
    V = np.asarray(positions_of(vertices), dtype=np.float64)
    resolved = []
    owner = np.full(len(V), -1, dtype=np.int64)
    names: list[str] = []
    for number, entry in enumerate(_entries(data, source), start=1):
        name = entry.get("name") if isinstance(entry, dict) else None
        err = EntryContext(source, number, name if isinstance(name, str) else None)
        if not isinstance(entry, dict):
            raise err("must be an object with a selector (indices, box, sphere or nearest)")
        unknown = sorted(set(entry) - ENTRY_KEYS)
        if unknown:
            raise err(f"unknown key {unknown[0]!r} (allowed: {', '.join(sorted(ENTRY_KEYS))})")
        if "name" in entry and (not isinstance(name, str) or not name):
            raise err("'name' must be a non-empty string")
        name = name or f"group {number}"
        if name in names:
            raise err(f"name {short_name(name)} already used by group {names.index(name) + 1}")
        rigid = entry.get("rigid", True)
        if not isinstance(rigid, bool):
            raise err(f"'rigid' must be true (a rigid part) or false (a shared rotation), got "
                      f"{rigid!r}")
        idx = select_vertices(entry, V, err)
        taken = owner[idx] >= 0
        if taken.any():
            v = int(idx[np.argmax(taken)])
            raise err(f"overlaps group {short_name(names[owner[v]])}: both select vertex {v} "
                      f"({int(taken.sum())} shared vertices)")
        owner[idx] = len(names)
        names.append(name)
        resolved.append((name, idx, rigid))
    groups = VertexGroups.from_lists(resolved, len(V), source)
    return _on(groups, welded)


def _on(groups: VertexGroups, welded: Any) -> VertexGroups:
    """``groups`` on the welded mesh (itself without one)."""
    if welded is None:
        return groups
    return groups.remapped(welded.welded_from.index, welded.n_vertices)


def _ids_from_ply(path: Path, n: int) -> VertexGroups:
    props = read_ply_vertex_properties(path)
    found = {k: v for k, v in props.items() if k in GROUP_PROPERTIES}
    if not found:
        names = ", ".join(sorted(props)) or "none"
        raise InputError(f"{path}: no vertex property 'group' or 'part' (found: {names})")
    if len(found) == 1:
        (key, ids), = found.items()
        return VertexGroups.from_ids(ids, n, rigid=GROUP_PROPERTIES[key], source=str(path))
    # both: parts and groups may not share a vertex; parts first, then groups
    ids = {k: VertexGroups.from_ids(v, n, source=f"{path} ({k})") for k, v in found.items()}
    lists = [(f"part {i}", ids["part"].members(i), True) for i in range(ids["part"].n_groups)]
    lists += [(f"group {i}", ids["group"].members(i), False)
              for i in range(ids["group"].n_groups)]
    return VertexGroups.from_lists(lists, n, str(path))


def load_groups(path: str | os.PathLike, vertices, welded: Any = None) -> VertexGroups:
    """Read vertex groups from a file.

    Parameters
    ----------
    path : path
        ``.json`` (named entries, see the module docstring), ``.npy`` or text (one id per
        vertex: libigl's ``G``, shared rotations, -1 for none), or ``.ply`` / ``.ply.gz``
        (vertex properties ``group`` and/or ``part``).
    vertices : (n, 3) array_like, or a mesh
        The mesh's rest positions (JSON selectors act on them; id files must have one id
        per vertex).
    welded : Mesh, optional
        The welded mesh the solve runs on (see :func:`parse_groups`).

    Returns
    -------
    VertexGroups

    Examples
    --------
    >>> import json, tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "g.json"
    >>> _ = p.write_text(json.dumps([{"name": "tip", "indices": [2]}]))
    >>> load_groups(p, np.zeros((3, 3))).ids.tolist()
    [-1, -1, 0]
    """
    path = existing_file(path)
    name = path.name.lower()
    V = np.asarray(positions_of(vertices), dtype=np.float64)
    n = len(V)
    if name.endswith(".json"):
        data = parse_json(read_input(path, "groups files"), str(path))
        return parse_groups(data, V, source=str(path), welded=welded)
    if name.endswith(".npy"):
        check_input_size(path.stat().st_size, path, "groups files")
        groups = VertexGroups.from_ids(load_numpy(path), n, source=str(path))
    elif name.endswith((".ply", ".ply.gz")):
        groups = _ids_from_ply(path, n)
    else:
        ids = int_tokens(path, "group id", "groups files", n)
        # range first, in Python: an id of 10**30 does not fit a C integer
        bad = next((v for v, i in enumerate(ids) if not -1 <= i < 2**62), None)
        if bad is not None:
            shown = ids[bad] if abs(ids[bad]) < 10**15 else f"{float(ids[bad]):.3g}"
            raise InputError(f"{path}: vertex {bad} has group id {shown} (use -1 for no "
                             "group, ids >= 0 for groups)")
        groups = VertexGroups.from_ids(np.asarray(ids, dtype=np.int64), n, source=str(path))
    return _on(groups, welded)


def groups_to_json(groups: VertexGroups) -> list[dict]:
    """Explicit JSON form of ``groups`` (names, vertex indices and flags).

    Examples
    --------
    >>> groups_to_json(VertexGroups.from_lists([("a", [0, 2], False)], 3))
    [{'name': 'a', 'indices': [0, 2], 'rigid': False}]
    """
    return [{"name": name, "indices": [int(i) for i in groups.members(g)],
             "rigid": bool(groups.rigid[g])} for g, name in enumerate(groups.names)]


def save_groups(path: str | os.PathLike, groups: VertexGroups) -> None:
    """Write ``groups`` as an explicit groups file (JSON with indices), atomically.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "g.json"
    >>> save_groups(p, VertexGroups.from_lists([("a", [1], True)], 2))
    >>> load_groups(p, np.zeros((2, 3))).names
    ('a',)
    """
    if not str(path).lower().endswith(".json"):
        raise InputError(f"{path}: groups are saved as .json")
    write_json(path, groups_to_json(groups))
