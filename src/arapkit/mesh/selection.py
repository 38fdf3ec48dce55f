"""Vertex selections and handle groups: which vertices are constrained and where they go.

Geometric selections (box, sphere, k nearest), the rotation the handle formats use, and the
:class:`HandleGroup` / :class:`HandleSet` records every handle source (JSON, ``.sel`` +
``.def``, the editor) produces. The files themselves are read in :mod:`arapkit.io`.

Examples
--------
>>> V = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
>>> HandleSet([HandleGroup("end", select_box(V, [1.5, -1, -1], [3, 1, 1]), V[2:])]).indices
array([2])
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numba as nb
import numpy as np

from ..errors import InputError
from ..validate import positions_of
from .numbers import COORDINATE_RANGE, extent, kernel_input
from .topology import union_root

__all__ = [
    "HandleContext",
    "HandleGroup",
    "HandleSet",
    "check_target_reach",
    "connected_region",
    "rotation_matrix",
    "select_box",
    "select_nearest",
    "select_sphere",
    "short_name",
]


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


def connected_region(faces: np.ndarray, mask: np.ndarray, seed: int) -> np.ndarray:
    """Vertices reachable from ``seed`` along face edges whose two ends are in ``mask``
    (``faces`` may be an (m, 2) edge list: a point cloud's graph).

    The paint bucket's region (``mask``: the vertices with the seed's r), sorted; empty
    when ``seed`` is not in ``mask``. One pass of union-find over the faces' edges: no edge
    list is made (1.9 s for a 1.75M-vertex mesh that has none yet), no sparse matrix and
    no breadth-first search (0.55 s and 0.35 s there; this takes 0.07 s).

    Examples
    --------
    >>> F = np.array([[0, 1, 2], [1, 3, 2], [3, 4, 5]])
    >>> connected_region(F, np.array([True, True, True, False, True, True]), 0).tolist()
    [0, 1, 2]
    >>> connected_region(F, np.ones(6, dtype=bool), 5).tolist()
    [0, 1, 2, 3, 4, 5]
    """
    return np.flatnonzero(_reach(kernel_input(faces, np.int64), kernel_input(mask, np.bool_),
                                 int(seed)))


@nb.njit(cache=True, nogil=True)
def _reach(F, mask, seed):  # pragma: no cover - compiled
    """Union-find over the edges with both ends in ``mask``; then seed's set, in ``mask``."""
    n = mask.shape[0]
    parent = np.arange(n)
    k = F.shape[1]  # triangles, or a point cloud's edges (k = 2)
    for f in range(F.shape[0]):
        for c in range(k if k > 2 else 1):
            a, b = F[f, c], F[f, (c + 1) % k]
            if mask[a] and mask[b]:
                ra, rb = union_root(parent, a), union_root(parent, b)
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
    out = np.zeros(n, dtype=np.bool_)
    if not mask[seed]:
        return out
    rs = union_root(parent, seed)
    for v in range(n):
        out[v] = mask[v] and union_root(parent, v) == rs
    return out


def select_box(vertices: np.ndarray, lo: Sequence[float], hi: Sequence[float]) -> np.ndarray:
    """Indices of vertices inside the axis-aligned box ``[lo, hi]`` (inclusive), ascending.

    Examples
    --------
    >>> import numpy as np
    >>> select_box(np.array([[0.0, 0, 0], [2, 0, 0]]), [-1, -1, -1], [1, 1, 1]).tolist()
    [0]
    """
    V = np.asarray(positions_of(vertices), dtype=np.float64)
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
    V = np.asarray(positions_of(vertices), dtype=np.float64)
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
    V = np.asarray(positions_of(vertices), dtype=np.float64)
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


class HandleContext:
    """Names a handle group in messages: ``file: handle group N ('name'): ...``.

    Calling it with a message gives the :class:`~arapkit.errors.InputError` to raise.

    Examples
    --------
    >>> str(HandleContext("h.json", 2, "left")("selects no vertices"))
    "h.json: handle group 2 ('left'): selects no vertices"
    """

    def __init__(self, source: str, number: int, name: str | None) -> None:
        self.source, self.number, self.name = source, number, name

    def __call__(self, msg: str) -> InputError:
        return InputError(f"{self.source}: handle {self.label}: {msg}")

    @property
    def label(self) -> str:
        """``group N ('name')``, the name cut short: a message is one readable line."""
        return f"group {self.number}" + (f" ({short_name(self.name)})" if self.name else "")


def short_name(name: str) -> str:
    """``repr`` of a name, shortened to about 60 characters.

    Examples
    --------
    >>> len(short_name("x" * 70))
    62
    """
    return repr(name) if len(name) <= 60 else repr(name[:57]) + "..."


def check_target_reach(targets: np.ndarray, idx: np.ndarray, V: np.ndarray,
                       err: Callable[[str], InputError]) -> None:
    """Refuse targets outside the number range the solver computes in for this mesh.

    The solver works in units of the mesh's extent and squares coordinates, so a target
    must be within ``COORDINATE_RANGE`` both in size and in mesh extents (the rule
    :func:`arapkit.mesh.model.check_number_range` applies to the mesh itself). Checked where
    the targets are read, the message (``err``, e.g. a :class:`HandleContext`) names the file
    and group that put them there, not the mesh.

    Examples
    --------
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0]])
    >>> check_target_reach(np.array([[1e200, 0, 0]]), np.array([1]), V,
    ...                    HandleContext("h.json", 1, None))
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: h.json: handle group 1: target of vertex 1 reaches 1e+200, ...
    """
    size = float(np.max(extent(V))) if len(V) else 0.0
    limit = COORDINATE_RANGE * min(1.0, size) if size > 0 else COORDINATE_RANGE
    far = np.abs(targets).max(axis=1) > limit
    if far.any():
        i = int(np.argmax(far))
        raise err(
            f"target of vertex {int(idx[i])} reaches {float(np.abs(targets[i]).max()):.3g}, "
            f"beyond the number range of this mesh (at most {limit:.3g}: coordinates up to "
            f"{COORDINATE_RANGE:.0e} and {COORDINATE_RANGE:.0e} mesh extents of {size:.3g})"
        )
