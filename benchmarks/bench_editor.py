"""Editor latency: from a handle move to the new vertex positions being sent (server side).

A real :class:`arapkit.editor.app.EditorApp` (viser server, solver thread) is started on
a mesh with a frozen base and one moving handle; a scripted drag of ``--steps`` gizmo
moves is fed through the same entry point the gizmo callback uses
(:meth:`EditorApp.drag_handle`).  For each move the latency is the time until the first
shape computed from that move *or a newer one* (the editor drops superseded moves) has
been handed to viser for sending.

Two pacings are measured:

* ``paced``: one move every ``1/--rate`` s, like a browser drag (moves arrive while the
  solver is still iterating, so supersede and the wait for the running iteration count);
* ``sequential``: the next move is sent only after the previous shape went out (pure
  pipeline cost, no waiting behind a running iteration).

Usage::

    python benchmarks/bench_editor.py                       # bunny00.off, r = 1 and 3
    python benchmarks/bench_editor.py --mesh x.off --rings 1 2 --steps 50 --rate 20
    python benchmarks/bench_editor.py --quick                # 20 paced steps

Targets (issue #5): median <= 100 ms at r = 1 and <= 200 ms at r = 3 on a ~30K mesh.
"""

from __future__ import annotations

import argparse
import math
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

DEFAULT_MESH = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "meshes" / (
    "bunny00.off")
TARGET_MS = {1: 100.0, 3: 200.0}


def free_port() -> int:
    """A TCP port nobody listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def handle_regions(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A fixed base (lowest 8 % along y) and a moving cap around the highest vertex."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    y = vertices[:, 1]
    base = np.flatnonzero(y <= lo[1] + 0.08 * (hi[1] - lo[1]))
    top = vertices[np.argmax(y)]
    radius = 0.08 * np.linalg.norm(hi - lo)
    cap = np.flatnonzero(np.linalg.norm(vertices - top, axis=1) <= radius)
    return base, np.setdiff1d(cap, base)


def drag_path(start: np.ndarray, diag: float, steps: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Gizmo poses of a drag: translate by up to 15 % of the size and turn up to 30 deg."""
    poses = []
    for k in range(1, steps + 1):
        t = k / steps
        angle = math.radians(30.0) * t
        wxyz = np.array([math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)])
        pos = start + diag * np.array([0.15 * t, 0.03 * math.sin(4 * math.pi * t), 0.0])
        poses.append((wxyz, pos))
    return poses


def run_drag(mesh, r: int, steps: int, rate: float, mode: str) -> dict[str, float]:
    """One scripted drag; returns latency statistics in ms."""
    from arapkit.editor.app import EditorApp
    from arapkit.editor.state import EditorState

    st = EditorState(mesh, rings=r)
    base, cap = handle_regions(st.vertices)
    st.add_handle(base, name="base", frozen=True)
    handle = st.add_handle(cap, name="cap")
    with tempfile.TemporaryDirectory() as tmp:
        app = EditorApp(st, port=free_port(), export_dir=tmp)
        try:
            if not app.wait_idle(600):
                raise RuntimeError("initial solve did not finish")
            sends: list[tuple[int, float]] = []
            errors: list[str] = []
            sent = threading.Event()

            def hook(u, t: float) -> None:
                if u.error:
                    errors.append(u.error)
                else:
                    sends.append((u.seq, t))
                sent.set()

            app.sent_hooks.append(hook)
            lo, hi = st.vertices.min(axis=0), st.vertices.max(axis=0)
            poses = drag_path(handle.position.copy(), float(np.linalg.norm(hi - lo)), steps)
            moves: list[tuple[int, float]] = []
            t_next = time.perf_counter()
            for k, (wxyz, pos) in enumerate(poses):
                phase = "start" if k == 0 else "end" if k == steps - 1 else "update"
                sent.clear()
                t = time.perf_counter()
                seq = app.drag_handle("cap", wxyz, pos, phase)
                moves.append((seq, t))
                if errors:
                    raise RuntimeError(f"solver failed: {errors[0]}")
                if mode == "sequential":
                    while not any(s >= seq for s, _ in sends[-4:]) and not errors:
                        sent.wait(10.0)
                        sent.clear()
                else:
                    t_next += 1.0 / rate
                    time.sleep(max(0.0, t_next - time.perf_counter()))
            app.wait_idle(600)
            lat = []
            for seq, t in moves:
                later = [ts for s, ts in sends if s >= seq and ts >= t]
                lat.append((min(later) - t) * 1e3)
            final = app.last_update
            return {
                "median": float(np.median(lat)),
                "p95": float(np.percentile(lat, 95)),
                "max": float(np.max(lat)),
                "dropped": float(app.worker.dropped),
                "final_energy": float(final.energy) if final else float("nan"),
                "final_iterations": float(final.iterations) if final else float("nan"),
            }
        finally:
            app.stop()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", default=str(DEFAULT_MESH.resolve()))
    ap.add_argument("--rings", type=int, nargs="+", default=[1, 3])
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--rate", type=float, default=20.0, help="moves per second when paced")
    ap.add_argument("--modes", nargs="+", default=["paced", "sequential"],
                    choices=["paced", "sequential"])
    ap.add_argument("--quick", action="store_true",
                    help="20 steps, paced only (what `make bench`/run_all.py --quick use)")
    args = ap.parse_args(argv)
    if args.quick:
        args.steps, args.modes = min(args.steps, 20), ["paced"]
    if not Path(args.mesh).exists():
        print(f"bench_editor: skipped: {args.mesh} not found (the shared data folder is absent)")
        return 0

    from arapkit import load_mesh

    mesh = load_mesh(args.mesh)
    print(f"mesh {Path(args.mesh).name}: {mesh.n_vertices:,} vertices, {mesh.n_faces:,} faces; "
          f"{args.steps}-step drag, paced at {args.rate:g} Hz")
    print(f"{'r':>2} {'mode':>10} {'median ms':>10} {'p95 ms':>8} {'max ms':>8} "
          f"{'dropped':>8} {'target':>7} {'final E':>10} {'iters':>6}")
    ok = True
    for r in args.rings:
        for mode in args.modes:
            s = run_drag(mesh, r, args.steps, args.rate, mode)
            target = TARGET_MS.get(r)
            passed = target is None or s["median"] <= target
            ok &= passed or mode != "paced"
            print(f"{r:>2} {mode:>10} {s['median']:>10.1f} {s['p95']:>8.1f} {s['max']:>8.1f} "
                  f"{int(s['dropped']):>8d} {('<=' + format(target, '.0f')) if target else '-':>7} "
                  f"{s['final_energy']:>10.4g} {int(s['final_iterations']):>6d}", flush=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
