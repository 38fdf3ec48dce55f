"""Make ``docs/blender-arap.png``: the ARAP Deform add-on at work, rendered headless by Blender.

The project's cactus (``examples/cactus.off``) is loaded into Blender (bpy, Blender as a
Python module) with the add-on registered from ``blender/``, as a user would set it up:
a Fixed handle on the pot, two Moving handles on the hands, each following an empty, and
r painted as a vertex group (arms stiff, weight 1 -> r = 4; trunk soft, weight 0 -> r = 1).
The empties are turned as ``examples/cactus.json`` turns the hands, the add-on solves into
its "ARAP Deform" shape key, and Cycles (CPU, 32 samples, denoised) renders the rest shape
(left) beside the result (right), coloured by the painted weight (blue soft, orange stiff).

Usage::

    PYTHONPATH=src python docs/blender_screenshot.py [OUT.png]
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MESH = ROOT / "examples" / "cactus.off"
HANDLES = ROOT / "examples" / "cactus.json"


def _mesh_object(bpy, name: str, V: np.ndarray, F: np.ndarray):
    me = bpy.data.meshes.new(name)
    me.from_pydata(V.tolist(), [], F.tolist())
    me.update()
    for p in me.polygons:
        p.use_smooth = True
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _material(bpy, weights_attr: str):
    """Soft (weight 0) blue to stiff (weight 1) orange, from the painted weights."""
    mat = bpy.data.materials.new("Rigidity")
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = 0.55
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_name = weights_attr
    ramp = nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (0.16, 0.36, 0.75, 1.0)
    ramp.color_ramp.elements[1].color = (0.95, 0.55, 0.15, 1.0)
    links.new(attr.outputs["Fac"], ramp.inputs["Fac"])
    links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def main(argv: list[str]) -> int:
    out = Path(argv[0]) if argv else ROOT / "docs" / "blender-arap.png"
    import bpy

    from arapkit import load_handles, load_mesh

    sys.path.insert(0, str(ROOT / "blender"))
    import arapkit_addon

    bpy.ops.wm.read_factory_settings(use_empty=True)
    arapkit_addon.register()
    from arapkit_addon import engine

    mesh = load_mesh(MESH)
    hs = load_handles(HANDLES, mesh.vertices)
    V = mesh.vertices - [0.0, mesh.vertices[:, 1].min(), 0.0]
    # the cactus stands on +y; Blender's up is +z
    to_z = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    Vz = V @ to_z.T
    stiff = (V[:, 1] > 6.0) & (np.abs(V[:, 0]) > 1.2)  # the arms
    weight = stiff.astype(float)

    obj = _mesh_object(bpy, "Cactus", Vz, mesh.faces)
    rest = _mesh_object(bpy, "Cactus at rest", Vz, mesh.faces)
    rest.location.x = -11.0
    mat = _material(bpy, "rigidity")
    for o in (obj, rest):
        o.data.materials.append(mat)
        a = o.data.attributes.new("rigidity", "FLOAT", "POINT")
        a.data.foreach_set("value", weight.astype(np.float32))
    # the groups, as a user paints and assigns them
    paint = obj.vertex_groups.new(name="Rigidity")
    paint.add([int(i) for i in np.flatnonzero(stiff)], 1.0, "REPLACE")
    s = obj.arap_deform
    s.rigidity, s.rigidity_group, s.r_min, s.r_max, s.tol = "GROUP", "Rigidity", 1, 4, 1e-4
    empties = []
    for g in hs.groups:
        vg = obj.vertex_groups.new(name=g.name.title())
        vg.add([int(i) for i in g.indices], 1.0, "REPLACE")
        item = s.handles.add()
        item.group = vg.name
        moving = not np.array_equal(g.targets, mesh.vertices[g.indices])
        item.kind = "MOVING" if moving else "FIXED"
        if moving:
            e = bpy.data.objects.new(f"{vg.name} handle", None)
            bpy.context.scene.collection.objects.link(e)
            e.location = Vz[g.indices].mean(axis=0)
            item.target = e
            empties.append((e, g))
    bpy.context.view_layer.objects.active = obj
    bpy.context.view_layer.update()
    assert bpy.ops.object.arap_deform(wait=True) == {"FINISHED"}
    # turn each empty about the hand's shoulder as the json turns the hand
    for e, g in empties:
        P, Q = Vz[g.indices], (g.targets - [0.0, mesh.vertices[:, 1].min(), 0.0]) @ to_z.T
        p0, q0 = P.mean(axis=0), Q.mean(axis=0)
        U, _, Wt = np.linalg.svd((P - p0).T @ (Q - q0))
        R = Wt.T @ np.diag([1, 1, np.sign(np.linalg.det(Wt.T @ U.T))]) @ U.T
        M = np.eye(4)
        M[:3, :3], M[:3, 3] = R, q0 - R @ p0
        from mathutils import Matrix

        e.matrix_world = Matrix(M.tolist()) @ e.matrix_world
    bpy.context.view_layer.update()
    assert bpy.ops.object.arap_deform(wait=True) == {"FINISHED"}
    print(obj.arap_deform.status)
    _stage(bpy, engine)
    bpy.context.scene.render.filepath = str(out)
    bpy.ops.render.render(write_still=True)
    _shrink(out)
    print(f"wrote {out}")
    engine.stop_all()
    return 0


def _shrink(path: Path) -> None:
    """96 colours (Pillow, where installed: matplotlib brings it): a third of the bytes."""
    try:
        from PIL import Image
    except ImportError:
        return
    im = Image.open(path).convert("RGB")
    im.quantize(colors=96, method=Image.Quantize.MEDIANCUT).save(path, optimize=True)


def _stage(bpy, engine) -> None:
    """Floor, sun, sky, a camera that frames both cacti, and Cycles on the CPU."""
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_plane_add(size=200, location=(-5.0, 0, 0))
    bpy.ops.object.light_add(type="SUN", rotation=(math.radians(35), 0, math.radians(25)))
    bpy.context.object.data.energy = 3.0
    bpy.ops.object.camera_add(location=(-5.0, -42.0, 8.0),
                              rotation=(math.radians(86), 0, 0))
    scene.camera = bpy.context.object
    scene.camera.data.lens = 42
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (0.78, 0.80, 0.84, 1.0)
    background.inputs["Strength"].default_value = 0.8
    scene.world = world
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 32
    scene.cycles.use_denoising = True  # OpenImageDenoise, on the CPU
    scene.render.resolution_x, scene.render.resolution_y = 1200, 600


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
