"""Handle JSON files: which vertices are constrained and where they go.

A handle file is a list of handle groups. Each group selects vertices by exactly one of
``indices``, ``box``, ``sphere`` or ``nearest`` and says where they go with ``fixed`` (the
default), ``translate``, ``rotate`` (then optional ``translate``) or ``targets``. The schema
is documented in ``docs/handles.md`` ("Handle files"). :func:`load_handles` also reads the
benchmark ``.sel`` + ``.def`` pairs (:mod:`arapkit.io.seldef`).

Everything here is a pure function of the file contents and the vertex array, so the
command line and the browser editor share it. Every problem raises
:class:`arapkit.errors.InputError` with a one-line message naming the file and the group.

Examples
--------
>>> import numpy as np
>>> V = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
>>> hs = parse_handles([{"name": "left", "indices": [0]},
...                     {"name": "right", "indices": [2], "translate": [0, 1, 0]}], V)
>>> hs.indices.tolist(), hs.targets[1].tolist()
([0, 2], [2.0, 1.0, 0.0])
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..mesh.selection import (
    HandleContext,
    HandleGroup,
    HandleSet,
    check_target_reach,
    rotation_matrix,
    select_box,
    select_nearest,
    select_sphere,
    short_name,
)
from ..validate import parse_json, positions_of, read_input
from .atomic import write_json
from .seldef import load_def, load_sel

__all__ = [
    "COMMENT_KEY",
    "GROUP_KEYS",
    "MOTION_KEYS",
    "SELECTION_KEYS",
    "handles_to_json",
    "load_handles",
    "parse_handles",
    "save_handles",
    "select_vertices",
]

SELECTION_KEYS = ("indices", "box", "sphere", "nearest")
MOTION_KEYS = ("fixed", "translate", "rotate", "targets")
#: Free text for people, in a group or at the top level; ignored (JSON has no comments).
COMMENT_KEY = "comment"
GROUP_KEYS = frozenset(("name", COMMENT_KEY, *SELECTION_KEYS, *MOTION_KEYS))
_SUB_KEYS = {
    "box": frozenset(("min", "max")),
    "sphere": frozenset(("center", "radius")),
    "nearest": frozenset(("point", "k")),
    "rotate": frozenset(("axis", "degrees", "center")),
}
_REQUIRED_SUB_KEYS = {
    "box": ("min", "max"),
    "sphere": ("center", "radius"),
    "nearest": ("point", "k"),
    "rotate": ("axis", "degrees"),
}


def _is_number(x: Any) -> bool:
    # JSON true/false arrive as bool, a subclass of int: never accept them as numbers
    if not isinstance(x, (int, float)) or isinstance(x, bool):
        return False
    try:
        return math.isfinite(x)
    except OverflowError:  # an integer too large for a double
        return False


def _brief(value: Any) -> str:
    """A bad value as short one-line JSON for a message."""
    try:
        text = json.dumps(value)
    except (TypeError, ValueError, RecursionError):
        text = type(value).__name__
    return text if len(text) <= 60 else text[:57] + "..."


def _vec3(value: Any, what: str, err: HandleContext) -> np.ndarray:
    if not (isinstance(value, list) and len(value) == 3 and all(_is_number(x) for x in value)):
        raise err(f"{what} must be a list of 3 finite numbers, got {_brief(value)}")
    return np.asarray(value, dtype=np.float64)


def _check_keys(obj: Any, allowed: frozenset, what: str, err: HandleContext) -> dict:
    if not isinstance(obj, dict):
        raise err(f"{what} must be an object, got {_brief(obj)}")
    unknown = sorted(set(obj) - allowed)
    if unknown:
        raise err(f"unknown key {unknown[0]!r} in {what} (allowed: {', '.join(sorted(allowed))})")
    return obj


def _sub(group: dict, key: str, err: HandleContext) -> dict:
    obj = _check_keys(group[key], _SUB_KEYS[key], f"'{key}'", err)
    for req in _REQUIRED_SUB_KEYS[key]:
        if req not in obj:
            raise err(f"'{key}' needs '{req}'")
    return obj


def _select(group: dict, vertices: np.ndarray, err: HandleContext) -> np.ndarray:
    kinds = [k for k in SELECTION_KEYS if k in group]
    if len(kinds) != 1:
        raise err(f"needs exactly one selection ({', '.join(SELECTION_KEYS)}), got {len(kinds)}")
    kind, n = kinds[0], len(vertices)
    if kind == "indices":
        raw = group["indices"]
        if not isinstance(raw, list) or not all(
            isinstance(i, int) and not isinstance(i, bool) for i in raw
        ):
            raise err("'indices' must be a list of integers")
        # range first, in Python: an index of 10**30 does not fit a C integer
        bad = next((i for i in raw if not 0 <= i < n), None)
        if bad is not None:
            shown = bad if abs(bad) < 10**15 else f"{float(bad):.3g}"
            raise err(f"vertex index {shown} out of range (mesh has {n} vertices)")
        idx = np.asarray(raw, dtype=np.int64)
        uniq, counts = np.unique(idx, return_counts=True)
        if np.any(counts > 1):
            raise err(f"vertex {int(uniq[counts > 1][0])} listed twice")
        sel = idx
    elif kind == "box":
        box = _sub(group, "box", err)
        lo, hi = _vec3(box["min"], "box 'min'", err), _vec3(box["max"], "box 'max'", err)
        if np.any(lo > hi):
            raise err("box 'min' must not exceed 'max' on any axis")
        sel = select_box(vertices, lo, hi)
    elif kind == "sphere":
        sph = _sub(group, "sphere", err)
        c = _vec3(sph["center"], "sphere 'center'", err)
        r = sph["radius"]
        if not _is_number(r) or r <= 0:
            raise err(f"sphere 'radius' must be a positive number, got {_brief(r)}")
        sel = select_sphere(vertices, c, r)
    else:
        near = _sub(group, "nearest", err)
        p = _vec3(near["point"], "nearest 'point'", err)
        k = near["k"]
        if not (isinstance(k, int) and not isinstance(k, bool)) or not 1 <= k <= n:
            raise err(f"nearest 'k' must be an integer in 1..{n}, got {_brief(k)}")
        sel = select_nearest(vertices, p, k)
    if sel.size == 0:
        raise err(f"{kind} selects no vertices")
    return sel


def select_vertices(entry: dict, vertices: np.ndarray, err) -> np.ndarray:
    """The vertices one entry of a handle or groups file selects: exactly one of
    ``indices``, ``box``, ``sphere`` or ``nearest`` (checked; ``err(message)`` makes the
    error, naming the file and the entry). Groups files (:mod:`arapkit.io.groups`) share
    the handle files' selectors through this.

    Examples
    --------
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    >>> select_vertices({"sphere": {"center": [2, 0, 0], "radius": 1.5}}, V,
    ...                 HandleContext("h.json", 1, None)).tolist()
    [1, 2]
    """
    return _select(entry, vertices, err)


def _move(group: dict, rest: np.ndarray, err: HandleContext) -> tuple[np.ndarray, str]:
    """Target positions of the selected rest positions, and the group kind."""
    present = [k for k in MOTION_KEYS if k in group]
    if "fixed" in group:
        if group["fixed"] is not True:
            raise err("'fixed' may only be true (omit it, or give translate/rotate/targets)")
        if len(present) > 1:
            raise err(f"'fixed' cannot be combined with {present[1]!r}")
        return rest.copy(), "fixed"
    if "targets" in group:
        if len(present) > 1:
            other = next(k for k in present if k != "targets")
            raise err(f"'targets' cannot be combined with {other!r}")
        raw = group["targets"]
        if not isinstance(raw, list) or len(raw) != len(rest):
            got = len(raw) if isinstance(raw, list) else type(raw).__name__
            raise err(f"'targets' needs {len(rest)} positions (one per selected vertex), got {got}")
        return np.stack([_vec3(t, f"target {i}", err) for i, t in enumerate(raw)]), "moved"
    if not present:
        return rest.copy(), "fixed"
    out = rest.copy()
    if "rotate" in group:
        rot = _sub(group, "rotate", err)
        axis = _vec3(rot["axis"], "rotate 'axis'", err)
        if np.linalg.norm(axis) == 0:
            raise err("rotate 'axis' must be non-zero")
        if not _is_number(rot["degrees"]):
            raise err(f"rotate 'degrees' must be a number, got {_brief(rot['degrees'])}")
        # default centre: the group's own centroid, so "rotate in place" needs no coordinates
        c = _vec3(rot["center"], "rotate 'center'", err) if "center" in rot else rest.mean(0)
        out = (out - c) @ rotation_matrix(axis, rot["degrees"]).T + c
    if "translate" in group:
        out = out + _vec3(group["translate"], "'translate'", err)
    return out, "moved"


def _group_list(data: Any, source: str) -> list:
    if isinstance(data, dict):
        unknown = sorted(set(data) - {"groups", COMMENT_KEY})
        if unknown:
            raise InputError(
                f"{source}: unknown top-level key {unknown[0]!r} (allowed: groups, comment)"
            )
        if "groups" not in data:
            raise InputError(f"{source}: expected a list of handle groups or {{'groups': [...]}}")
        data = data["groups"]
    if not isinstance(data, list):
        raise InputError(f"{source}: expected a list of handle groups")
    if not data:
        raise InputError(f"{source}: no handle groups")
    return data


def parse_handles(
    data: Any, vertices: np.ndarray, source: str = "<handles>", welded: Any = None
) -> HandleSet:
    """Resolve a parsed handle description against rest vertex positions.

    Parameters
    ----------
    data : list of dict, or {"groups": list}
        Parsed JSON (the schema is in ``docs/handles.md``, "Handle files").
    vertices : (n, 3) array_like, or a mesh
        Rest positions (a Mesh or a trimesh stands for its vertices); selections and
        rotations use them.
    source : str
        Name used in error messages (normally the file name).
    welded : Mesh, optional
        A mesh made by :func:`arapkit.mesh.welding.weld` from the mesh whose positions are
        ``vertices``. The handles are then resolved for the solve on it: ``box``,
        ``sphere`` and ``nearest`` select its vertices (so ``nearest`` counts positions,
        not copies of one position), while ``indices`` keep numbering the input's
        vertices and are mapped through the weld
        (:func:`arapkit.mesh.welding.weld_handles`). The result indexes ``welded``.

    Returns
    -------
    HandleSet

    Raises
    ------
    InputError
        Unknown keys, malformed values, empty selections, out-of-range indices or groups
        selecting the same vertex; the message names the group.

    Examples
    --------
    >>> import numpy as np
    >>> V = np.eye(3)
    >>> hs = parse_handles([{"box": {"min": [0.5, -1, -1], "max": [2, 1, 1]},
    ...                      "rotate": {"axis": [0, 0, 1], "degrees": 90,
    ...                                 "center": [0, 0, 0]}}], V)
    >>> np.round(hs.targets, 12).tolist()
    [[0.0, 1.0, 0.0]]

    On a welded soup ``nearest`` picks distinct positions, ``indices`` input vertices:

    >>> from arapkit.mesh.welding import weld
    >>> from arapkit import Mesh
    >>> soup = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
    ...             [[0, 1, 2], [3, 4, 5]])
    >>> hs = parse_handles([{"nearest": {"point": [1, 0, 0], "k": 2}}, {"indices": [4]}],
    ...                    soup.vertices, welded=weld(soup))
    >>> [g.indices.tolist() for g in hs.groups]
    [[0, 1], [3]]
    """
    V = np.asarray(positions_of(vertices), dtype=np.float64)
    space = _Space(V, welded, source)
    groups: list[HandleGroup] = []
    names: dict[str, int] = {}
    for number, g in enumerate(_group_list(data, source), start=1):
        name = g.get("name") if isinstance(g, dict) else None
        err = HandleContext(source, number, name if isinstance(name, str) else None)
        _check_keys(g, GROUP_KEYS, "group", err)
        if "name" in g and (not isinstance(name, str) or not name):
            raise err("'name' must be a non-empty string")
        name = name or f"group {number}"
        if name in names:
            raise err(f"name {short_name(name)} already used by group {names[name]}")
        names[name] = number
        group = space.resolve(g, name, err)
        if group is not None:
            groups.append(group)
    space.check_copies()
    return HandleSet(groups, source=source)


class _Space:
    """Resolves handle groups into the vertex numbering of the solve, and keeps which
    group owns each vertex (two groups may not select the same vertex).

    Without a weld, everything happens on ``vertices``. With one, geometric selections
    act on the welded vertices and explicit ``indices`` on the input's, mapped through
    the weld; copies of one position listed by different ``indices`` groups become one
    handle owned by the first (as on the input, where they are distinct vertices), once
    :meth:`check_copies` has made sure their targets agree.
    """

    def __init__(self, vertices: np.ndarray, welded: Any, source: str) -> None:
        self.vertices, self.welded, self.source = vertices, welded, source
        if welded is not None and len(welded.welded_from.index) != len(vertices):
            raise ValueError(f"{len(vertices)} vertices for a mesh welded from "
                             f"{len(welded.welded_from.index)}")
        n = len(vertices) if welded is None else welded.n_vertices
        self.owner = np.full(n, -1, dtype=np.int64)
        self.names: list[str] = []
        self.explicit: list[bool] = []
        # input vertices of ``indices`` groups and their targets, for check_copies
        self.listed: list[tuple[np.ndarray, np.ndarray]] = []
        self.input_owner = np.full(len(vertices), -1, dtype=np.int64)

    def resolve(self, g: dict, name: str, err: HandleContext) -> HandleGroup | None:
        """The group in the solve's numbering (None when copies claimed all of it)."""
        explicit = "indices" in g
        on = self.vertices if self.welded is None or explicit else self.welded.vertices
        idx = _select(g, on, err)
        targets, kind = _move(g, on[idx], err)
        if not np.isfinite(targets).all():
            raise err("the motion puts targets beyond double precision (too large to represent)")
        check_target_reach(targets, idx, on, err)
        number = len(self.names)
        if self.welded is not None and explicit:
            self._claim(self.input_owner, idx, err)  # one input vertex in two groups
            self.input_owner[idx] = number
            self.listed.append((idx, targets))
            from ..mesh.welding import weld_handles

            idx, targets = weld_handles(self.welded, idx, targets, what=self.source)
            # copies already held by an earlier indices group stay there
            by_list = np.array(self.explicit + [False])[self.owner[idx]]  # -1: unowned
            idx, targets = idx[~by_list], targets[~by_list]
        self._claim(self.owner, idx, err)
        self.owner[idx] = number
        self.names.append(name)
        self.explicit.append(explicit)
        return HandleGroup(name, idx, targets, kind) if len(idx) else None

    def _claim(self, owner: np.ndarray, idx: np.ndarray, err: HandleContext) -> None:
        taken = owner[idx] >= 0
        if np.any(taken):
            first = int(idx[np.argmax(taken)])
            what = "welded vertex" if owner is self.owner and self.welded is not None else "vertex"
            raise err(
                f"overlaps group {short_name(self.names[owner[first]])}: "
                f"both select {what} {first} ({int(taken.sum())} shared vertices)"
            )

    def check_copies(self) -> None:
        """Refuse copies of one position sent to different targets by different groups."""
        if self.listed:
            from ..mesh.welding import weld_handles

            weld_handles(self.welded, np.concatenate([i for i, _ in self.listed]),
                         np.concatenate([t for _, t in self.listed]), what=self.source)


def load_handles(
    path: str | os.PathLike,
    vertices: np.ndarray,
    transform: str | os.PathLike | None = None,
    welded: Any = None,
) -> HandleSet:
    """Read handles from a JSON file or a ``.sel`` (+ ``.def``) pair.

    Parameters
    ----------
    path : path
        ``*.json`` handle groups, or ``*.sel`` per-vertex status.
    vertices : (n, 3) array_like, or a mesh
        Rest positions (a Mesh or a trimesh stands for its vertices).
    transform : path, optional
        ``.def`` 4x4 matrix for a ``.sel`` file; defaults to the ``.def`` next to it.
    welded : Mesh, optional
        A mesh welded (:func:`arapkit.mesh.welding.weld`) from the mesh of ``vertices``: the
        handles come back on its vertices, geometric selections made on it and vertex
        numbers read as the input's (see :func:`parse_handles`).

    Returns
    -------
    HandleSet

    Examples
    --------
    >>> import json, tempfile, numpy as np, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "h.json"
    >>> _ = p.write_text(json.dumps([{"indices": [0]}]))
    >>> load_handles(p, np.zeros((2, 3))).indices.tolist()
    [0]
    """
    path = Path(path)
    if path.suffix.lower() == ".sel":
        if transform is None:
            transform = path.with_suffix(".def")
            if not transform.exists():
                raise InputError(f"{path}: a .sel file needs a .def transform (--transform FILE)")
        hs = load_sel(path, vertices, load_def(transform), transform)
        if welded is None:
            return hs
        from ..mesh.welding import weld_handle_set

        return weld_handle_set(welded, hs)  # statuses number the input's vertices
    if transform is not None:
        raise InputError(f"{transform}: a .def transform only applies to .sel handle files")
    data = parse_json(read_input(path, "handle files"), str(path))
    return parse_handles(data, vertices, source=str(path), welded=welded)


def handles_to_json(handles: HandleSet) -> list[dict]:
    """Explicit JSON form of a handle set (indices and targets written out).

    Fixed groups are written as ``{"name", "indices", "fixed": true}`` so that reloading
    them against the same rest shape gives identical targets.

    Examples
    --------
    >>> import numpy as np
    >>> hs = HandleSet([HandleGroup("a", np.array([0]), np.zeros((1, 3)))])
    >>> handles_to_json(hs)
    [{'name': 'a', 'indices': [0], 'fixed': True}]
    """
    out = []
    for g in handles.groups:
        item: dict[str, Any] = {"name": g.name, "indices": [int(i) for i in g.indices]}
        if g.kind == "fixed":
            item["fixed"] = True
        else:
            item["targets"] = [[float(x) for x in t] for t in g.targets]
        out.append(item)
    return out


def save_handles(path: str | os.PathLike, handles: HandleSet) -> None:
    """Write ``handles`` as explicit handle JSON (atomically).

    Examples
    --------
    >>> import tempfile, numpy as np, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "h.json"
    >>> save_handles(p, HandleSet([HandleGroup("a", np.array([1]), np.ones((1, 3)), "moved")]))
    >>> load_handles(p, np.zeros((2, 3))).targets.tolist()
    [[1.0, 1.0, 1.0]]
    """
    write_json(path, handles_to_json(handles))
