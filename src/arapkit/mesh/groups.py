"""Vertex groups: sets of vertices that share one rotation, or move as one rigid part.

Two kinds, told apart by a flag per group:

* a **shared-rotation group** (``rigid=False``) is libigl's ``ARAPData.G``: the
  neighbourhoods of its vertices are fitted with one rotation together, while their
  positions stay free (the group still bends and stretches, only less);
* a **rigid part** (``rigid=True``) moves by one rigid motion: every edge inside it keeps
  its length, and a handle inside it moves the whole part.

:class:`VertexGroups` holds both as one id per vertex (``-1``: in no group) with a name and
a flag per group. Files are read and written in :mod:`arapkit.io.groups`; the solver's
use of them is :mod:`arapkit.arap.grouped`.

Examples
--------
>>> g = VertexGroups.from_lists([("arm", [0, 1, 2], True), ("belly", [4, 5], False)], 7)
>>> g.ids.tolist(), g.names, g.rigid.tolist()
([0, 0, 0, -1, 1, 1, -1], ('arm', 'belly'), [True, False])
>>> g.members(0).tolist(), g.summary()
([0, 1, 2], '1 rigid part (3 vertices), 1 shared-rotation group (2 vertices)')
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .cloud import counted

__all__ = ["VertexGroups"]


def _plural(k: int, word: str, words: str | None = None) -> str:
    return f"{k} {word}" if k == 1 else f"{k} {words or word + 's'}"


@dataclass(frozen=True, eq=False)
class VertexGroups:
    """Named vertex groups of one mesh: shared-rotation groups and rigid parts.

    Attributes
    ----------
    ids : (n,) int64
        The group of each vertex (an index into ``names``), ``-1`` for none.
    names : tuple of str
        The groups' names (unique; messages name a group by it).
    rigid : (k,) bool
        True for a rigid part, False for a shared-rotation group.
    source : str
        Where the groups came from (a file name), for messages.

    Build with :meth:`from_ids` or :meth:`from_lists`; both check their input.
    """

    ids: np.ndarray
    names: tuple[str, ...]
    rigid: np.ndarray
    source: str = "groups"

    # -- construction -----------------------------------------------------------------
    @classmethod
    def from_ids(cls, ids, n_vertices: int | None = None, *, rigid: bool | Sequence[bool] = False,
                 names: Sequence[str] | None = None, source: str = "groups") -> VertexGroups:
        """Groups from one id per vertex, as libigl's ``G``.

        Vertices with the same id ``>= 0`` form a group, and ``-1`` is in no group. The ids
        need not be consecutive: only the ids present make groups (numbered in increasing
        id order). libigl documents ``G`` as 1..k but its code counts from 0; both read the
        same here, as they solve the same in libigl (an id no vertex has is an empty group
        there, and no group here).

        Parameters
        ----------
        ids : (n,) int
        n_vertices : int, optional
            The mesh's vertex count, checked against ``len(ids)``.
        rigid : bool or sequence of bool
            One flag for every group, or one per present id in increasing order.
        names : sequence of str, optional
            One per present id (default ``"group <id>"``).
        source : str
            Named in messages.

        Examples
        --------
        >>> g = VertexGroups.from_ids([3, 3, -1, 7], rigid=True)
        >>> g.ids.tolist(), g.names
        ([0, 0, -1, 1], ('group 3', 'group 7'))
        """
        arr = np.asarray(ids)
        whole = arr.size == 0 or np.issubdtype(arr.dtype, np.integer) or (
            np.issubdtype(arr.dtype, np.floating) and bool(np.all(np.isfinite(arr)))
            and bool(np.all(arr == np.round(arr))))
        if arr.ndim != 1 or not whole:
            raise InputError(f"{source}: group ids must be one integer per vertex, got "
                             f"{arr.dtype} of shape {arr.shape}")
        arr = arr.astype(np.int64)
        if n_vertices is not None and len(arr) != n_vertices:
            raise InputError(f"{source}: {len(arr)} group ids for a mesh of {n_vertices} "
                             "vertices")
        if (arr < -1).any():
            v = int(np.flatnonzero(arr < -1)[0])
            raise InputError(f"{source}: vertex {v} has group id {int(arr[v])} (use -1 for "
                             "no group, ids >= 0 for groups)")
        present, dense = np.unique(arr[arr >= 0], return_inverse=True)
        out = np.full(len(arr), -1, dtype=np.int64)
        out[arr >= 0] = dense
        k = len(present)
        if names is None:
            names = [f"group {int(i)}" for i in present]
        flags = np.broadcast_to(np.asarray(rigid, dtype=bool), (k,)) if np.ndim(rigid) == 0 \
            else np.asarray(rigid, dtype=bool)
        return cls._checked(out, tuple(names), flags, source)

    @classmethod
    def from_lists(cls, groups: Iterable[tuple[str, Sequence[int], bool]], n_vertices: int,
                   source: str = "groups") -> VertexGroups:
        """Groups from ``(name, vertex indices, rigid)`` triples; a vertex in two is refused.

        Examples
        --------
        >>> VertexGroups.from_lists([("a", [0, 1], False)], 3).ids.tolist()
        [0, 0, -1]
        """
        ids = np.full(int(n_vertices), -1, dtype=np.int64)
        names, flags = [], []
        for number, (name, idx, rigid) in enumerate(groups):
            idx = np.asarray(idx, dtype=np.int64).reshape(-1)
            if idx.size and (idx.min() < 0 or idx.max() >= n_vertices):
                bad = int(idx[(idx < 0) | (idx >= n_vertices)][0])
                raise InputError(f"{source}: group {name!r}: vertex {bad} out of range "
                                 f"(mesh has {n_vertices} vertices)")
            taken = ids[idx] >= 0
            if taken.any():
                v = int(idx[np.argmax(taken)])
                raise InputError(f"{source}: group {name!r} overlaps group "
                                 f"{names[ids[v]]!r}: both hold vertex {v}")
            ids[idx] = number
            names.append(str(name))
            flags.append(bool(rigid))
        return cls._checked(ids, tuple(names), np.asarray(flags, dtype=bool), source)

    @classmethod
    def _checked(cls, ids: np.ndarray, names: tuple[str, ...], rigid: np.ndarray,
                 source: str) -> VertexGroups:
        k = len(names)
        if len(rigid) != k:
            raise InputError(f"{source}: {len(rigid)} rigid flags for {k} groups")
        seen: dict[str, int] = {}
        for i, name in enumerate(names):
            if not isinstance(name, str) or not name:
                raise InputError(f"{source}: group {i + 1}: the name must be a non-empty string")
            if name in seen:
                raise InputError(f"{source}: group name {name!r} used twice")
            seen[name] = i
        return cls(ids, names, np.array(rigid, dtype=bool), source)

    # -- queries ----------------------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        """The mesh's vertex count."""
        return len(self.ids)

    @property
    def n_groups(self) -> int:
        """How many groups there are (both kinds)."""
        return len(self.names)

    @property
    def sizes(self) -> np.ndarray:
        """(k,) the number of vertices of each group."""
        return np.bincount(self.ids[self.ids >= 0], minlength=self.n_groups)

    def members(self, g: int) -> np.ndarray:
        """The vertices of group ``g``, ascending."""
        return np.flatnonzero(self.ids == g)

    def of_kind(self, rigid: bool) -> np.ndarray:
        """(n,) ids of only the rigid parts (``rigid=True``) or only the shared-rotation
        groups, renumbered ``0..`` in the groups' order (-1 elsewhere).

        Examples
        --------
        >>> g = VertexGroups.from_lists([("a", [0], False), ("b", [1], True)], 3)
        >>> g.of_kind(True).tolist(), g.of_kind(False).tolist()
        ([-1, 0, -1], [0, -1, -1])
        """
        keep = self.rigid if rigid else ~self.rigid
        new = np.full(self.n_groups + 1, -1, dtype=np.int64)
        new[:-1][keep] = np.arange(int(keep.sum()))
        return new[self.ids]  # -1 indexes the last slot, which is -1

    def names_of_kind(self, rigid: bool) -> tuple[str, ...]:
        """The names of the groups :meth:`of_kind` numbers, in its order."""
        return tuple(n for n, r in zip(self.names, self.rigid) if bool(r) == rigid)

    def summary(self, points: bool = False) -> str:
        """One line: how many parts and groups, and how many vertices (``points``: of a
        point cloud, points) they hold."""
        sizes = self.sizes
        bits = []
        for flag, word in ((True, "rigid part"), (False, "shared-rotation group")):
            k = int((self.rigid == flag).sum())
            if k:
                held = int(sizes[self.rigid == flag].sum())
                bits.append(f"{_plural(k, word)} ({counted(held, points=points)})")
        return ", ".join(bits) or "no groups"

    def remapped(self, index: np.ndarray, n_vertices: int) -> VertexGroups:
        """The same groups on another vertex set: vertex ``i`` here is ``index[i]`` there
        (a weld's map); a vertex there takes the group of the first vertex mapped to it
        that has one. Two groups meeting on one vertex there are refused.

        Examples
        --------
        >>> g = VertexGroups.from_lists([("a", [0, 1], True)], 3)
        >>> g.remapped(np.array([0, 0, 1]), 2).ids.tolist()
        [0, -1]
        """
        index = np.asarray(index, dtype=np.int64)
        ids = np.full(n_vertices, -1, dtype=np.int64)
        has = self.ids >= 0
        tgt, gid = index[has], self.ids[has]
        ids[tgt] = gid
        clash = ids[tgt] != gid
        if clash.any():
            i = int(np.argmax(clash))
            raise InputError(f"{self.source}: groups {self.names[gid[i]]!r} and "
                             f"{self.names[ids[tgt[i]]]!r} hold copies of one welded vertex "
                             f"({int(tgt[i])})")
        return VertexGroups(ids, self.names, self.rigid, self.source)
