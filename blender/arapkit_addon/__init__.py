"""ARAP Deform for Blender: bend a mesh with handle groups and a painted rigidity map.

A thin shell over arapkit (bundled as wheels in the extension): properties on the mesh
object (:mod:`.props`), operators (:mod:`.ops`), the panel (:mod:`.ui`) and the glue that
reads the object and writes the "ARAP Deform" shape key (:mod:`.engine`); the solving is
:mod:`arapkit.blender`'s, on a background thread. Handlers keep a bound mesh following its
handle objects: a moved object re-solves at once (depsgraph update), an animation frame too
(and waits for the solve where nobody watches: rendering, ``blender -b``).
"""

from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from . import engine, ops, props, ui

_rendering = False


@persistent
def _on_depsgraph(scene, depsgraph) -> None:
    for obj in engine.bound_objects():
        engine.sync(obj)


@persistent
def _on_frame(scene, depsgraph=None) -> None:
    blocking = bpy.app.background or _rendering
    for obj in engine.bound_objects():
        if engine.sync(obj, exact=blocking) and blocking:
            engine.wait(obj)


@persistent
def _render_starts(scene, depsgraph=None) -> None:
    global _rendering
    _rendering = True


@persistent
def _render_ends(scene, depsgraph=None) -> None:
    global _rendering
    _rendering = False


@persistent
def _on_load(*_args) -> None:
    engine.stop_all()


_HANDLERS = (
    (bpy.app.handlers.depsgraph_update_post, _on_depsgraph),
    (bpy.app.handlers.frame_change_post, _on_frame),
    (bpy.app.handlers.render_init, _render_starts),
    (bpy.app.handlers.render_complete, _render_ends),
    (bpy.app.handlers.render_cancel, _render_ends),
    (bpy.app.handlers.load_pre, _on_load),
)


def register() -> None:
    props.register()
    for cls in (*ops.CLASSES, *ui.CLASSES):
        bpy.utils.register_class(cls)
    for handlers, fn in _HANDLERS:
        if fn not in handlers:
            handlers.append(fn)


def unregister() -> None:
    engine.stop_all()
    for handlers, fn in _HANDLERS:
        if fn in handlers:
            handlers.remove(fn)
    for cls in reversed((*ops.CLASSES, *ui.CLASSES)):
        bpy.utils.unregister_class(cls)
    props.unregister()
