"""Transport to the browser: bytes per frame of each way to show a drag.

Two consecutive frames of a 30-frame drag (``pull``, 29/30 and 30/30 of the way) are made
the cheap way, by the proxy preview of ``proxy.py`` (20K proxy, nearest-vertex rotation
skinning), on the dragon; the 1.75M figures scale the per-vertex sizes by the subdivided
dragon's vertex count (its per-vertex motion is the same surface's). Reported per frame:

* full float32 positions (what the editor sends today: ``mesh_node.vertices = V32``);
* full positions quantised to 16 bits per coordinate in the bounding box
  (step = extent / 65535, far below the 1 % preview tolerance);
* a delta stream: only the vertices that moved more than 1e-4 / 1e-3 of the diagonal since
  the previous frame (index + float32 position);
* the zlib-compressed 16-bit frame delta;
* the proxy mesh's own positions (20K / 50K, float32), or its per-vertex rigid motions
  (position + quaternion, 7 float32) for skinning in the browser.

Usage::

    python benchmarks/scale/transport.py
"""

from __future__ import annotations

import zlib

import numpy as np
from common import base_and_top, drag_motion, dragon, dragon_decimated, machine_load, table
from proxy import Skinning, proxy_handles

N_X4 = 1_750_000  # about one Loop subdivision of the dragon (solvers.py --mesh x4 prints it)


def quantise(X: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """16-bit coordinates in the rest bounding box (padded by half its size each side)."""
    span = hi - lo
    q = (X - (lo - 0.5 * span)) / (2.0 * span) * 65535.0
    return np.clip(np.rint(q), 0, 65535).astype(np.uint16)


def frames(mesh, n_proxy: int):
    """Two consecutive preview frames (29/30 and 30/30 of the pull drag) on ``mesh``."""
    from arapkit import Deformer

    V = mesh.vertices
    base, top = base_and_top(V)
    pm = dragon_decimated(n_proxy)
    Q = pm.vertices
    pb, pt = proxy_handles(V, Q, base, top)
    d = Deformer(pm, np.concatenate([pb, pt]), accelerate=True)
    sk = Skinning(V, Q, 1)
    out = []
    for frac in (29 / 30, 1.0):
        R, t = drag_motion(V, top, "pull", frac)
        res = d.solve(np.concatenate([Q[pb], Q[pt] @ R.T + t]), tol=1e-5, max_iter=3000)
        out.append(sk(res.vertices, res.rotations).copy())
    return out


def main() -> None:
    mesh = dragon()
    n = mesh.n_vertices
    V, diag = mesh.vertices, mesh.bounding_box_diagonal
    print(f"{mesh.name}: {n} vertices; {machine_load()}")
    A, B = frames(mesh, 20000)
    lo, hi = V.min(axis=0), V.max(axis=0)
    moved = np.linalg.norm(B - A, axis=1) / diag
    qa, qb = quantise(A, lo, hi), quantise(B, lo, hi)
    dz = len(zlib.compress((qb.astype(np.int32) - qa).astype(np.int16).tobytes(), 6))
    per_vertex = {
        "full float32 (today)": 12.0,
        "full 16-bit quantised": 6.0,
        "delta > 1e-4 diag (int32 index + float32 xyz)": 16.0 * float((moved > 1e-4).mean()),
        "delta > 1e-3 diag (int32 index + float32 xyz)": 16.0 * float((moved > 1e-3).mean()),
        "16-bit frame delta, zlib": dz / n,
    }
    rows = [[k, f"{v * n / 1e6:.2f}", f"{v * N_X4 / 1e6:.2f}", f"{30 * v * n / 1e6:.0f}"]
            for k, v in per_vertex.items()]
    for npx in (20000, 50000):
        rows.append([f"proxy {npx // 1000}K positions float32", f"{12 * npx / 1e6:.2f}",
                     f"{12 * npx / 1e6:.2f}", f"{30 * 12 * npx / 1e6:.0f}"])
        rows.append([f"proxy {npx // 1000}K rigid motions (7 float32)", f"{28 * npx / 1e6:.2f}",
                     f"{28 * npx / 1e6:.2f}", f"{30 * 28 * npx / 1e6:.0f}"])
    print(f"moved between frames: median {np.median(moved):.1e}, max {moved.max():.1e} of the "
          f"diagonal; {100 * (moved > 1e-4).mean():.0f} % above 1e-4, "
          f"{100 * (moved > 1e-3).mean():.0f} % above 1e-3")
    print(table(["stream", "MB/frame 437K", "MB/frame 1.75M", "MB/s at 30 Hz (437K)"], rows))
    print(machine_load())


if __name__ == "__main__":
    main()
