"""ARAP Deform for Blender: bend a mesh with handle groups and a painted rigidity map.

A thin shell over arapkit (bundled as wheels in the extension): properties on the mesh
object (:mod:`.props`), operators (:mod:`.ops`), the panel (:mod:`.ui`) and the glue that
reads the object and writes the "ARAP Deform" shape key (:mod:`.engine`); the solving is
:mod:`arapkit.blender`'s, on a background thread. Handlers keep a bound mesh following its
handle objects: a moved object re-solves at once (depsgraph update), an animation frame too
(and waits for the solve where nobody watches: rendering, ``blender -b``).
"""

from __future__ import annotations

import os

import bpy
from bpy.app.handlers import persistent


def _numba_cache() -> None:
    """Keep numba's compiled kernels in this extension's user folder (Blender's place for
    an extension's files; its own folder may be read-only and is replaced on update), so
    they compile once, not in every session. Set before arapkit imports numba; a cache
    folder chosen by the user (NUMBA_CACHE_DIR) is kept."""
    if "NUMBA_CACHE_DIR" in os.environ:
        return
    try:
        folder = bpy.utils.extension_path_user(__package__, path="numba-cache", create=True)
    except (ValueError, AttributeError):  # not installed as an extension (a test's import)
        return
    os.environ["NUMBA_CACHE_DIR"] = folder


_numba_cache()

from . import engine, ops, props, ui  # noqa: E402 - after the cache folder is set

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
