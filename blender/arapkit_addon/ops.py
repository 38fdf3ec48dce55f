"""The add-on's operators: deform, stop, rebind, and the handle list's add and remove."""

from __future__ import annotations

import bpy

from arapkit.errors import InputError

from . import engine


def _mesh_object(context):
    obj = context.object
    return obj if obj is not None and obj.type == "MESH" else None


class ARAPKIT_OT_deform(bpy.types.Operator):
    """Solve ARAP for the handles' current pose into the "ARAP Deform" shape key, then
    follow the handle objects as they move"""

    bl_idname = "object.arap_deform"
    bl_label = "ARAP Deform"
    bl_options = {"REGISTER", "UNDO"}

    wait: bpy.props.BoolProperty(
        name="Wait", default=False, options={"SKIP_SAVE"},
        description="Wait for the solve (scripts; always so without a window)")

    _timer = None

    @classmethod
    def poll(cls, context):
        if _mesh_object(context) is None:
            cls.poll_message_set("Select a mesh object")
            return False
        return True

    def execute(self, context):
        obj = _mesh_object(context)
        try:
            engine.start(obj)
        except InputError as exc:
            engine.stop(obj)
            obj.arap_deform.status = str(exc)
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        if self.wait or bpy.app.background or context.window_manager.windows[:] == []:
            engine.wait(obj)
            return self._finish(obj)
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        obj = _mesh_object(context)
        session = None if obj is None else engine.session_of(obj)
        if session is None:
            return self._end(context, {"CANCELLED"})
        if event.type == "ESC":
            engine.stop(obj)
            self.report({"WARNING"}, f"{obj.name}: ARAP Deform stopped")
            return self._end(context, {"CANCELLED"})
        if event.type == "TIMER" and not session.live.busy:
            engine.take(obj, session)
            return self._end(context, self._finish(obj))
        return {"PASS_THROUGH"}

    def _end(self, context, result):
        if self._timer is not None:
            context.window_manager.event_timer_remove(self._timer)
            self._timer = None
        return result

    def _finish(self, obj):
        session = engine.session_of(obj)
        if session is not None and session.error is not None:
            self.report({"ERROR"}, session.error)
            engine.stop(obj)
            obj.arap_deform.status = session.error
            return {"CANCELLED"}
        self.report({"INFO"}, f"{obj.name}: {obj.arap_deform.status}")
        return {"FINISHED"}


class ARAPKIT_OT_stop(bpy.types.Operator):
    """Stop following the handles (the shape key keeps its last shape)"""

    bl_idname = "object.arap_stop"
    bl_label = "Stop ARAP Deform"

    @classmethod
    def poll(cls, context):
        obj = _mesh_object(context)
        return obj is not None and engine.session_of(obj) is not None

    def execute(self, context):
        obj = _mesh_object(context)
        engine.stop(obj)
        obj.arap_deform.status = "stopped"
        return {"FINISHED"}


class ARAPKIT_OT_rebind(bpy.types.Operator):
    """Take the handle objects' current pose as the rest pose (the shape returns to rest)"""

    bl_idname = "object.arap_rebind"
    bl_label = "Rebind ARAP Handles"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return _mesh_object(context) is not None

    def execute(self, context):
        obj = _mesh_object(context)
        try:
            engine.bind(obj, reset=True)
        except InputError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        if engine.session_of(obj) is not None:
            engine.mark_stale(obj)
        return {"FINISHED"}


class ARAPKIT_OT_handle_add(bpy.types.Operator):
    """Add a handle: the active vertex group, fixed for the first handle, else moving"""

    bl_idname = "object.arap_handle_add"
    bl_label = "Add ARAP Handle"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return _mesh_object(context) is not None

    def execute(self, context):
        obj = _mesh_object(context)
        s = obj.arap_deform
        item = s.handles.add()
        group = obj.vertex_groups.active
        item.group = group.name if group is not None else ""
        item.kind = "FIXED" if len(s.handles) == 1 else "MOVING"
        s.active_handle = len(s.handles) - 1
        return {"FINISHED"}


class ARAPKIT_OT_handle_remove(bpy.types.Operator):
    """Remove the selected handle"""

    bl_idname = "object.arap_handle_remove"
    bl_label = "Remove ARAP Handle"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        obj = _mesh_object(context)
        return obj is not None and len(obj.arap_deform.handles) > 0

    def execute(self, context):
        s = _mesh_object(context).arap_deform
        s.handles.remove(s.active_handle)
        s.active_handle = max(0, min(s.active_handle, len(s.handles) - 1))
        engine.mark_stale(_mesh_object(context))
        return {"FINISHED"}


CLASSES = (ARAPKIT_OT_deform, ARAPKIT_OT_stop, ARAPKIT_OT_rebind, ARAPKIT_OT_handle_add,
           ARAPKIT_OT_handle_remove)
