"""Handle and rigidity files: which vertices are constrained, where they go, and per-vertex r.

Three handle sources are understood, all resolved against the rest vertex positions:

* **Handle JSON** (``*.json``): a list of handle groups. Each group selects vertices by
  exactly one of ``indices``, ``box``, ``sphere`` or ``nearest`` and says where they go with
  ``fixed`` (the default), ``translate``, ``rotate`` (then optional ``translate``) or
  ``targets``. The schema is documented in the README (section "Handle files").
* **Botsch–Sorkine / CGAL benchmark** (``*.sel`` + ``*.def``): one status per vertex
  (0 fixed, 1 free, 2 handle; nothing else) and a 4x4 matrix applied to the handle vertices.
* **Rigidity maps** (``load_rings``): one integer r >= 1 per vertex, as plain text, ``.npy``
  or a PLY vertex property named ``rings``.

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

import io
import json
import math
import os
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from arapkit.errors import InputError
from arapkit.mesh.model import COORDINATE_RANGE
from arapkit.validate import check_input_size, parse_json, read_input, ring_sizes

__all__ = [
    "HandleGroup",
    "HandleSet",
    "handles_to_json",
    "load_def",
    "load_handles",
    "load_rings",
    "load_sel",
    "parse_handles",
    "rotation_matrix",
    "save_def",
    "save_handles",
    "save_rings",
    "save_sel",
    "select_box",
    "select_nearest",
    "select_sphere",
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


# --------------------------------------------------------------------------- data types


@dataclass(frozen=True)
class HandleGroup:
    """One named group of constrained vertices.

    Attributes
    ----------
    name : str
        Name used in messages and in saved files.
    indices : (k,) int64
        Vertex indices, in selection order (explicit ``indices`` keep the order given,
        geometric selections are ascending).
    targets : (k, 3) float64
        Target position of each selected vertex.
    kind : str
        ``"fixed"`` (targets equal the rest positions) or ``"moved"``.
    """

    name: str
    indices: np.ndarray
    targets: np.ndarray
    kind: str = "fixed"


@dataclass(frozen=True)
class HandleSet:
    """All handle groups of one file, flattened for :class:`arapkit.Deformer`.

    Attributes
    ----------
    groups : list of HandleGroup
    source : str
        File name (or ``"<handles>"``) for messages.
    indices : (h,) int64
        Concatenation of the groups' indices (unique across groups).
    targets : (h, 3) float64
        Matching target positions.

    Examples
    --------
    >>> import numpy as np
    >>> g = HandleGroup("a", np.array([1]), np.zeros((1, 3)))
    >>> HandleSet([g]).indices.tolist()
    [1]
    """

    groups: list[HandleGroup]
    source: str = "<handles>"
    indices: np.ndarray = field(init=False, repr=False)
    targets: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.groups:
            idx = np.concatenate([g.indices for g in self.groups]).astype(np.int64)
            tgt = np.concatenate([g.targets for g in self.groups]).astype(np.float64)
        else:
            idx, tgt = np.zeros(0, np.int64), np.zeros((0, 3))
        object.__setattr__(self, "indices", idx)
        object.__setattr__(self, "targets", tgt.reshape(-1, 3))

    @property
    def fixed_mask(self) -> np.ndarray:
        """(h,) bool: True for handles whose group is ``fixed``."""
        if not self.groups:
            return np.zeros(0, bool)
        return np.concatenate([np.full(len(g.indices), g.kind == "fixed") for g in self.groups])

    def __len__(self) -> int:
        return len(self.indices)


# --------------------------------------------------------------------------- selections


def select_box(vertices: np.ndarray, lo: Sequence[float], hi: Sequence[float]) -> np.ndarray:
    """Indices of vertices inside the axis-aligned box ``[lo, hi]`` (inclusive), ascending.

    Examples
    --------
    >>> import numpy as np
    >>> select_box(np.array([[0.0, 0, 0], [2, 0, 0]]), [-1, -1, -1], [1, 1, 1]).tolist()
    [0]
    """
    V = np.asarray(vertices, dtype=np.float64)
    inside = np.all((V >= np.asarray(lo, float)) & (V <= np.asarray(hi, float)), axis=1)
    return np.flatnonzero(inside).astype(np.int64)


def select_sphere(vertices: np.ndarray, center: Sequence[float], radius: float) -> np.ndarray:
    """Indices of vertices within ``radius`` of ``center`` (inclusive), ascending.

    Examples
    --------
    >>> import numpy as np
    >>> select_sphere(np.array([[0.0, 0, 0], [2, 0, 0]]), [2, 0, 0], 0.5).tolist()
    [1]
    """
    V = np.asarray(vertices, dtype=np.float64)
    with np.errstate(over="ignore"):  # numpy squares go to inf; Python's float ** raises
        d2 = np.sum((V - np.asarray(center, float)) ** 2, axis=1)
        r2 = np.float64(radius) ** 2
    return np.flatnonzero(d2 <= r2).astype(np.int64)


def select_nearest(vertices: np.ndarray, point: Sequence[float], k: int) -> np.ndarray:
    """Indices of the ``k`` vertices nearest to ``point``, ascending.

    Ties are broken by the lower vertex index so that the result is reproducible.

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [5, 0, 0]])
    >>> select_nearest(V, [0.9, 0, 0], 2).tolist()
    [0, 1]
    """
    V = np.asarray(vertices, dtype=np.float64)
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k <= len(V):
        raise InputError(f"select_nearest: k must be an integer in 1..{len(V)}, got {k!r}")
    P = np.asarray(point, dtype=np.float64)
    if P.shape != (3,) or not np.all(np.isfinite(P)):
        raise InputError(f"select_nearest: point must be 3 finite numbers, got {point!r}")
    d2 = np.sum((V - P) ** 2, axis=1)
    # lexsort by (distance, index): stable and deterministic for equal distances
    order = np.lexsort((np.arange(len(V)), d2))[:k]
    return np.sort(order).astype(np.int64)


def rotation_matrix(axis: Sequence[float], degrees: float) -> np.ndarray:
    """Right-handed rotation by ``degrees`` about ``axis`` (Rodrigues' formula).

    Examples
    --------
    >>> import numpy as np
    >>> np.round(rotation_matrix([0, 0, 1], 90) @ [1, 0, 0], 12).tolist()
    [0.0, 1.0, 0.0]
    """
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.abs(a).max()  # first to O(1): the norm of a 1e200 axis would overflow
    a = a / np.linalg.norm(a)
    t = math.radians(float(degrees))
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + math.sin(t) * K + (1.0 - math.cos(t)) * (K @ K)


# --------------------------------------------------------------------------- JSON handles


class _Where:
    """Formats the 'file: group ...' prefix of messages."""

    def __init__(self, source: str, number: int, name: str | None) -> None:
        self.source, self.number, self.name = source, number, name

    def __call__(self, msg: str) -> InputError:
        return InputError(f"{self.source}: handle {self.label}: {msg}")

    @property
    def label(self) -> str:
        """``group N ('name')``, the name cut short: a message is one readable line."""
        return f"group {self.number}" + (f" ({_short(self.name)})" if self.name else "")


def _short(name: str) -> str:
    """``repr`` of a name, shortened to about 60 characters."""
    return repr(name) if len(name) <= 60 else repr(name[:57]) + "..."


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


def _vec3(value: Any, what: str, err: _Where) -> np.ndarray:
    if not (isinstance(value, list) and len(value) == 3 and all(_is_number(x) for x in value)):
        raise err(f"{what} must be a list of 3 finite numbers, got {_brief(value)}")
    return np.asarray(value, dtype=np.float64)


def _check_keys(obj: Any, allowed: frozenset, what: str, err: _Where) -> dict:
    if not isinstance(obj, dict):
        raise err(f"{what} must be an object, got {_brief(obj)}")
    unknown = sorted(set(obj) - allowed)
    if unknown:
        raise err(f"unknown key {unknown[0]!r} in {what} (allowed: {', '.join(sorted(allowed))})")
    return obj


def _sub(group: dict, key: str, err: _Where) -> dict:
    obj = _check_keys(group[key], _SUB_KEYS[key], f"'{key}'", err)
    for req in _REQUIRED_SUB_KEYS[key]:
        if req not in obj:
            raise err(f"'{key}' needs '{req}'")
    return obj


def _select(group: dict, vertices: np.ndarray, err: _Where) -> np.ndarray:
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


def _move(group: dict, rest: np.ndarray, err: _Where) -> tuple[np.ndarray, str]:
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


def _check_reach(targets: np.ndarray, idx: np.ndarray, V: np.ndarray, err: Any) -> None:
    """Refuse targets outside the number range the solver computes in for this mesh.

    The solver works in units of the mesh's extent and squares coordinates, so a target
    must be within ``COORDINATE_RANGE`` both in size and in mesh extents (the rule
    :func:`arapkit.mesh.model.check_number_range` applies to the mesh itself). Checked here,
    the message names the file and group that put it there, not the mesh.
    """
    extent = float(np.max(V.max(axis=0) * 0.5 - V.min(axis=0) * 0.5)) * 2.0 if len(V) else 0.0
    limit = COORDINATE_RANGE * min(1.0, extent) if extent > 0 else COORDINATE_RANGE
    far = np.abs(targets).max(axis=1) > limit
    if far.any():
        i = int(np.argmax(far))
        raise err(
            f"target of vertex {int(idx[i])} reaches {float(np.abs(targets[i]).max()):.3g}, "
            f"beyond the number range of this mesh (at most {limit:.3g}: coordinates up to "
            f"{COORDINATE_RANGE:.0e} and {COORDINATE_RANGE:.0e} mesh extents of {extent:.3g})"
        )


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
        Parsed JSON (see the README section "Handle files" for the schema).
    vertices : (n, 3) array_like
        Rest positions; selections and rotations use them.
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
    V = np.asarray(vertices, dtype=np.float64)
    space = _Space(V, welded, source)
    groups: list[HandleGroup] = []
    names: dict[str, int] = {}
    for number, g in enumerate(_group_list(data, source), start=1):
        name = g.get("name") if isinstance(g, dict) else None
        err = _Where(source, number, name if isinstance(name, str) else None)
        _check_keys(g, GROUP_KEYS, "group", err)
        if "name" in g and (not isinstance(name, str) or not name):
            raise err("'name' must be a non-empty string")
        name = name or f"group {number}"
        if name in names:
            raise err(f"name {_short(name)} already used by group {names[name]}")
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

    def resolve(self, g: dict, name: str, err: _Where) -> HandleGroup | None:
        """The group in the solve's numbering (None when copies claimed all of it)."""
        explicit = "indices" in g
        on = self.vertices if self.welded is None or explicit else self.welded.vertices
        idx = _select(g, on, err)
        targets, kind = _move(g, on[idx], err)
        if not np.isfinite(targets).all():
            raise err("the motion puts targets beyond double precision (too large to represent)")
        _check_reach(targets, idx, on, err)
        number = len(self.names)
        if self.welded is not None and explicit:
            self._claim(self.input_owner, idx, err)  # one input vertex in two groups
            self.input_owner[idx] = number
            self.listed.append((idx, targets))
            from arapkit.mesh.welding import weld_handles

            idx, targets = weld_handles(self.welded, idx, targets, what=self.source)
            # copies already held by an earlier indices group stay there
            by_list = np.array(self.explicit + [False])[self.owner[idx]]  # -1: unowned
            idx, targets = idx[~by_list], targets[~by_list]
        self._claim(self.owner, idx, err)
        self.owner[idx] = number
        self.names.append(name)
        self.explicit.append(explicit)
        return HandleGroup(name, idx, targets, kind) if len(idx) else None

    def _claim(self, owner: np.ndarray, idx: np.ndarray, err: _Where) -> None:
        taken = owner[idx] >= 0
        if np.any(taken):
            first = int(idx[np.argmax(taken)])
            what = "welded vertex" if owner is self.owner and self.welded is not None else "vertex"
            raise err(
                f"overlaps group {_short(self.names[owner[first]])}: both select {what} {first} "
                f"({int(taken.sum())} shared vertices)"
            )

    def check_copies(self) -> None:
        """Refuse copies of one position sent to different targets by different groups."""
        if self.listed:
            from arapkit.mesh.welding import weld_handles

            weld_handles(self.welded, np.concatenate([i for i, _ in self.listed]),
                         np.concatenate([t for _, t in self.listed]), what=self.source)


def _read_text(path: Path, what: str) -> str:
    """A capped text input file (:func:`arapkit.validate.read_input`), decoded."""
    try:
        return read_input(path, what).decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file") from None


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
    vertices : (n, 3) array_like
        Rest positions.
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
        from arapkit.mesh.welding import weld_handle_set

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
    from arapkit.io.fileio import write_json

    write_json(path, handles_to_json(handles))


# --------------------------------------------------------------------------- .sel / .def


_INTEGER = re.compile(r"[+-]?[0-9]+")


def _tokens(path: Path, what: str) -> Iterator[tuple[int, str]]:
    """(line number, token) for the whitespace-separated tokens of a text file, skipping
    ``#`` comments; lines are read one at a time, so a long file is never split at once."""
    for number, line in enumerate(io.StringIO(_read_text(path, what)), start=1):
        for token in line.split("#", 1)[0].split():
            yield number, token


def _int_tokens(path: Path, what: str, kind: str, expected: int | None = None,
                allowed: range | None = None) -> list[int]:
    """The whitespace-separated integers of a text file (Python ints: no size limit).

    A token that is not an integer, or outside ``allowed``, is named with its line.
    With ``expected``, reading stops at the first token beyond that count. ``kind`` names
    the kind of file for the size cap's message.
    """
    out: list[int] = []
    for number, t in _tokens(path, kind):
        # ASCII digits with one optional sign: "--1" and "²" pass str.isdigit but not int()
        if not _INTEGER.fullmatch(t) or len(t) > 4000:
            shown = t if len(t) <= 40 else t[:37] + "..."
            raise InputError(f"{path}:{number}: {what} {shown!r} is not an integer")
        value = int(t)
        if allowed is not None and value not in allowed:
            shown = t if len(t) <= 40 else t[:37] + "..."
            raise InputError(f"{path}:{number}: {what} {shown} is not one of "
                             f"{', '.join(map(str, allowed))}")
        out.append(value)
        if expected is not None and len(out) > expected:
            raise InputError(f"{path}:{number}: more than {expected} {what}s for a mesh of "
                             f"{expected} vertices")
    return out


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
    toks = [t for _, t in _tokens(path, ".def files")]
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
    V = np.asarray(vertices, dtype=np.float64)
    # any other code is a typo or another format: refused, not silently "free"
    status = np.array(_int_tokens(path, "status", ".sel files", len(V), range(3)), dtype=np.int8)
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
        err = _Where(str(matrix_source or path), len(groups) + 1, "handle")
        _check_reach(tgt, moved, V, err)
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
    from arapkit.io.fileio import atomic_write

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
    from arapkit.io.fileio import atomic_write

    M = np.asarray(matrix, dtype=np.float64).reshape(4, 4)
    rows = [" ".join(repr(float(x)) for x in row) for row in M]
    atomic_write(path, "# 4x4 handle transformation matrix\n" + "\n".join(rows) + "\n")


# --------------------------------------------------------------------------- rigidity maps


def _validate_rings(values: Any, n_vertices: int, path: Path) -> np.ndarray:
    """One r per vertex, each in ``1..MAX_RINGS`` (:func:`arapkit.validate.ring_sizes`)."""
    arr = values if isinstance(values, list) else np.asarray(values)
    if isinstance(arr, np.ndarray) and arr.ndim != 1:
        raise InputError(f"{path}: rigidity map must be 1-D (one r per vertex), got {arr.shape}")
    if len(arr) != n_vertices:
        raise InputError(f"{path}: {len(arr)} rigidity values for a mesh of {n_vertices} vertices")
    return ring_sizes(arr, n_vertices, str(path)).astype(np.int64)


def _rings_from_ply(path: Path) -> np.ndarray:
    from arapkit.io.fileio import read_ply_vertex_properties

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
    path = Path(path)
    name = path.name.lower()
    if "\0" in str(path):
        raise InputError(f"{str(path)!r}: not a usable file name (NUL byte)")
    if not path.exists():
        raise InputError(f"{path}: file not found")
    if name.endswith(".npy"):
        from arapkit.io.fileio import load_numpy

        check_input_size(path.stat().st_size, path, "rings files")
        values = load_numpy(path)
    elif name.endswith((".ply", ".ply.gz")):
        values = _rings_from_ply(path)
    else:
        values = _int_tokens(path, "rigidity value", "rings files", int(n_vertices))
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
    from arapkit.io.fileio import atomic_write

    path = Path(path)
    r = np.asarray(rings)
    r = _validate_rings(r, len(r), path)
    if path.name.lower().endswith(".npy"):
        import io

        buf = io.BytesIO()
        np.save(buf, r)
        atomic_write(path, buf.getvalue())
    elif path.name.lower().endswith((".ply", ".ply.gz")):
        raise InputError(
            f"{path}: a PLY rigidity map needs the mesh; use arapkit.io.fileio.save_mesh with "
            "vertex_properties={'rings': ...}"
        )
    else:
        atomic_write(path, "\n".join(str(int(x)) for x in r) + "\n")
