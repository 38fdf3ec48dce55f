"""Scenes the Blender add-on tests run in a fresh Blender (bpy), one per process.

``python tests/blender_scenes.py SCENE OUT`` builds a scene as a user would (a mesh with
UVs, a material and an attribute; vertex groups; r painted as weights; an empty or a bone
to pull with), runs the add-on and saves what the test needs into ``OUT/result.npz`` (and
``OUT/result.json``). ``tests/test_blender_addon.py`` then checks it against arapkit's own
``Deformer`` in the test process. bpy is imported only when a scene runs, so collecting
this module (doctests) never starts Blender.

The add-on is loaded from ``blender/`` (scenes ``solve``, ``bone``, ``bad``), or from an
installed extension (scene ``installed``: the zip installed by ``install``).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _bpy():
    import bpy

    return bpy


def _addon():
    sys.path.insert(0, str(ROOT / "blender"))
    import arapkit_addon

    arapkit_addon.register()
    from arapkit_addon import engine

    return engine


def make_bar(name: str = "Bar", cuts: int = 10):
    """A 4 x 1 x 1 box of quads, subdivided, with UVs, a material and a float attribute."""
    bpy = _bpy()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    obj = bpy.context.object
    obj.name = name
    obj.scale = (4.0, 1.0, 1.0)
    bpy.ops.object.transform_apply(scale=True)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=cuts)
    bpy.ops.object.mode_set(mode="OBJECT")
    obj.location = (0.3, -0.2, 0.5)  # the object's own frame is not the world's
    mat = bpy.data.materials.new("Clay")
    obj.data.materials.append(mat)
    attr = obj.data.attributes.new("temperature", "FLOAT", "POINT")
    attr.data.foreach_set("value", np.arange(len(obj.data.vertices), dtype=np.float32))
    return obj


def coords(obj) -> np.ndarray:
    co = np.empty(3 * len(obj.data.vertices), dtype=np.float32)
    obj.data.vertices.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def key_coords(obj, name: str) -> np.ndarray:
    """A shape key's coordinates read point by point (not the add-on's fast path)."""
    kb = obj.data.shape_keys.key_blocks[name]
    co = np.empty(3 * len(kb.data), dtype=np.float32)
    kb.data.foreach_get("co", co)
    return co.reshape(-1, 3)


def uvs(obj) -> np.ndarray:
    uv = np.empty(2 * len(obj.data.loops), dtype=np.float32)
    obj.data.uv_layers.active.data.foreach_get("uv", uv)
    return uv


def add_group(obj, name: str, weights: np.ndarray):
    g = obj.vertex_groups.new(name=name)
    for w in np.unique(weights[weights > 0]):
        g.add([int(i) for i in np.flatnonzero(weights == w)], float(w), "REPLACE")
    return g


def rig_bar(obj, driver, bone: str = ""):
    """Pin the -x end, pull the +x end with ``driver``; paint r by x."""
    bpy = _bpy()
    V = coords(obj)
    x = V[:, 0]
    add_group(obj, "Pin", (x <= x.min() + 1e-6).astype(float))
    add_group(obj, "Tip", (x >= x.max() - 1e-6).astype(float))
    # painted rigidity: quantised to Weight Paint's steps, stiff in the middle
    paint = np.round(np.clip(1.0 - np.abs(x) / 2.0, 0.0, 1.0), 2)
    add_group(obj, "Rigidity", paint)
    bpy.context.view_layer.objects.active = obj
    s = obj.arap_deform
    s.rigidity, s.rigidity_group, s.r_min, s.r_max = "GROUP", "Rigidity", 1, 4
    s.tol = 1e-4
    bpy.ops.object.arap_handle_add()
    s.handles[0].group = "Pin"
    bpy.ops.object.arap_handle_add()
    s.handles[1].group, s.handles[1].target, s.handles[1].bone = "Tip", driver, bone


def _matrix(m) -> list:
    return [list(row) for row in m]


def scene_solve(out: Path) -> dict:
    """Deform with an empty; move it; the live shape follows; it settles exactly."""
    bpy = _bpy()
    engine = _addon()
    obj = make_bar()
    bpy.ops.object.empty_add(location=(2.3, -0.2, 0.5))
    empty = bpy.context.object
    rig_bar(obj, empty)
    base_before, uv_before = coords(obj), uvs(obj)
    t0 = time.perf_counter()
    assert bpy.ops.object.arap_deform() == {"FINISHED"}
    first_s = time.perf_counter() - t0
    session = engine.session_of(obj)
    shape0, key0 = session.shape.copy(), key_coords(obj, engine.SHAPE_KEY)
    bind = np.array(session.live.deformer.mesh.vertices)  # what was solved: the Basis
    empty_rest = _matrix(empty.matrix_world)
    # the user moves the empty: the depsgraph handler asks, Blender's timer writes
    empty.location = (2.1, 0.6, 1.3)
    empty.rotation_euler = (0.3, -0.5, 0.9)
    bpy.context.view_layer.update()
    live_shape, deadline = None, time.monotonic() + 60
    while live_shape is None and time.monotonic() < deadline:
        time.sleep(0.01)
        engine.pump()
        if session.shape is not None and not np.array_equal(session.shape, shape0):
            live_shape = session.shape.copy()
    assert engine.wait(obj, 300)  # the drag has stopped: solved on, warm-started
    warm = session.shape.copy()
    assert bpy.ops.object.arap_deform() == {"FINISHED"}  # Update: the exact solve
    session = engine.session_of(obj)
    np.savez(out / "result.npz", base_before=base_before, base_after=coords(obj),
             uv_before=uv_before, uv_after=uvs(obj), rest=bind,
             tris=engine.triangles(obj)[0], shape0=shape0, key0=key0,
             live=np.zeros((0, 3)) if live_shape is None else live_shape,
             warm=warm, shape1=session.shape,
             key1=key_coords(obj, engine.SHAPE_KEY),
             temperature=_attribute(obj, "temperature"))
    return {"empty_rest": empty_rest, "empty_moved": _matrix(empty.matrix_world),
            "object": _matrix(obj.matrix_world), "status": obj.arap_deform.status,
            "materials": [m.name for m in obj.data.materials],
            "keys": [k.name for k in obj.data.shape_keys.key_blocks],
            "key_value": obj.data.shape_keys.key_blocks[engine.SHAPE_KEY].value,
            "first_solve_s": first_s}


def _attribute(obj, name: str) -> np.ndarray:
    a = obj.data.attributes[name]
    v = np.empty(len(a.data), dtype=np.float32)
    a.data.foreach_get("value", v)
    return v


def scene_bone(out: Path) -> dict:
    """A moving group carried by a bone: posing the bone deforms the mesh."""
    bpy = _bpy()
    engine = _addon()
    obj = make_bar(cuts=6)
    bpy.ops.object.armature_add(location=(1.8, -0.2, 0.5))
    arm = bpy.context.object
    bone = arm.data.bones[0].name
    rig_bar(obj, arm, bone)
    obj.arap_deform.rigidity = "UNIFORM"
    obj.arap_deform.r = 2
    assert bpy.ops.object.arap_deform() == {"FINISHED"}
    pb = arm.pose.bones[bone]
    before = (np.array(arm.matrix_world), np.array(pb.matrix))
    pb.rotation_mode = "XYZ"
    pb.rotation_euler = (0.0, 0.7, 0.0)
    bpy.context.view_layer.update()
    assert engine.wait(obj, 300)
    assert bpy.ops.object.arap_deform() == {"FINISHED"}  # Update: the exact solve
    after = (np.array(arm.matrix_world), np.array(pb.matrix))
    np.savez(out / "result.npz", rest=coords(obj), tris=engine.triangles(obj)[0],
             shape=engine.session_of(obj).shape, arm_before=before[0], bone_before=before[1],
             arm_after=after[0], bone_after=after[1], object=np.array(obj.matrix_world))
    return {"status": obj.arap_deform.status}


def scene_animation(out: Path) -> dict:
    """An animated empty: each frame set (as a render or ``blender -b`` sets it) gets the
    exact solve of that frame's pose before the frame is done."""
    bpy = _bpy()
    engine = _addon()
    obj = make_bar(cuts=5)
    bpy.ops.object.empty_add(location=(2.3, -0.2, 0.5))
    empty = bpy.context.object
    rig_bar(obj, empty)
    empty.keyframe_insert("location", frame=1)
    empty.location = (2.0, 0.8, 1.6)
    empty.keyframe_insert("location", frame=10)
    bpy.context.scene.frame_set(1)
    assert bpy.ops.object.arap_deform() == {"FINISHED"}
    shapes, poses = [], []
    for frame in (4, 10):
        bpy.context.scene.frame_set(frame)  # frame_change_post: solved before it returns
        shapes.append(key_coords(obj, engine.SHAPE_KEY).astype(np.float64))
        poses.append(np.array(empty.matrix_world))
    bpy.context.scene.frame_set(1)
    np.savez(out / "result.npz", rest=coords(obj), tris=engine.triangles(obj)[0],
             shapes=np.array(shapes), poses=np.array(poses),
             object=np.array(obj.matrix_world), exact=engine.session_of(obj).shape)
    return {"status": obj.arap_deform.status}


class _Layout:
    """A stand-in for Blender's UI layout (there is none without a window): it checks that
    every property, collection and operator the panel names exists, and records them."""

    def __init__(self, seen: list):
        self.seen = seen

    def _sub(self, *args, **kwargs):
        return _Layout(self.seen)

    row = column = box = split = _sub

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties, f"no property {name!r} on {data}"
        self.seen.append(("prop", name))

    def prop_search(self, data, name, search_data, search_name, **kwargs):
        assert name in data.bl_rna.properties, f"no property {name!r} on {data}"
        assert search_name in search_data.bl_rna.properties, f"no {search_name!r}"
        self.seen.append(("search", name, search_name))

    def operator(self, idname, **kwargs):
        group, name = idname.split(".")
        assert hasattr(getattr(_bpy().ops, group), name), f"no operator {idname}"
        self.seen.append(("operator", idname))

    def label(self, **kwargs):
        self.seen.append(("label", kwargs.get("text", "")))

    def template_list(self, listtype, list_id, data, name, active_data, active_name, **kw):
        bpy = _bpy()
        assert hasattr(bpy.types, listtype), f"no UI list {listtype}"
        assert name in data.bl_rna.properties and active_name in active_data.bl_rna.properties
        draw_item = getattr(bpy.types, listtype).draw_item  # a UIList is Blender's to make
        for i, item in enumerate(getattr(data, name)):
            draw_item(None, bpy.context, self, data, item, 0, active_data, active_name, i)
        self.seen.append(("list", name))


def scene_panel(out: Path) -> dict:
    """The panel drawn in each state a user meets: before Deform, painted r, an armature."""
    bpy = _bpy()
    engine = _addon()
    ui = sys.modules["arapkit_addon.ui"]
    obj = make_bar(cuts=2)
    bpy.ops.object.armature_add(location=(2.0, 0, 0))
    arm = bpy.context.object
    rig_bar(obj, arm, arm.data.bones[0].name)
    seen: dict[str, list] = {}
    obj.arap_deform.rigidity = "UNIFORM"
    ui.draw(_Layout(seen.setdefault("before", [])), obj)
    obj.arap_deform.rigidity = "GROUP"
    assert bpy.ops.object.arap_deform() == {"FINISHED"}
    ui.draw(_Layout(seen.setdefault("painted, running", [])), obj)
    obj.arap_deform.method = "sr-arap"  # no rigidity map: no rigidity controls
    ui.draw(_Layout(seen.setdefault("sr-arap", [])), obj)
    engine.stop_all()
    return {k: [list(x) for x in v] for k, v in seen.items()}


def scene_bad(out: Path) -> dict:
    """Bad input: each case's message from the operator, and the mesh left as it was."""
    bpy = _bpy()
    engine = _addon()
    results = {}

    def attempt(case: str, obj) -> None:
        before = coords(obj)
        keys = obj.data.shape_keys
        try:
            r = bpy.ops.object.arap_deform()
            msg = obj.arap_deform.status
        except RuntimeError as exc:  # an ERROR report, as Blender raises it without a window
            r, msg = {"CANCELLED"}, str(exc)
        results[case] = {"result": sorted(r), "message": msg,
                         "untouched": bool(np.array_equal(before, coords(obj))),
                         "keys_before": keys is not None,
                         "keys": None if obj.data.shape_keys is None else
                         [k.name for k in obj.data.shape_keys.key_blocks]}

    def fresh(**kw):
        obj = make_bar(cuts=3)
        bpy.ops.object.empty_add(location=(2.3, -0.2, 0.5))
        empty = bpy.context.object
        rig_bar(obj, empty)
        for key, value in kw.items():
            setattr(obj.arap_deform, key, value)
        return obj

    obj = fresh()
    obj.arap_deform.handles.clear()
    attempt("no handles", obj)
    obj = fresh()
    obj.arap_deform.handles.remove(0)
    attempt("no fixed group", obj)
    obj = fresh()
    obj.vertex_groups["Tip"].remove(list(range(len(obj.data.vertices))))
    attempt("empty group", obj)
    obj = fresh()
    obj.arap_deform.handles[1].group = "Nope"
    attempt("missing group", obj)
    obj = fresh()
    obj.arap_deform.handles[1].target = None
    attempt("no object", obj)
    obj = fresh()
    bpy.ops.object.mode_set(mode="EDIT")
    attempt("edit mode", obj)
    bpy.ops.object.mode_set(mode="OBJECT")
    obj = fresh()
    obj.arap_deform.rigidity_group = ""
    attempt("no rigidity group", obj)
    # a fin on the bar: three faces share an edge (non-manifold), and a loose vertex
    obj = fresh()
    me = obj.data
    import bmesh

    bm = bmesh.new()
    bm.from_mesh(me)
    bm.verts.ensure_lookup_table()
    edge = next(e for e in bm.edges if len(e.link_faces) == 2)
    a, b = edge.verts
    c = bm.verts.new(a.co + (a.co - b.co).cross(a.normal) * 2.0)
    bm.faces.new((a, b, c))
    bm.verts.new((9.0, 9.0, 9.0))
    bm.to_mesh(me)
    bm.free()
    attempt("non-manifold", obj)
    results["non-manifold"]["nonmanifold_edges"] = int(
        engine.session_of(obj).live.deformer.mesh.n_nonmanifold_edges
        if engine.session_of(obj) is not None else -1)
    return results


def scene_install(out: Path, zip_path: str) -> dict:
    """Install the extension zip as Blender's Install from Disk does (user repository)."""
    bpy = _bpy()
    r = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default",
                                                 enable_on_install=True)
    bpy.ops.wm.save_userpref()
    return {"result": sorted(r),
            "enabled": [a.module for a in bpy.context.preferences.addons
                        if a.module.endswith("arapkit")]}


def scene_installed(out: Path) -> dict:
    """A new Blender session with the installed extension: deform as a user would."""
    bpy = _bpy()
    obj = make_bar(cuts=4)  # factory settings first: they would disable the add-on
    module = "bl_ext.user_default.arapkit"
    if module not in bpy.context.preferences.addons:
        bpy.ops.preferences.addon_enable(module=module)
    engine = sys.modules[module + ".engine"]
    import numba
    import scipy

    import arapkit

    bpy.ops.object.empty_add(location=(2.3, -0.2, 0.5))
    empty = bpy.context.object
    rig_bar(obj, empty)
    t0 = time.perf_counter()
    assert bpy.ops.object.arap_deform() == {"FINISHED"}
    first_s = time.perf_counter() - t0
    empty.location.z += 1.0
    bpy.context.view_layer.update()
    assert engine.wait(obj, 600)
    assert bpy.ops.object.arap_deform() == {"FINISHED"}  # Update: the exact solve
    session = engine.session_of(obj)
    np.savez(out / "result.npz", rest=coords(obj), tris=engine.triangles(obj)[0],
             shape=session.shape, handles=session.rig.handles, targets=session.last_targets,
             rings=session.live.deformer.rings)
    return {"files": {m.__name__: m.__file__ for m in (arapkit, scipy, numba)},
            "status": obj.arap_deform.status, "first_solve_s": first_s}


SCENES = {"solve": scene_solve, "bone": scene_bone, "animation": scene_animation,
          "panel": scene_panel, "bad": scene_bad,
          "install": scene_install, "installed": scene_installed}


def main(argv: list[str]) -> int:
    scene, out, *args = argv
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    result = SCENES[scene](out, *args)
    (out / "result.json").write_text(json.dumps(result))
    _bpy().ops.wm.read_factory_settings(use_empty=True)  # ends the sessions' threads too
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
