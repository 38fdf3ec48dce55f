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
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order

from arapkit import validate
from arapkit.arap.energies.base import offered_by
from arapkit.errors import InputError
from arapkit.mesh.weights import DEFAULT_WEIGHTS, WEIGHT_KINDS

SESSION_FORMAT = "arapkit-editor-session"
SESSION_VERSION = 1
#: solver-panel methods: "arap" is r-ring ARAP with the painted map, the others name
#: :data:`arapkit.arap.energies.base.ENERGIES` (no rigidity map) or Laplacian editing
#: (r-ring ARAP is "arap": it takes the painted map)
METHODS = ("arap", "laplacian", *(e for e in offered_by("editor") if e != "rring"),
           "volumetric")
MAX_UNDO = 200


# --------------------------------------------------------------------------- geometry helpers


def quat_to_matrix(wxyz: Sequence[float] | np.ndarray) -> np.ndarray:
    """Rotation matrix of a (not necessarily unit) quaternion ``(w, x, y, z)``.

    Examples
    --------
    >>> np.allclose(quat_to_matrix([1, 0, 0, 0]), np.eye(3))
    True
    """
    w, x, y, z = np.asarray(wxyz, dtype=np.float64) / np.linalg.norm(wxyz)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


@dataclasses.dataclass(frozen=True)
class CameraView:
    """A pinhole camera as the browser reports it (OpenCV axes: +z forward, +y down).

    Parameters
    ----------
    position : (3,) camera centre in world coordinates.
    wxyz : (4,) camera-to-world rotation.
    fov : vertical field of view in radians.
    aspect : canvas width / height.

    Examples
    --------
    >>> cam = CameraView(np.array([0.0, 0, -5]), np.array([1.0, 0, 0, 0]), 1.0, 1.5)
    >>> uv, depth = cam.project(np.zeros((1, 3)))
    >>> uv.round(3).tolist(), depth.tolist()
    ([[0.5, 0.5]], [5.0])
    """

    position: np.ndarray
    wxyz: np.ndarray
    fov: float
    aspect: float

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Screen coordinates in [0, 1]^2 (origin top left) and depth of ``points``."""
        R = quat_to_matrix(self.wxyz)
        cam = (np.asarray(points, dtype=np.float64) - self.position) @ R
        depth = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            half_h = np.tan(self.fov / 2.0)
            u = 0.5 + cam[:, 0] / depth / (2.0 * half_h * self.aspect)
            v = 0.5 + cam[:, 1] / depth / (2.0 * half_h)
        return np.stack([u, v], axis=1), depth

    def ray(self, screen_pos: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """World-space origin and unit direction of the ray through ``screen_pos``."""
        half_h = np.tan(self.fov / 2.0)
        d_cam = np.array(
            [
                (screen_pos[0] - 0.5) * 2.0 * half_h * self.aspect,
                (screen_pos[1] - 0.5) * 2.0 * half_h,
                1.0,
            ]
        )
        d = quat_to_matrix(self.wxyz) @ d_cam
        return np.asarray(self.position, dtype=np.float64), d / np.linalg.norm(d)


def raycast(
    vertices: np.ndarray, faces: np.ndarray, origin: np.ndarray, direction: np.ndarray
) -> tuple[int, np.ndarray] | None:
    """Nearest face hit by a ray (Moller-Trumbore over all faces, vectorised).

    Returns ``(face_index, hit_point)`` or ``None`` when the ray misses.  Picking is
    the only place the editor needs this, so a brute-force test (a few ms for 70K faces)
    is preferred over building an acceleration structure per shape.

    Examples
    --------
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]); F = np.array([[0, 1, 2]])
    >>> f, p = raycast(V, F, np.array([0.2, 0.2, 1.0]), np.array([0.0, 0, -1]))
    >>> f, p.round(3).tolist()
    (0, [0.2, 0.2, 0.0])
    """
    o = np.asarray(origin, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    e1, e2 = b - a, c - a
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    # parallel-ray test relative to the face's size: picking works at any mesh scale
    size = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1) * np.linalg.norm(d)
    ok = np.abs(det) > 1e-12 * size
    inv = np.zeros_like(det)
    inv[ok] = 1.0 / det[ok]
    s = o - a
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ d) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    if not hit.any():
        return None
    f = int(np.flatnonzero(hit)[np.argmin(t[hit])])
    return f, o + t[f] * d


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (zero for unreferenced vertices)."""
    fn = np.cross(
        vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]
    )
    n = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, norm, out=np.zeros_like(n), where=norm > 0)


# --------------------------------------------------------------------------- data classes


@dataclasses.dataclass
class Handle:
    """One handle region: vertices moved together by one gizmo.

    Examples
    --------
    >>> h = Handle.create("tip", np.array([0, 1]), np.array([[0.0, 0, 0], [2.0, 0, 0]]))
    >>> h.position.tolist()
    [1.0, 0.0, 0.0]
    >>> h.targets().tolist()
    [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]
    """

    name: str
    vertices: np.ndarray  # (k,) int64 vertex indices
    anchor: np.ndarray  # (k, 3) positions when the handle was made
    wxyz: np.ndarray  # gizmo rotation
    position: np.ndarray  # gizmo position; starts at the anchor centroid
    frozen: bool = False

    @classmethod
    def create(cls, name: str, vertices: np.ndarray, anchor: np.ndarray) -> Handle:
        """A handle whose gizmo sits at the centroid of ``anchor`` with no rotation."""
        anchor = np.array(anchor, dtype=np.float64).reshape(-1, 3)
        return cls(
            name=name,
            vertices=np.array(vertices, dtype=np.int64).reshape(-1),
            anchor=anchor,
            wxyz=np.array([1.0, 0.0, 0.0, 0.0]),
            position=anchor.mean(axis=0),
        )

    @property
    def pivot(self) -> np.ndarray:
        """Centre of rotation: the anchor centroid."""
        return self.anchor.mean(axis=0)

    def targets(self) -> np.ndarray:
        """Target positions of the handle vertices for the current gizmo pose."""
        R = quat_to_matrix(self.wxyz)
        return (self.anchor - self.pivot) @ R.T + self.position

    def copy(self) -> Handle:
        # Arrays are replaced, never mutated, so sharing them is safe.
        return dataclasses.replace(self)

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "vertices": self.vertices.tolist(),
            "frozen": self.frozen,
            "anchor": self.anchor.tolist(),
            "wxyz": self.wxyz.tolist(),
            "position": self.position.tolist(),
            "targets": self.targets().tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], n_vertices: int) -> Handle:
        """Inverse of :meth:`to_dict`; a handle given only by targets gets them as anchor.

        Every field is checked with the rules of :mod:`arapkit.validate`; a bad one raises
        :class:`InputError` naming the handle and the field.
        """
        if not isinstance(d, dict):
            raise InputError(f"session handle: expected an object, got {type(d).__name__}")
        name = d.get("name", "handle")
        if not isinstance(name, str) or not name or "\0" in name:
            raise InputError(f"session handle: 'name' must be a non-empty string, got {name!r:.40}")
        where = f"session handle {name!r}"
        if "vertices" not in d:
            raise InputError(f"{where}: no 'vertices'")
        idx = validate.handle_indices(d["vertices"], n_vertices, f"{where}: 'vertices'")
        key = "anchor" if "anchor" in d else "targets"
        if key not in d:
            raise InputError(f"{where}: needs 'anchor' or 'targets'")
        anchor = validate.real_array(d[key], f"{where}: {key!r}")
        if anchor.shape != (idx.size, 3):
            raise InputError(f"{where}: expected {idx.size} {key} rows of 3, got {anchor.shape}")
        validate.check_finite_positions(anchor, f"{where}: {key!r}")
        h = cls.create(name, idx, anchor)
        if "wxyz" in d or "position" in d:
            h.wxyz = validate.quaternion(d.get("wxyz", [1, 0, 0, 0]), f"{where}: 'wxyz'")
            h.position = validate.vec3(d.get("position", h.position.tolist()),
                                       f"{where}: 'position'")
        frozen = d.get("frozen", False)
        if not isinstance(frozen, bool):
            raise InputError(f"{where}: 'frozen' must be true or false, got {frozen!r:.40}")
        h.frozen = frozen
        with np.errstate(over="ignore", invalid="ignore"):
            finite = np.isfinite(h.targets()).all()
        if not finite:
            raise InputError(f"{where}: its targets are beyond double precision (too large)")
        return h


@dataclasses.dataclass
class SolverSettings:
    """What the user chose in the solver panel.

    ``live_budget_ms`` and ``live_max_iter`` bound the work before the first update of
    a drag is sent; the solve then continues to ``tol`` / ``max_iter`` unless a newer
    drag supersedes it.
    """

    method: str = "arap"
    weights: str = DEFAULT_WEIGHTS
    tol: float = 1e-3
    max_iter: int = 200
    live_max_iter: int = 8
    live_budget_ms: float = 60.0

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SolverSettings:
        """Settings from a session's ``solver`` object, each field checked.

        Examples
        --------
        >>> SolverSettings.from_dict({"tol": 1e-4}).tol
        0.0001
        """
        known = [f.name for f in dataclasses.fields(cls)]
        validate.keys_of(d, known, "session solver")
        s = cls(**d)
        if not isinstance(s.method, str) or s.method not in METHODS:
            raise InputError(f"session solver: method {s.method!r:.40}: expected one of {METHODS}")
        if not isinstance(s.weights, str) or s.weights not in WEIGHT_KINDS:
            raise InputError(f"session solver: weights {s.weights!r:.40}: expected one of "
                             f"{', '.join(WEIGHT_KINDS)}")
        s.tol = validate.tolerance(s.tol, "session solver: tol")
        s.max_iter = validate.iteration_cap(s.max_iter, "session solver: max_iter")
        s.live_max_iter = validate.iteration_cap(s.live_max_iter, "session solver: live_max_iter")
        s.live_budget_ms = validate.number(s.live_budget_ms, "session solver: live_budget_ms",
                                           lo=0.0, hi=3.6e6)
        return s


@dataclasses.dataclass(frozen=True)
class _Snapshot:
    handles: tuple[Handle, ...]
    rings: np.ndarray


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
        self.rings = self._check_rings(rings)
        self.handles: list[Handle] = []
        self.selection = np.zeros(0, dtype=np.int64)
        self.settings = SolverSettings()
        self._undo: list[_Snapshot] = []
        self._redo: list[_Snapshot] = []
        self._name_counter = 0

    # ---------------------------------------------------------------- basics
    @property
    def n(self) -> int:
        return int(self.mesh.n_vertices)

    def _check_rings(self, rings: int | np.ndarray, source: str = "rings") -> np.ndarray:
        # the library's one rule (1..MAX_RINGS), as for the command line and rings files
        return validate.ring_sizes(rings, self.n, source).astype(np.int64)

    # ---------------------------------------------------------------- undo / redo
    def _snapshot(self) -> _Snapshot:
        return _Snapshot(tuple(h.copy() for h in self.handles), self.rings)

    def _restore(self, snap: _Snapshot) -> None:
        self.handles = [h.copy() for h in snap.handles]
        self.rings = snap.rings

    def checkpoint(self) -> None:
        """Record the current handles and rings as one undo step (drops the redo list)."""
        self._undo.append(self._snapshot())
        del self._undo[:-MAX_UNDO]
        self._redo.clear()

    def undo(self) -> bool:
        """Go back one step; ``False`` when there is nothing to undo."""
        if not self._undo:
            return False
        self._redo.append(self._snapshot())
        self._restore(self._undo.pop())
        return True

    def redo(self) -> bool:
        """Re-apply the last undone step; ``False`` when there is nothing to redo."""
        if not self._redo:
            return False
        self._undo.append(self._snapshot())
        self._restore(self._redo.pop())
        return True

    @property
    def can_undo(self) -> bool:
        return bool(self._undo)

    @property
    def can_redo(self) -> bool:
        return bool(self._redo)

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
        d2 = np.sum((self.vertices - np.asarray(point, dtype=np.float64)) ** 2, axis=1)
        return np.flatnonzero(d2 <= radius * radius)

    def nearest_vertex(self, point: np.ndarray) -> int:
        """Index of the shown vertex closest to ``point``."""
        d2 = np.sum((self.vertices - np.asarray(point, dtype=np.float64)) ** 2, axis=1)
        return int(np.argmin(d2))

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

        ``front_only`` keeps only vertices whose normal faces the camera, a cheap
        stand-in for an occlusion test that matches what users expect on closed shapes.
        """
        uv, depth = camera.project(self.vertices)
        lo, hi = np.minimum(screen_min, screen_max), np.maximum(screen_min, screen_max)
        inside = (depth > 0) & np.all((uv >= lo) & (uv <= hi), axis=1)
        if front_only:
            nrm = vertex_normals(self.vertices, np.asarray(self.mesh.faces))
            inside &= np.einsum("ij,ij->i", nrm, camera.position - self.vertices) > 0
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
    def set_global_rings(self, r: int) -> None:
        """Give every vertex the same ``r``."""
        new = self._check_rings(validate.ring_size(r, "global r"))
        self.checkpoint()
        self.rings = new

    def load_rings(self, rings: np.ndarray) -> None:
        """Replace the rigidity map (e.g. a learned rings file)."""
        new = self._check_rings(rings)
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
        same = self.rings == self.rings[seed]
        e = np.asarray(self.mesh.edges)
        # Keep only edges whose two ends have the seed's r: the region is one BFS tree.
        e = e[same[e[:, 0]] & same[e[:, 1]]]
        sub = sp.coo_matrix(
            (np.ones(len(e), dtype=np.int8), (e[:, 0], e[:, 1])), shape=(self.n, self.n)
        ).tocsr()
        order = breadth_first_order(sub, seed, directed=False, return_predecessors=False)
        return np.sort(order.astype(np.int64))

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
            "solver": self.settings.to_dict(),
            # a session on a welded mesh indexes the welded vertices: reopening welds again
            "weld": (None if getattr(self.mesh, "welded_from", None) is None
                     else self.mesh.welded_from.tol),
        }

    def apply_dict(self, d: dict[str, Any], record: bool = True) -> None:
        """Load handles, rings and settings from a session dict made for this mesh.

        Everything is checked before anything changes, so a bad session leaves the editor
        as it was.
        """
        if not isinstance(d, dict):
            raise InputError(f"session: expected a JSON object, got {type(d).__name__}")
        if d.get("format") != SESSION_FORMAT:
            raise InputError(
                f"session: not an arapkit editor session (format={d.get('format')!r:.40})")
        n_vertices = d.get("n_vertices", -1)
        if (not isinstance(n_vertices, int) or isinstance(n_vertices, bool)
                or n_vertices != self.n):
            raise InputError(
                f"session: made for a mesh of {n_vertices!r:.40} vertices, "
                f"the loaded mesh has {self.n}"
            )
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
        rings = self._check_rings(d["rings"], "session rings") if "rings" in d else self.rings
        settings = SolverSettings.from_dict(d.get("solver", {}))
        if record:
            self.checkpoint()
        self.handles, self.rings, self.settings = handles, rings, settings

    def save_session(self, path: str | os.PathLike[str]) -> Path:
        """Write the session as JSON (atomically: a crash never leaves half a file)."""
        from arapkit.io import write_json

        path = Path(path)
        write_json(path, self.to_dict(), indent=1)
        return path

    @staticmethod
    def read_session(path: str | os.PathLike[str]) -> dict[str, Any]:
        """Parse a session file, with a one-line error for a bad one."""
        try:
            d = validate.parse_json(validate.read_input(path, "sessions"), str(path))
        except InputError as exc:
            shown = repr(str(path)) if "\0" in str(path) else str(path)  # never print a NUL
            why = str(exc).removeprefix(f"{shown}: ")
            raise InputError(f"{shown}: cannot read session ({why})") from None
        if not isinstance(d, dict):
            raise InputError(f"{path}: a session must be a JSON object")
        return d

    @classmethod
    def from_session(cls, path: str | os.PathLike[str]) -> EditorState:
        """Load the mesh named in a session file (relative to the file) and apply it."""
        from arapkit import load_mesh

        d = cls.read_session(path)
        mesh_path = d.get("mesh")
        if not mesh_path:
            raise InputError(f"{path}: the session names no mesh file")
        if not isinstance(mesh_path, str) or "\0" in mesh_path:
            raise InputError(f"{path}: 'mesh' must be a file name, got {mesh_path!r:.60}")
        mesh_file = Path(path).parent / mesh_path
        mesh = load_mesh(str(mesh_file))
        if d.get("weld") is not None:
            from arapkit.mesh.welding import weld

            mesh = weld(mesh, d["weld"])
        st = cls(mesh, mesh_path=str(mesh_file))
        st.apply_dict(d, record=False)
        return st
