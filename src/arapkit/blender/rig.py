"""What the Blender add-on reads from a scene, as arrays, and the handles it makes of them.

Blender users pin and pull a mesh with vertex groups: Blender's own Laplacian Deform
modifier takes an anchors group, the Hook modifier moves a group with an object. The
add-on reads the same things and hands them here as plain arrays (so that all of this is
tested without Blender):

* each handle group as its weights per vertex (0 where a vertex is not in the group) and
  its kind: ``"fixed"`` (held where it is) or ``"moving"`` (carried by an object or a
  bone);
* each moving group's motion: a 4x4 matrix in the mesh's own coordinates, the driver's
  transform now times the inverse of its transform when the handle was bound (what the
  Hook modifier calls its inverse matrix);
* the rigidity group's weights, mapped to ``r`` in a range the panel sets.

A vertex belongs to a group when its weight there is above zero (Blender's own rule for
membership). Where a fixed and a moving group share vertices, the moving group wins (a
hook pulling part of the pinned region is what the user asked for); two moving groups
sharing a vertex would pull it two ways and are refused.

Examples
--------
>>> import numpy as np
>>> rest = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
>>> rig = make_rig(3, [GroupHandle("Pin", "fixed", np.array([1.0, 0, 0])),
...                    GroupHandle("Tip", "moving", np.array([0.0, 0, 0.5]))])
>>> rig.handles.tolist(), rig.moving_names
([0, 2], ('Tip',))
>>> lift = np.eye(4); lift[2, 3] = 1.0
>>> rig.targets(rest, [lift]).tolist()
[[0.0, 0.0, 0.0], [2.0, 0.0, 1.0]]
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..mesh.model import Mesh
from ..validate import MAX_RINGS, integer, real_array

__all__ = ["HANDLE_KINDS", "GroupHandle", "Rig", "make_rig", "mesh_notes",
           "rings_from_weights"]

#: how a handle group is held: pinned where it is, or carried by an object or a bone
HANDLE_KINDS = ("fixed", "moving")


@dataclass(frozen=True)
class GroupHandle:
    """One handle group as the add-on reads it.

    Attributes
    ----------
    name : str
        The vertex group's name (messages name it).
    kind : {"fixed", "moving"}
    weights : (n,) float
        The group's weight per vertex, 0 where the vertex is not in the group.
    """

    name: str
    kind: str
    weights: np.ndarray


@dataclass(frozen=True)
class Rig:
    """The handles made of the groups, and which moving group carries each.

    Attributes
    ----------
    handles : (h,) int64
        Handle vertices, ascending (what :class:`arapkit.Deformer` takes).
    owner : (h,) int64
        For each handle, the index of the moving group that carries it in
        :attr:`moving_names`, or -1 for a fixed one.
    moving_names : tuple of str
        The moving groups, in the order their motions are given to :meth:`targets`.
    """

    handles: np.ndarray
    owner: np.ndarray
    moving_names: tuple[str, ...]

    def targets(self, rest: np.ndarray, motions: Sequence[np.ndarray]) -> np.ndarray:
        """Where each handle goes: at rest if fixed, else its group's motion applied.

        Parameters
        ----------
        rest : (n, 3)
            The mesh's rest positions (its own coordinates).
        motions : sequence of (4, 4)
            One affine matrix per moving group, in :attr:`moving_names` order.
        """
        M = real_array(motions, "handle motions").reshape(-1, 4, 4)
        if len(M) != len(self.moving_names):
            raise InputError(f"handle motions: expected {len(self.moving_names)} matrices "
                             f"(one per moving group), got {len(M)}")
        if not np.isfinite(M).all():
            bad = int(np.flatnonzero(~np.isfinite(M).all(axis=(1, 2)))[0])
            raise InputError(f"moving group '{self.moving_names[bad]}': its object's "
                             "transform is not finite")
        P = np.asarray(rest, dtype=np.float64)[self.handles]
        T = P.copy()
        for i in range(len(M)):
            sel = self.owner == i
            T[sel] = P[sel] @ M[i, :3, :3].T + M[i, :3, 3]
        return T


def make_rig(n_vertices: int, groups: Sequence[GroupHandle], what: str = "mesh") -> Rig:
    """The handles of ``groups``, checked: one-line messages name the group at fault.

    Refused: no group at all, no fixed group (as Blender's Laplacian Deform needs its
    anchors), a group of no vertices, an unknown kind, weights of the wrong length, a
    vertex in two moving groups.

    Examples
    --------
    >>> import numpy as np
    >>> make_rig(3, [GroupHandle("Tip", "moving", np.array([0.0, 0, 1]))], "Bar")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: Bar: no fixed group (add the vertices that stay put as one)
    >>> make_rig(3, [GroupHandle("Pin", "fixed", np.zeros(3))], "Bar")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: Bar: vertex group 'Pin' is empty (no weight above 0)
    """
    if not groups:
        raise InputError(f"{what}: no handle groups (add a Fixed group of the vertices that "
                         "stay put, and a Moving group driven by an object or a bone)")
    member = []
    for g in groups:
        if g.kind not in HANDLE_KINDS:
            raise InputError(f"{what}: vertex group '{g.name}': kind must be one of "
                             f"{', '.join(HANDLE_KINDS)}, got {g.kind!r:.40}")
        w = real_array(g.weights, f"{what}: vertex group '{g.name}'")
        if w.shape != (n_vertices,):
            raise InputError(f"{what}: vertex group '{g.name}': expected one weight per "
                             f"vertex ({n_vertices}), got shape {w.shape}")
        m = np.nan_to_num(w, nan=0.0) > 0.0
        if not m.any():
            raise InputError(f"{what}: vertex group '{g.name}' is empty (no weight above 0)")
        member.append(m)
    if not any(g.kind == "fixed" for g in groups):
        raise InputError(f"{what}: no fixed group (add the vertices that stay put as one)")
    owner = np.full(n_vertices, -2, dtype=np.int64)  # -2: free, -1: fixed, i: moving group i
    moving: list[str] = []
    for g, m in zip(groups, member):
        if g.kind == "fixed":
            owner[m & (owner == -2)] = -1
            continue
        clash = m & (owner >= 0)
        if clash.any():
            v = int(np.flatnonzero(clash)[0])
            raise InputError(f"{what}: vertex {v} is in two moving groups, "
                             f"'{moving[owner[v]]}' and '{g.name}' (a vertex follows one)")
        owner[m] = len(moving)  # a moving group takes its vertices from a fixed one
        moving.append(g.name)
    handles = np.flatnonzero(owner >= -1)
    return Rig(handles.astype(np.int64), owner[handles], tuple(moving))


def rings_from_weights(weights, r_min: int, r_max: int, what: str = "rigidity") -> np.ndarray:
    """r per vertex from painted weights: 0 paints ``r_min``, 1 paints ``r_max``.

    In between, ``r = rint(r_min + w (r_max - r_min))``; weights are clipped to [0, 1]
    (Weight Paint's range) and a vertex outside the group has weight 0.

    Examples
    --------
    >>> rings_from_weights([0.0, 0.5, 1.0, 2.0], 1, 5).tolist()
    [1, 3, 5, 5]
    """
    lo = integer(r_min, f"{what}: r at weight 0", lo=1, hi=MAX_RINGS)
    hi = integer(r_max, f"{what}: r at weight 1", lo=1, hi=MAX_RINGS)
    w = np.clip(np.nan_to_num(real_array(weights, what), nan=0.0), 0.0, 1.0)
    return np.rint(lo + w * (hi - lo)).astype(np.int32)


def mesh_notes(mesh: Mesh, polygons: int = 0) -> tuple[str, ...]:
    """What the report says about a Blender mesh as it is solved, most important first.

    The library's repairs (:attr:`arapkit.Mesh.notes`: dropped faces, loose vertices kept
    fixed), then non-manifold edges (solved as they are: the energy needs no manifold),
    then ``polygons``, the faces with more than three corners, which the add-on solves as
    Blender's own triangles (its triangulation handles concave n-gons).

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    >>> mesh_notes(Mesh(V[:3], [[0, 1, 2]]), polygons=2)
    ("2 quad(s) or n-gon(s) solved as Blender's triangles",)
    >>> fan = Mesh(V, [[0, 1, 2], [0, 1, 3], [0, 1, 4]])
    >>> mesh_notes(fan)
    ('1 non-manifold edge(s) (more than two faces): solved as they are',)
    """
    out = list(mesh.notes)
    bad = mesh.n_nonmanifold_edges
    if bad:
        out.append(f"{bad} non-manifold edge(s) (more than two faces): solved as they are")
    if polygons:
        out.append(f"{polygons} quad(s) or n-gon(s) solved as Blender's triangles")
    return tuple(out)
