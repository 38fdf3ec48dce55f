"""The ARAP Deform settings stored on a mesh object (saved in the .blend file).

The Method and Weights menus are filled from arapkit (:mod:`arapkit.blender.settings`:
the method registry), not from a list kept here.
"""

from __future__ import annotations

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from arapkit.blender.settings import (
    DEFAULT_MAX_ITER,
    DEFAULT_TOL,
    method_items,
    weight_items,
)

#: kept alive for Blender: an EnumProperty's items must outlive the property
METHOD_ITEMS = method_items()
WEIGHT_ITEMS = weight_items()
IDENTITY = (1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def _changed(self, context) -> None:
    """A setting the solver reads changed: the running session is rebuilt (debounced)."""
    from . import engine

    obj = self.id_data
    if isinstance(obj, bpy.types.Object):
        engine.mark_stale(obj)


def _handle_changed(self, context) -> None:
    """A handle's group, kind, object or bone changed: its rest pose is taken anew."""
    self.bound = False
    _changed(self, context)


class ARAPHandle(bpy.types.PropertyGroup):
    """One handle: a vertex group, held fixed or carried by an object or a bone."""

    group: StringProperty(name="Vertex Group", description="The handle's vertices",
                          update=_handle_changed)
    kind: EnumProperty(
        name="Kind",
        items=[("FIXED", "Fixed", "The group stays where it is"),
               ("MOVING", "Moving", "The group follows an object or a bone")],
        default="FIXED", update=_handle_changed)
    target: PointerProperty(name="Object", type=bpy.types.Object,
                            description="The object (an empty, a hook ...) or armature "
                                        "that carries the group", update=_handle_changed)
    bone: StringProperty(name="Bone", description="With an armature: the bone that "
                                                  "carries the group", update=_handle_changed)
    # the pose when bound (what the Hook modifier keeps as its inverse matrix), as Blender's
    # own float32 matrices, row-major: the motion is then computed in float64 from exactly
    # the numbers Blender has (a product stored in float32 would be off by its round-off)
    bind_object: FloatVectorProperty(name="Object at Bind", size=16, default=IDENTITY)
    bind_driver: FloatVectorProperty(name="Driver at Bind", size=16, default=IDENTITY)
    bind_bone: FloatVectorProperty(name="Bone at Bind", size=16, default=IDENTITY)
    bound: BoolProperty(name="Bound", default=False)


class ARAPSettings(bpy.types.PropertyGroup):
    """What the ARAP Deform panel sets for one mesh object."""

    handles: CollectionProperty(type=ARAPHandle)
    active_handle: IntProperty(name="Active Handle", default=0)
    method: EnumProperty(name="Method", items=METHOD_ITEMS, update=_changed,
                         description="The deformation energy (from arapkit's method registry)")
    weights: EnumProperty(name="Weights", items=WEIGHT_ITEMS, update=_changed,
                          description="Edge weights of the energy")
    tol: FloatProperty(name="Tolerance", default=DEFAULT_TOL, min=1e-12, max=0.5,
                       precision=6, update=_changed,
                       description="Stop when the energy changes by less than this fraction "
                                   "in one iteration (the paper's test)")
    max_iter: IntProperty(name="Max Iterations", default=DEFAULT_MAX_ITER, min=1,
                          max=1_000_000, update=_changed)
    rigidity: EnumProperty(
        name="Rigidity",
        items=[("UNIFORM", "Uniform", "One r for the whole mesh"),
               ("GROUP", "Painted", "r painted in Weight Paint as a vertex group: weight 0 "
                                    "gives the lower r, weight 1 the upper")],
        default="UNIFORM", update=_changed)
    r: IntProperty(name="r", default=1, min=1, max=100, update=_changed,
                   description="Neighbourhood rings: 1 is classic ARAP, larger is stiffer")
    rigidity_group: StringProperty(name="Rigidity Group", update=_changed,
                                   description="Vertex group whose weights paint r")
    r_min: IntProperty(name="r at 0", default=1, min=1, max=100, update=_changed)
    r_max: IntProperty(name="r at 1", default=4, min=1, max=100, update=_changed)
    live: BoolProperty(name="Live", default=False,
                       description="Re-solve whenever a handle object moves")
    status: StringProperty(name="Status", default="")


CLASSES = (ARAPHandle, ARAPSettings)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.arap_deform = PointerProperty(type=ARAPSettings)


def unregister() -> None:
    del bpy.types.Object.arap_deform
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
