"""The Blender door: what the ARAP Deform add-on needs of the library, without Blender.

The add-on itself (``blender/arapkit_addon/`` at the repository's root, packed with
``make blender-addon``) is a thin shell of operators, properties and a panel that imports
:mod:`bpy`. It reads vertex groups, object matrices and the panel's settings as arrays and
hands them to this package, which is plain Python and tested without Blender:

* :mod:`arapkit.blender.rig` -- handle groups (fixed, moving) to handles and targets, and
  painted weights to r;
* :mod:`arapkit.blender.live` -- the background solver thread (newest pose wins, exact
  solve once a drag stops);
* :mod:`arapkit.blender.settings` -- the panel's choices, from the method registry.

Examples
--------
>>> from arapkit.blender import GroupHandle, make_rig
>>> make_rig(2, [GroupHandle("Pin", "fixed", [1.0, 0.0])]).handles.tolist()
[0]
"""

from .live import FRAME_MS, SETTLE_S, LiveDeformer, Shape
from .rig import HANDLE_KINDS, GroupHandle, Rig, make_rig, mesh_notes, rings_from_weights
from .settings import method_items, takes_rigidity_map, weight_items

__all__ = [
    "FRAME_MS",
    "HANDLE_KINDS",
    "SETTLE_S",
    "GroupHandle",
    "LiveDeformer",
    "Rig",
    "Shape",
    "make_rig",
    "mesh_notes",
    "method_items",
    "rings_from_weights",
    "takes_rigidity_map",
    "weight_items",
]
