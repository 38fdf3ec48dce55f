"""The Blender add-on following a drag, headless (bpy): shapes per second and main-thread stalls.

A bar of about 50K vertices (and, with ``--large``, 100K: coarse to fine) is pinned at
one end and pulled at the other by an empty. The drag moves the empty every 1/60 s along
an arc, as a mouse drag would, calls the view layer update (the add-on's depsgraph handler
hands the new targets to its solver thread) and Blender's timer function (which writes the
newest shape into the shape key), for :data:`DRAG_S` seconds. Reported:

* **shapes/s**: distinct shapes written into the shape key per second of drag (the
  issue's goal: at least 20 at 50K vertices);
* **main thread**: the longest and the 95th-percentile time of one frame's work on
  Blender's thread (update plus timer): what a user would feel as a frozen viewport;
* **iterations/s of the library**: ``Deformer.solve`` warm-started on the same mesh, in
  the same run, without Blender: the baseline the shapes are drawn from;
* **settle**: from the last move to the converged shape (warm-started; coarse to fine:
  the exact solve);
* **key write**: one shape into the shape key, the add-on's way (``ShapeKey.points``)
  against the per-point ``ShapeKey.data``.

Usage: ``python benchmarks/bench_blender.py [--quick] [--large]`` with bpy installed
(``pip install --no-deps bpy``); without it the script says so and exits 0.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: how long the drag lasts (s)
DRAG_S = 4.0
#: how often Blender's timer and the mouse move (s)
FRAME_S = 1.0 / 60.0


def make_bar(cuts: int, again: int = 0):
    """A 4 x 1 x 1 box of quads subdivided with ``cuts`` (Blender allows at most 100), then
    ``again`` more times once more."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    obj = bpy.context.object
    obj.scale = (4.0, 1.0, 1.0)
    bpy.ops.object.transform_apply(scale=True)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=cuts)
    if again:
        bpy.ops.mesh.subdivide(number_cuts=again)
    bpy.ops.object.mode_set(mode="OBJECT")
    return obj


def run(cuts: int, again: int = 0) -> dict:
    import bpy

    sys.path.insert(0, str(ROOT / "blender"))
    import arapkit_addon

    arapkit_addon.register()
    from arapkit_addon import engine

    obj = make_bar(cuts, again)
    n = len(obj.data.vertices)
    co = np.empty(3 * n, dtype=np.float32)
    obj.data.vertices.foreach_get("co", co)
    x = co.reshape(-1, 3)[:, 0]
    for name, sel in (("Pin", x <= x.min() + 1e-6), ("Tip", x >= x.max() - 1e-6)):
        obj.vertex_groups.new(name=name).add([int(i) for i in np.flatnonzero(sel)], 1.0,
                                             "REPLACE")
    bpy.ops.object.empty_add(location=(2.0, 0.0, 0.0))
    empty = bpy.context.object
    bpy.context.view_layer.objects.active = obj
    s = obj.arap_deform
    for group, kind in (("Pin", "FIXED"), ("Tip", "MOVING")):
        h = s.handles.add()
        h.group, h.kind = group, kind
    s.handles[1].target = empty
    t0 = time.perf_counter()
    bpy.ops.object.arap_deform(wait=True)
    first = time.perf_counter() - t0
    session = engine.session_of(obj)
    written, frames = 0, []
    start = time.perf_counter()
    while (now := time.perf_counter()) - start < DRAG_S:
        a = 0.9 * (now - start) / DRAG_S  # up to about 52 degrees
        f0 = time.perf_counter()
        empty.location = (2.0 * np.cos(a), 0.0, 2.0 * np.sin(a))
        empty.rotation_euler = (0.0, -a, 0.0)
        bpy.context.view_layer.update()  # the depsgraph handler asks the solver
        written += engine.pump()  # Blender's timer writes what the solver sent
        frames.append(time.perf_counter() - f0)
        time.sleep(max(0.0, FRAME_S - (time.perf_counter() - f0)))
    drag = time.perf_counter() - start
    t_rel = time.perf_counter()
    engine.wait(obj, 600)
    settle = time.perf_counter() - t_rel
    # the baseline, same run: the library's warm-started iterations on the same problem
    d = session.live.deformer
    T = session.last_targets
    t1 = time.perf_counter()
    res = d.solve(T, init=session.shape, tol=1e-12, max_iter=20)
    per_s = res.iterations / (time.perf_counter() - t1)
    # writing a shape into the key: the add-on's path (ShapeKey.points, one array) against
    # the per-point one (ShapeKey.data), interleaved, median of 20 each
    kb = obj.data.shape_keys.key_blocks[engine.SHAPE_KEY]
    flat = session.shape.astype(np.float32).ravel()
    times = {"points": [], "data": []}
    for _ in range(20):
        for how in times:
            t2 = time.perf_counter()
            getattr(kb, how).foreach_set("co", flat)
            times[how].append(time.perf_counter() - t2)
    frames_ms = np.array(frames) * 1e3
    out = {"vertices": n, "first deform s": first, "shapes/s": written / drag,
           "main max ms": frames_ms.max(), "main p95 ms": np.percentile(frames_ms, 95),
           "library it/s": per_s, "settle s": settle, "status": s.status,
           "key write ms": np.median(times["points"]) * 1e3,
           "per-point write ms": np.median(times["data"]) * 1e3,
           "multires": type(d).__name__ == "MultiresDeformer"}
    engine.stop_all()
    arapkit_addon.unregister()
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="a 5K-vertex bar only")
    p.add_argument("--large", action="store_true", help="also 100K vertices (coarse to fine)")
    args = p.parse_args(argv)
    try:
        import bpy  # noqa: F401
    except ImportError:
        print("bench_blender: bpy is not installed (pip install --no-deps bpy): skipped")
        return 0
    # about 6 (c + 1)^2 vertices: cuts 90 gives 50K; 64 then 1 more gives 101K
    sizes = [(28, 0)] if args.quick else [(90, 0)] + ([(64, 1)] if args.large else [])
    rows = [run(*c) for c in sizes]
    keys = ["vertices", "first deform s", "shapes/s", "main max ms", "main p95 ms",
            "library it/s", "settle s", "multires", "key write ms", "per-point write ms"]
    print("| " + " | ".join(keys) + " |")
    print("|" + "---|" * len(keys))
    for r in rows:
        print("| " + " | ".join(f"{r[k]:.3g}" if isinstance(r[k], float) else str(r[k])
                                for k in keys) + " |")
    for r in rows:
        print(f"{r['vertices']}: {r['status']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
