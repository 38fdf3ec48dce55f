"""Blender's side of a deformation: read the object, run a session, write the shape key.

A *session* is one mesh object bound to an :class:`arapkit.blender.LiveDeformer` (the
solver thread). Everything here runs on Blender's main thread and only does what is quick:
reading vertex groups and matrices, handing targets over, writing shapes. The result is a
shape key (:data:`SHAPE_KEY`), so the base mesh, its UVs, materials and attributes are
never touched, and the modifier stack still applies on top.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import bpy
import numpy as np

from arapkit.blender import (
    GroupHandle,
    LiveDeformer,
    Rig,
    make_rig,
    mesh_notes,
    rings_from_weights,
)
from arapkit.blender.settings import takes_rigidity_map
from arapkit.errors import InputError
from arapkit.mesh.model import Mesh

#: the shape key the result is written to (relative to the Basis, value 1)
SHAPE_KEY = "ARAP Deform"
#: a changed setting rebuilds the session once it has not changed again for this long (s)
STALE_S = 0.3


@dataclass
class Session:
    """One bound object: its solver, its rig and what was last asked and written."""

    uid: int
    live: LiveDeformer
    rig: Rig
    rest: np.ndarray
    n_vertices: int
    #: per moving group, in the rig's order: its handle item's index
    movers: list[int]
    last_targets: np.ndarray | None = None
    last_written: int = 0
    #: the last shape written (float64, before the shape key's float32)
    shape: np.ndarray | None = None
    stale_since: float | None = None
    #: the last solve's one-line message (None after a shape was written)
    error: str | None = None
    notes: tuple[str, ...] = field(default_factory=tuple)


_sessions: dict[int, Session] = {}


# ------------------------------------------------------------------------ reading Blender
def rest_positions(obj: bpy.types.Object) -> np.ndarray:
    """The rest shape in the object's own coordinates: the Basis key if there is one."""
    me = obj.data
    n = len(me.vertices)
    co = np.empty(3 * n, dtype=np.float32)
    keys = me.shape_keys
    if keys is not None and keys.reference_key is not None:
        keys.reference_key.points.foreach_get("co", co)
    else:
        me.vertices.foreach_get("co", co)
    return co.reshape(n, 3).astype(np.float64)


def triangles(obj: bpy.types.Object) -> tuple[np.ndarray, int]:
    """Blender's own triangulation of the faces (concave n-gons too), and how many faces
    had more than three corners."""
    me = obj.data
    me.calc_loop_triangles()
    tri = np.empty(3 * len(me.loop_triangles), dtype=np.int32)
    me.loop_triangles.foreach_get("vertices", tri)
    sizes = np.empty(len(me.polygons), dtype=np.int32)
    me.polygons.foreach_get("loop_total", sizes)
    return tri.reshape(-1, 3).astype(np.int64), int((sizes > 3).sum())


def group_weights(obj: bpy.types.Object, names: list[str]) -> dict[str, np.ndarray]:
    """The weight of every vertex in each named group (0 outside it), in one pass."""
    me = obj.data
    index = {}
    for name in names:
        vg = obj.vertex_groups.get(name)
        if vg is None:
            raise InputError(f"{obj.name}: there is no vertex group '{name}'")
        index[vg.index] = name
    out = {name: np.zeros(len(me.vertices)) for name in names}
    for v in me.vertices:
        for g in v.groups:
            name = index.get(g.group)
            if name is not None:
                out[name][v.index] = g.weight
    return out


def _array(m) -> np.ndarray:
    """A Blender matrix as float64 (its float32 entries exactly)."""
    return np.array(m, dtype=np.float64).reshape(4, 4)


def driver_parts(obj: bpy.types.Object, item) -> tuple[np.ndarray, np.ndarray]:
    """The handle's driver now: its object's world matrix and its bone's pose matrix
    (identity without a bone)."""
    target = item.target
    if target is None:
        raise InputError(f"{obj.name}: moving group '{item.group}' has no object to follow")
    if not item.bone:
        return _array(target.matrix_world), np.eye(4)
    pb = target.pose.bones.get(item.bone) if target.pose is not None else None
    if pb is None:
        raise InputError(f"{obj.name}: moving group '{item.group}': '{target.name}' has "
                         f"no bone '{item.bone}'")
    return _array(target.matrix_world), _array(pb.matrix)


def motions(obj: bpy.types.Object, session: Session) -> list[np.ndarray]:
    """Each moving group's motion since it was bound, in the mesh's own coordinates:
    ``O⁻¹ D D_bind⁻¹ O_bind`` (O the mesh object's world matrix, D the driver's)."""
    items = obj.arap_deform.handles
    O_inv = np.linalg.inv(_array(obj.matrix_world))
    out = []
    for i in session.movers:
        item = items[i]
        world, pose = driver_parts(obj, item)
        at_bind = _array(item.bind_driver) @ _array(item.bind_bone)
        out.append(O_inv @ (world @ pose) @ np.linalg.inv(at_bind) @ _array(item.bind_object))
    return out


# ------------------------------------------------------------------------ sessions
def session_of(obj: bpy.types.Object) -> Session | None:
    return _sessions.get(obj.session_uid)


def check_object(obj) -> None:
    """Refuse what no session can run on, in one line."""
    if obj is None or obj.type != "MESH":
        raise InputError("ARAP Deform works on a mesh object: select one")
    if obj.mode == "EDIT":
        raise InputError(f"{obj.name}: leave Edit Mode first (ARAP Deform writes a shape key)")
    if len(obj.data.vertices) == 0:
        raise InputError(f"{obj.name}: the mesh has no vertices")


def bind(obj: bpy.types.Object, reset: bool = False) -> None:
    """Record each moving handle's driver matrix as its rest (``reset``: all of them)."""
    for item in obj.arap_deform.handles:
        if item.kind == "MOVING" and item.target is not None and (reset or not item.bound):
            world, pose = driver_parts(obj, item)
            item.bind_object = tuple(_array(obj.matrix_world).ravel())
            item.bind_driver, item.bind_bone = tuple(world.ravel()), tuple(pose.ravel())
            item.bound = True


def start(obj: bpy.types.Object) -> Session:
    """Read ``obj``, start its solver and ask for the exact solve of the current pose.

    Raises InputError (one line, naming the object and group) for what cannot be solved.
    """
    check_object(obj)
    s = obj.arap_deform
    stop(obj)
    bind(obj)
    rest = rest_positions(obj)
    F, polys = triangles(obj)
    if len(F) == 0:
        raise InputError(f"{obj.name}: the mesh has no faces (ARAP bends a surface)")
    items = list(s.handles)
    for item in items:
        if not item.group:
            raise InputError(f"{obj.name}: a handle has no vertex group (pick one)")
    uses_r = takes_rigidity_map(s.method) and s.rigidity == "GROUP"
    if uses_r and not s.rigidity_group:
        raise InputError(f"{obj.name}: Rigidity is Painted but no rigidity group is chosen")
    names = sorted({i.group for i in items} | ({s.rigidity_group} if uses_r else set()))
    weights = group_weights(obj, names)
    groups = [GroupHandle(i.group, "fixed" if i.kind == "FIXED" else "moving",
                          weights[i.group]) for i in items]
    rig = make_rig(len(rest), groups, obj.name)
    # the moving groups in the rig's order, each with its handle item
    movers = [next(k for k, i in enumerate(items) if i.group == name and i.kind == "MOVING")
              for name in rig.moving_names]
    for k in movers:
        driver_parts(obj, items[k])  # a missing object or bone is said now, not later
    if not takes_rigidity_map(s.method):
        rings = 1
    elif uses_r:
        rings = rings_from_weights(weights[s.rigidity_group], s.r_min, s.r_max,
                                   f"{obj.name}: rigidity group '{s.rigidity_group}'")
    else:
        rings = int(s.r)
    mesh = Mesh(rest, F, name=obj.name)
    live = LiveDeformer(mesh, rig.handles, rings, method=s.method, weights=s.weights,
                        tol=s.tol, max_iter=s.max_iter)
    session = Session(obj.session_uid, live, rig, rest, len(rest), movers,
                      notes=mesh_notes(mesh, polys))
    _sessions[obj.session_uid] = session
    s.live = True
    s.status = "solving"
    sync(obj, exact=True)
    ensure_timer()
    return session


def stop(obj: bpy.types.Object) -> None:
    """End ``obj``'s session (the shape key stays as it is)."""
    session = _sessions.pop(obj.session_uid, None)
    if session is not None:
        session.live.close(timeout=0.0)  # never wait on Blender's thread: it ends by itself
    if hasattr(obj, "arap_deform"):
        obj.arap_deform.live = False


def stop_all() -> None:
    for session in _sessions.values():
        session.live.close(timeout=0.0)
    _sessions.clear()


def mark_stale(obj: bpy.types.Object) -> None:
    session = _sessions.get(obj.session_uid)
    if session is not None:
        session.stale_since = time.monotonic()


def sync(obj: bpy.types.Object, exact: bool = False) -> bool:
    """Hand the handles' current targets to the solver if they changed; True if asked."""
    session = _sessions.get(obj.session_uid)
    if session is None:
        return False
    try:
        T = session.rig.targets(session.rest, motions(obj, session))
    except InputError as exc:
        obj.arap_deform.status = str(exc)
        return False
    if not exact and session.last_targets is not None and np.array_equal(T, session.last_targets):
        return False
    session.last_targets = T
    session.live.request(T, exact=exact)
    return True


def write_shape(obj: bpy.types.Object, V: np.ndarray) -> None:
    """Write ``V`` into the ARAP Deform shape key (made, with a Basis, if missing)."""
    me = obj.data
    if me.shape_keys is None:
        obj.shape_key_add(name="Basis", from_mix=False)
    kb = me.shape_keys.key_blocks.get(SHAPE_KEY)
    if kb is None:
        kb = obj.shape_key_add(name=SHAPE_KEY, from_mix=False)
        kb.value = 1.0
    # ShapeKey.points (Blender 4.1+) is the key's array as it is: 0.07 ms at 50K vertices,
    # where ShapeKey.data goes point by point (12 ms, most of a frame)
    kb.points.foreach_set("co", np.asarray(V, dtype=np.float32).ravel())
    me.update()


def take(obj: bpy.types.Object, session: Session) -> bool:
    """Write the solver's newest shape, if any; True if one was written."""
    return show(obj, session, session.live.poll())


def show(obj: bpy.types.Object, session: Session, shape) -> bool:
    """Write ``shape`` (an :class:`arapkit.blender.Shape`) or its message; True if written."""
    if shape is None:
        return False
    s = obj.arap_deform
    if shape.error is not None:
        s.status = session.error = shape.error
        return False
    session.error = None
    if obj.mode == "EDIT":
        s.status = "leave Edit Mode to see the result"
        return False
    write_shape(obj, shape.vertices)
    session.shape = shape.vertices
    session.last_written = shape.seq
    notes = session.notes + shape.notes
    if shape.exact:
        s.status = "; ".join((f"{'converged' if shape.converged else 'stopped'} in "
                              f"{shape.iterations} iterations, {shape.elapsed_ms:.0f} ms",
                              *notes))
    elif shape.converged:  # a drag's last pose, solved on from the last shape
        s.status = f"converged (following the handles, {shape.iterations} iterations)"
    else:
        s.status = "following the handles"
    return True


def bound_objects() -> list[bpy.types.Object]:
    """The objects that have a session now."""
    return [obj for obj in map(find, list(_sessions)) if obj is not None]


def find(uid: int) -> bpy.types.Object | None:
    for obj in bpy.data.objects:
        if obj.session_uid == uid:
            return obj
    return None


def pump() -> int:
    """Blender's timer: write new shapes, rebuild stale sessions, drop orphaned ones.

    Returns how many shapes it wrote.
    """
    now = time.monotonic()
    written = 0
    for uid, session in list(_sessions.items()):
        obj = find(uid)
        if obj is None or obj.type != "MESH":
            session.live.close(timeout=0.0)
            del _sessions[uid]
            continue
        if not obj.arap_deform.live:  # an undo went back to before Deform
            stop(obj)
            continue
        if len(obj.data.vertices) != session.n_vertices:
            stop(obj)
            obj.arap_deform.status = "the mesh changed: press Deform again"
            continue
        if session.stale_since is not None and now - session.stale_since >= STALE_S:
            try:
                start(obj)
            except InputError as exc:
                stop(obj)
                obj.arap_deform.status = str(exc)
            continue
        written += take(obj, session)
    return written


def wait(obj: bpy.types.Object, timeout: float | None = None) -> bool:
    """Block until ``obj``'s solver is idle and write its shape (scripts, ``blender -b``)."""
    session = _sessions.get(obj.session_uid)
    if session is None:
        return False
    return show(obj, session, session.live.wait(timeout))


# ------------------------------------------------------------------------ the timer
def _tick() -> float | None:
    try:
        pump()
    except Exception as exc:  # a timer that raises is unregistered by Blender: keep it
        print(f"arapkit: {type(exc).__name__}: {exc}")
    if not _sessions:
        return None
    return 1.0 / 60.0


def ensure_timer() -> None:
    if not bpy.app.timers.is_registered(_tick):
        bpy.app.timers.register(_tick, first_interval=0.0, persistent=True)
