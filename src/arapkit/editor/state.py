"""Editor state without any user interface: selection, handles, rigidity paint, undo.

Everything the browser editor does to the model goes through :class:`EditorState`, so it
can be unit-tested without a server or a browser.  Geometry and solving stay in the
library; this module only keeps track of *what the user asked for*: which vertices are
handles, where their gizmos are, which ``r`` each vertex has, and the undo history.

Conventions
-----------
* ``state.vertices`` is the shape currently shown (the last solver result); selection,
  brush and picking measure distances on it, because that is what the user sees.
* ``state.rings`` is never modified in place: every operation assigns a new array, so
  undo snapshots can share arrays instead of copying 37K integers per step.
* A handle stores the positions of its vertices when it was created (``anchor``) and
  a gizmo pose (rotation ``wxyz`` + ``position``, the gizmo starts at the anchor
  centroid).  Its targets are ``R(wxyz) @ (anchor - pivot) + position``.

Examples
--------
>>> from arapkit.mesh.shapes import bar
>>> st = EditorState(bar())
>>> sel = st.select_near(st.vertices[0], radius=0.05)
>>> h = st.add_handle()
>>> st.move_handle(h.name, position=h.position + [0.0, 0.0, 0.1])
True
>>> idx, tgt = st.constraints()
>>> bool(abs(tgt[:, 2] - st.vertices[idx, 2]).max() > 0.09)
True
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from arapkit import validate
from arapkit.arap.domains import domain_of
from arapkit.editor import session as session_file
from arapkit.editor.geometry import (  # raycast, quat_to_matrix: kept at their old path
    CameraView,
    in_screen_rect,
    nearest_vertex,
    quat_to_matrix,
    raycast,
    vertex_normals,
    vertices_within,
)
from arapkit.editor.groups import PaintedGroups
from arapkit.editor.handles import Handle
from arapkit.editor.session import SESSION_FORMAT, SESSION_VERSION
from arapkit.editor.settings import METHODS, SolverSettings
from arapkit.errors import InputError
from arapkit.mesh.selection import connected_region

__all__ = ["METHODS", "MAX_UNDO", "SESSION_FORMAT", "SESSION_VERSION", "CameraView",
           "EditorState", "Handle", "SolverSettings", "quat_to_matrix", "raycast",
           "vertex_normals"]

MAX_UNDO = 200


@dataclasses.dataclass(frozen=True)
class _Snapshot:
    handles: tuple[Handle, ...]
    rings: np.ndarray
    groups: PaintedGroups | None = None


# --------------------------------------------------------------------------- editor state


class EditorState:
    """Model of one editing session (mesh, handles, rigidity map, undo history).

    Parameters
    ----------
    mesh : arapkit.Mesh
    rings : int or (n,) ints, initial rigidity map.
    mesh_path : file the mesh came from (stored in saved sessions), if any.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> st = EditorState(bar(), rings=2)
    >>> int(st.rings.min()), int(st.rings.max())
    (2, 2)
    """

    def __init__(self, mesh: Any, rings: int | np.ndarray = 1, mesh_path: str | None = None):
        self.mesh = mesh
        self.mesh_path = None if mesh_path is None else str(mesh_path)
        self.vertices = np.array(mesh.vertices, dtype=np.float64)
        self.rings = self.check_rings(rings)
        #: painted rigid parts and shared-rotation groups (never changed in place)
        self.groups = PaintedGroups.empty(self.n)
        self.handles: list[Handle] = []
        self.selection = np.zeros(0, dtype=np.int64)
        # the shape's own weighting: a point cloud's kinds are not a mesh's
        self.settings = SolverSettings(weights=domain_of(mesh).default_weights)
        self._undo: list[_Snapshot] = []
        self._redo: list[_Snapshot] = []
        self._name_counter = 0

    # ---------------------------------------------------------------- basics
    @property
    def n(self) -> int:
        return int(self.mesh.n_vertices)

    def check_rings(self, rings: int | np.ndarray, source: str = "rings") -> np.ndarray:
        """r for every vertex of this mesh by the library's one rule
        (:func:`arapkit.validate.ring_sizes`), as for the command line and rings files."""
        return validate.ring_sizes(rings, self.n, source)

    def clear_history(self) -> None:
        """Forget the undo history (start-up choices are not undoable edits)."""
        self._undo.clear()
        self._redo.clear()

    # ---------------------------------------------------------------- undo / redo
    def _snapshot(self) -> _Snapshot:
        return _Snapshot(tuple(h.copy() for h in self.handles), self.rings, self.groups)

    def _restore(self, snap: _Snapshot) -> None:
        self.handles = [h.copy() for h in snap.handles]
        self.rings = snap.rings
        self.groups = snap.groups

    def checkpoint(self) -> None:
        """Record the current handles and rings as one undo step (drops the redo list)."""
        self._undo.append(self._snapshot())
        del self._undo[:-MAX_UNDO]
        self._redo.clear()

    def _is_current(self, snap: _Snapshot) -> bool:
        """``snap`` is what the state already is: going back to it would change nothing."""
        return ((snap.rings is self.rings or np.array_equal(snap.rings, self.rings))
                and (snap.groups is self.groups
                     or (snap.groups.specs == self.groups.specs
                         and np.array_equal(snap.groups.ids, self.groups.ids)))
                and len(snap.handles) == len(self.handles)
                and all(a.same_as(b) for a, b in zip(snap.handles, self.handles,
                                                      strict=True)))

    def _step(self, source: list[_Snapshot], target: list[_Snapshot]) -> bool:
        # steps that changed nothing (a gizmo grabbed and let go in place, a value set to
        # what it was) are dropped: every Undo click changes what the user sees
        while source and self._is_current(source[-1]):
            source.pop()
        if not source:
            return False
        target.append(self._snapshot())
        self._restore(source.pop())
        return True

    def undo(self) -> bool:
        """Go back one step that changes something; ``False`` when there is none."""
        return self._step(self._undo, self._redo)

    def redo(self) -> bool:
        """Re-apply the last undone step; ``False`` when there is nothing to redo."""
        return self._step(self._redo, self._undo)

    @property
    def can_undo(self) -> bool:
        # from the top: the last step is nearly always a real one, so one comparison
        return any(not self._is_current(s) for s in reversed(self._undo))

    @property
    def can_redo(self) -> bool:
        return any(not self._is_current(s) for s in reversed(self._redo))

    # ---------------------------------------------------------------- selection
    def _combine(self, idx: np.ndarray, mode: str) -> np.ndarray:
        idx = np.unique(np.asarray(idx, dtype=np.int64))
        if mode == "replace":
            self.selection = idx
        elif mode == "add":
            self.selection = np.union1d(self.selection, idx)
        elif mode == "remove":
            self.selection = np.setdiff1d(self.selection, idx)
        else:
            raise ValueError(f"selection mode {mode!r}: expected replace, add or remove")
        return self.selection

    def vertices_near(self, point: np.ndarray, radius: float) -> np.ndarray:
        """Vertices of the shown shape within ``radius`` of ``point`` (Euclidean)."""
        return vertices_within(self.vertices, point, radius)

    def nearest_vertex(self, point: np.ndarray) -> int:
        """Index of the shown vertex closest to ``point``."""
        return nearest_vertex(self.vertices, point)

    def select_near(self, point: np.ndarray, radius: float, mode: str = "add") -> np.ndarray:
        """Select the vertices within ``radius`` of ``point`` (at least the nearest one)."""
        idx = self.vertices_near(point, radius)
        if idx.size == 0:
            idx = np.array([self.nearest_vertex(point)])
        return self._combine(idx, mode)

    def select_in_rect(
        self,
        camera: CameraView,
        screen_min: Sequence[float],
        screen_max: Sequence[float],
        mode: str = "add",
        front_only: bool = True,
    ) -> np.ndarray:
        """Select the vertices whose projection falls inside a screen rectangle.

        ``front_only`` keeps only the vertices facing the camera (see
        :func:`arapkit.editor.geometry.in_screen_rect`).
        """
        faces = self.mesh.faces  # None for a point cloud: no facing test
        inside = in_screen_rect(camera, self.vertices, None if faces is None else
                                np.asarray(faces), screen_min, screen_max, front_only)
        return self._combine(np.flatnonzero(inside), mode)

    def clear_selection(self) -> None:
        self.selection = np.zeros(0, dtype=np.int64)

    # ---------------------------------------------------------------- handles
    def handle(self, name: str) -> Handle:
        for h in self.handles:
            if h.name == name:
                return h
        raise KeyError(f"no handle named {name!r}")

    def _fresh_name(self) -> str:
        names = {h.name for h in self.handles}
        while True:
            self._name_counter += 1
            name = f"handle-{self._name_counter}"
            if name not in names:
                return name

    def add_handle(
        self, vertices: np.ndarray | None = None, name: str | None = None, frozen: bool = False
    ) -> Handle:
        """Make a handle from ``vertices`` (default: the selection) and clear the selection.

        A vertex belongs to at most one handle: vertices already in another handle move
        to the new one, and a handle left empty is removed.
        """
        idx = np.unique(np.asarray(self.selection if vertices is None else vertices, np.int64))
        if idx.size == 0:
            raise InputError("new handle: no vertices selected")
        if idx.min() < 0 or idx.max() >= self.n:
            raise InputError(f"new handle: vertex index out of range 0..{self.n - 1}")
        if name is not None and any(h.name == name for h in self.handles):
            raise InputError(f"new handle: the name {name!r} is taken")
        self.checkpoint()
        self._steal(idx)
        h = Handle.create(name or self._fresh_name(), idx, self.vertices[idx])
        h.frozen = frozen
        self.handles.append(h)
        self.clear_selection()
        return h

    def _steal(self, idx: np.ndarray) -> None:
        kept = []
        for h in self.handles:
            keep = ~np.isin(h.vertices, idx)
            if keep.all():
                kept.append(h)
            elif keep.any():
                # Keep the remaining vertices where their targets currently are.
                t = h.targets()[keep]
                h2 = Handle.create(h.name, h.vertices[keep], t)
                h2.frozen = h.frozen
                kept.append(h2)
        self.handles = kept

    def remove_handle(self, name: str) -> None:
        """Delete a handle; its vertices become free."""
        h = self.handle(name)
        self.checkpoint()
        self.handles = [x for x in self.handles if x is not h]

    def rename_handle(self, name: str, new_name: str) -> None:
        new_name = new_name.strip()
        if not new_name:
            raise InputError("rename handle: the new name is empty")
        if new_name == name:
            return
        if new_name != name and any(h.name == new_name for h in self.handles):
            raise InputError(f"rename handle: the name {new_name!r} is taken")
        h = self.handle(name)
        self.checkpoint()
        h.name = new_name

    def set_frozen(self, name: str, frozen: bool) -> None:
        """A frozen handle keeps its vertices where they are; its gizmo is disabled."""
        h = self.handle(name)
        if h.frozen == bool(frozen):
            return
        self.checkpoint()
        h.frozen = bool(frozen)

    def move_handle(
        self,
        name: str,
        wxyz: Sequence[float] | np.ndarray | None = None,
        position: Sequence[float] | np.ndarray | None = None,
        record: bool = True,
    ) -> bool:
        """Set a handle's gizmo pose.  Returns ``False`` (and does nothing) when frozen.

        Use ``record=False`` for the updates of a drag whose start already called
        :meth:`checkpoint`, so a whole drag is one undo step.
        """
        h = self.handle(name)
        if h.frozen:
            return False
        # checked before anything changes: a bad pose leaves the handle as it was
        q = None if wxyz is None else validate.quaternion(list(wxyz), f"handle {name!r}: wxyz")
        p = None if position is None else validate.vec3(list(position),
                                                         f"handle {name!r}: position")
        if record:
            self.checkpoint()
        if q is not None:
            h.wxyz = q
        if p is not None:
            h.position = p
        return True

    def add_handle_set(self, handle_set: Any, record: bool = True) -> list[Handle]:
        """Add the groups of an :class:`arapkit.mesh.selection.HandleSet` (e.g. ``--handles``).

        A group's targets become the new handle's anchor, so its gizmo starts where the
        file put it; ``fixed`` groups come in frozen.
        """
        if record:
            self.checkpoint()
        added = []
        for g in handle_set.groups:
            name = g.name if all(h.name != g.name for h in self.handles) else self._fresh_name()
            self._steal(np.asarray(g.indices))
            h = Handle.create(name, g.indices, g.targets)
            h.frozen = g.kind == "fixed"
            self.handles.append(h)
            added.append(h)
        return added

    def handle_indices(self) -> np.ndarray:
        """All handle vertices in handle order (the handle set given to the solver)."""
        if not self.handles:
            return np.zeros(0, dtype=np.int64)
        return np.concatenate([h.vertices for h in self.handles])

    def constraints(self) -> tuple[np.ndarray, np.ndarray]:
        """``(indices, targets)`` for the solver, in handle order."""
        if not self.handles:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
        return self.handle_indices(), np.concatenate([h.targets() for h in self.handles])

    # ---------------------------------------------------------------- rigidity
    def set_global_rings(self, r: int, record: bool = True) -> None:
        """Give every vertex the same ``r`` (``record=False``: as part of the last undo
        step, e.g. a slider gesture applied in two pieces)."""
        new = self.check_rings(validate.ring_size(r, "global r"))
        if record:
            self.checkpoint()
        self.rings = new

    def restore_rings(self, rings: np.ndarray) -> None:
        """Go back to the map ``rings`` (a cancelled build's), as an undoable step."""
        self.load_rings(rings)

    def load_rings(self, rings: np.ndarray) -> None:
        """Replace the rigidity map (e.g. a learned rings file)."""
        new = self.check_rings(rings)
        self.checkpoint()
        self.rings = new

    def paint(self, point: np.ndarray, radius: float, r: int, record: bool = True) -> int:
        """Brush: set ``r`` on the vertices within ``radius`` of ``point``.

        Returns the number of vertices whose value changed.  Use ``record=False`` for the
        dabs after the first one of a stroke.
        """
        idx = self.vertices_near(point, radius)
        if idx.size == 0:
            idx = np.array([self.nearest_vertex(point)])
        return self._assign(idx, r, record)

    def flood_fill(self, seed: int, r: int, record: bool = True) -> int:
        """Paint bucket: set ``r`` on the edge-connected region of equal ``r`` around ``seed``.

        Returns the number of vertices in the filled region.
        """
        region = self.fill_region(seed)
        self._assign(region, r, record)
        return int(region.size)

    def fill_region(self, seed: int) -> np.ndarray:
        """Vertices reachable from ``seed`` through edges whose ends both have its ``r``."""
        if not 0 <= seed < self.n:
            raise InputError(f"flood fill: vertex {seed} out of range 0..{self.n - 1}")
        # a point cloud links its points by its graph's edges
        links = self.mesh.faces if self.mesh.faces is not None else self.mesh.edges
        return connected_region(links, self.rings == self.rings[seed], seed)

    def _assign(self, idx: np.ndarray, r: int, record: bool) -> int:
        r = validate.ring_size(r, "paint r")
        changed = int(np.count_nonzero(self.rings[idx] != r))
        if changed == 0:
            return 0
        if record:
            self.checkpoint()
        new = self.rings.copy()
        new[idx] = r
        self.rings = new
        return changed

    # ---------------------------------------------------------------- groups
    def new_group(self, rigid: bool, name: str | None = None) -> int:
        """Add an empty group (a rigid part, or a shared-rotation group); its index."""
        groups, g = self.groups.with_group(rigid, name)
        self.checkpoint()
        self.groups = groups
        return g

    def paint_group(self, point: np.ndarray, radius: float, g: int,
                    record: bool = True) -> int:
        """Part brush: put the vertices within ``radius`` of ``point`` in group ``g`` (-1:
        in none). Returns the number of vertices that changed group; ``record=False`` for
        the dabs after a stroke's first.

        Examples
        --------
        >>> from arapkit.mesh.shapes import bar
        >>> st = EditorState(bar())
        >>> g = st.new_group(rigid=True)
        >>> st.paint_group(st.vertices[0], 0.2, g) > 0, st.groups.vertex_groups().names
        (True, ('part 1',))
        """
        idx = self.vertices_near(point, radius)
        if idx.size == 0:
            idx = np.array([self.nearest_vertex(point)])
        changed = int(np.count_nonzero(self.groups.ids[idx] != g))
        if changed:
            new = self.groups.painted(idx, g)  # checked before the undo step
            if record:
                self.checkpoint()
            self.groups = new
        return changed

    def remove_group(self, g: int) -> None:
        """Delete group ``g``; its vertices are in no group."""
        new = self.groups.without(g)
        self.checkpoint()
        self.groups = new

    def load_groups(self, groups: Any) -> None:
        """Replace the painted groups by a :class:`~arapkit.mesh.groups.VertexGroups`."""
        if groups.n_vertices != self.n:
            raise InputError(f"{groups.source}: groups of {groups.n_vertices} vertices for a "
                             f"mesh of {self.n}")
        self.checkpoint()
        self.groups = PaintedGroups.of(groups)

    # ---------------------------------------------------------------- sessions
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready session: mesh path, handles (with targets), rings, solver settings."""
        idx, tgt = self.constraints()
        return {
            "format": SESSION_FORMAT,
            "version": SESSION_VERSION,
            "mesh": self.mesh_path,
            "mesh_name": getattr(self.mesh, "name", None),
            "n_vertices": self.n,
            "handles": [h.to_dict() for h in self.handles],
            "handle_indices": idx.tolist(),
            "targets": tgt.tolist(),
            "rings": self.rings.tolist(),
            "groups": self.groups.to_json(),
            "solver": self.settings.to_dict(),
            # a session on a welded mesh indexes the welded vertices: reopening welds again
            "weld": (None if getattr(self.mesh, "welded_from", None) is None
                     else self.mesh.welded_from.tol),
            # a cloud's graph (k or a radius) decides its solve: reopening builds the same
            "graph": session_file.graph_of(self.mesh),
        }

    def apply_dict(self, d: dict[str, Any], record: bool = True) -> None:
        """Load handles, rings and settings from a session dict made for this mesh.

        Everything is checked before anything changes, so a bad session leaves the editor
        as it was.  Method names of older sessions are read (see :class:`SolverSettings`).
        """
        session_file.check_header(d, self.n)
        raw = d.get("handles", [])
        if not isinstance(raw, list):
            raise InputError(f"session: 'handles' must be a list, got {type(raw).__name__}")
        handles = [Handle.from_dict(h, self.n) for h in raw]
        names = [h.name for h in handles]
        if len(set(names)) != len(names):
            raise InputError("session: two handles have the same name")
        all_idx = np.concatenate([h.vertices for h in handles]) if handles else np.zeros(0)
        if np.unique(all_idx).size != all_idx.size:
            raise InputError("session: a vertex belongs to two handles")
        rings = self.check_rings(d["rings"], "session rings") if "rings" in d else self.rings
        groups = (PaintedGroups.from_json(d["groups"], self.n) if "groups" in d
                  else PaintedGroups.empty(self.n))
        settings = SolverSettings.from_dict(d.get("solver", {}))
        if record:
            self.checkpoint()
        self.handles, self.rings, self.settings = handles, rings, settings
        self.groups = groups

    def save_session(self, path: str | os.PathLike[str]) -> Path:
        """Write the session as JSON (atomically: a crash never leaves half a file)."""
        return session_file.write_session(path, self.to_dict())

    @staticmethod
    def read_session(path: str | os.PathLike[str]) -> dict[str, Any]:
        """Parse a session file, with a one-line error for a bad one."""
        return session_file.read_session(path)

    @classmethod
    def from_session(cls, path: str | os.PathLike[str]) -> EditorState:
        """Load the mesh named in a session file (relative to the file) and apply it."""
        from arapkit.io import load_shape

        d = cls.read_session(path)
        mesh_path = d.get("mesh")
        if not mesh_path:
            raise InputError(f"{path}: the session names no mesh file")
        if not isinstance(mesh_path, str) or "\0" in mesh_path:
            raise InputError(f"{path}: 'mesh' must be a file name, got {mesh_path!r:.60}")
        mesh_file = Path(path).parent / mesh_path
        # a mesh, or a point cloud on the graph the session was made with
        mesh = load_shape(str(mesh_file), **session_file.graph_options(d, str(path)))
        if d.get("weld") is not None:
            from arapkit.mesh.welding import weld

            mesh = weld(mesh, d["weld"])
        st = cls(mesh, mesh_path=str(mesh_file))
        st.apply_dict(d, record=False)
        return st
