"""The ARAP Deform panel: in the mesh's Data properties, and in the 3D Viewport's sidebar."""

from __future__ import annotations

import bpy

from arapkit.blender.settings import takes_rigidity_map

from . import engine


class ARAPKIT_UL_handles(bpy.types.UIList):
    """One row per handle: group, kind, and the object (and bone) a moving one follows."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname,
                  index=0):
        obj = data.id_data
        row = layout.row(align=True)
        row.prop_search(item, "group", obj, "vertex_groups", text="", icon="GROUP_VERTEX")
        row.prop(item, "kind", text="")
        if item.kind == "MOVING":
            row.prop(item, "target", text="")
            if item.target is not None and item.target.type == "ARMATURE":
                row.prop_search(item, "bone", item.target.data, "bones", text="")


def draw(layout, obj) -> None:
    s = obj.arap_deform
    col = layout.column()
    col.prop(s, "method")
    col.prop(s, "weights")
    row = col.row(align=True)
    row.prop(s, "tol")
    row.prop(s, "max_iter", text="Max")
    if takes_rigidity_map(s.method):
        box = col.box()
        box.prop(s, "rigidity", expand=True)
        if s.rigidity == "UNIFORM":
            box.prop(s, "r")
        else:
            box.prop_search(s, "rigidity_group", obj, "vertex_groups", text="Group")
            row = box.row(align=True)
            row.prop(s, "r_min")
            row.prop(s, "r_max")
    col.label(text="Handles")
    row = col.row()
    row.template_list("ARAPKIT_UL_handles", "", s, "handles", s, "active_handle", rows=3)
    side = row.column(align=True)
    side.operator("object.arap_handle_add", icon="ADD", text="")
    side.operator("object.arap_handle_remove", icon="REMOVE", text="")
    row = col.row(align=True)
    running = engine.session_of(obj) is not None
    row.operator("object.arap_deform", text="Update" if running else "Deform",
                 icon="MOD_MESHDEFORM")
    if running:
        row.operator("object.arap_stop", text="Stop", icon="PAUSE")
    row.operator("object.arap_rebind", text="Rebind", icon="FILE_REFRESH")
    if s.status:
        failed = not running and not s.status.startswith(("converged", "stopped"))
        col.label(text=s.status, icon="ERROR" if failed else "INFO")


class ARAPKIT_PT_data(bpy.types.Panel):
    bl_label = "ARAP Deform"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "data"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type == "MESH"

    def draw(self, context):
        draw(self.layout, context.object)


class ARAPKIT_PT_sidebar(bpy.types.Panel):
    bl_label = "ARAP Deform"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "ARAP"

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type == "MESH"

    def draw(self, context):
        draw(self.layout, context.object)


CLASSES = (ARAPKIT_UL_handles, ARAPKIT_PT_data, ARAPKIT_PT_sidebar)
