"""ARAP dynamics: h-independence against libigl, agreement with libigl, iterations per step.

The scene: examples/bar.off's shape (``arapkit.mesh.shapes.bar``, 7 m x 0.4 m x 0.4 m,
1,154 vertices), its left end pinned, gravity 9.81 m/s^2 along -z, from rest, 1 s.

1. **h-independence.** The pose at t = 1 s with steps of 1/30, 1/60, 1/120 and 1/240 s;
   each change when the step is halved, as a fraction of the bounding-box diagonal
   (max over vertices). arapkit with its defaults (stiffness 3e4 N/m, damping 2/s) and
   without damping; libigl's ``arap_solve`` with ``with_dynamics`` (its Python package)
   with ``ym`` chosen so that at h = 1/60 its stiffness equals arapkit's, and gravity as
   its force ``f_ext = M g`` (its default spokes-and-rims energy, 10 iterations a step).
   arapkit's energy there is spokes-and-rims with raw cotangents too, so the two differ
   only in how the stiffness follows h (libigl's ``ym / h^2``).
2. **Agreement with libigl.** ``Simulator.like_libigl`` against libigl's compiled
   ``arap_solve`` over 30 steps of 1/30 s (max deviation / diagonal).
3. **Anderson acceleration.** Iterations per step and seconds for 1 s at 60 steps a
   second, plain against accelerated, interleaved ``--repeats`` times (min wall time).
4. **The stopping tolerance.** The same 1 s at 60 steps a second for ``tol`` 1e-4 ...
   1e-7, each against a reference solved to ``tol`` 1e-12: the largest deviation over
   the frames (fraction of the diagonal) and the iterations per step.
5. **Rigid parts.** The cost per frame of the same 1 s with a rigid bone (the middle 2 m
   of the bar) and with a shared-rotation group there, against the plain bar, interleaved
   ``--repeats`` times (min wall time), with the iterations per step.

Usage::

    python benchmarks/bench_dynamics.py [--repeats 3] [--only parts]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def scene():
    from arapkit.mesh.shapes import bar

    m = bar()
    return m, np.flatnonzero(m.vertices[:, 0] == 0), np.array([0.0, 0.0, -9.81])


def arapkit_pose(fps: int, **options) -> np.ndarray:
    from arapkit.methods.dynamics import simulate

    m, left, g = scene()
    return simulate(m, fps + 1, dt=1 / fps, handles=left, gravity=g, **options).vertices[-1]


def libigl_pose(fps: int, ym: float, steps: int | None = None) -> np.ndarray:
    import igl

    m, left, g = scene()
    V, F = m.vertices, m.faces.astype(np.int64)
    data = igl.ARAPData()
    data.energy = igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS
    data.with_dynamics, data.h, data.ym, data.max_iter = True, 1 / fps, ym, 10
    igl.arap_precomputation(V, F, 3, left.astype(np.int32), data)
    M = igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_VORONOI).diagonal()
    data.f_ext = M[:, None] * g[None, :]  # set after the precomputation, which zeroes it
    U = V.copy()
    for _ in range(fps if steps is None else steps):
        U = igl.arap_solve(V[left], data, U)
    return U


def h_independence() -> None:
    from arapkit.arap.dynamics import LIBIGL_ENERGY_SCALE
    from arapkit.methods.dynamics import DEFAULT_STIFFNESS

    m, _, _ = scene()
    diag = m.bounding_box_diagonal
    ym = DEFAULT_STIFFNESS * (1 / 60) ** 2 / LIBIGL_ENERGY_SCALE["spokes-and-rims"]
    runs = {
        "arapkit, defaults (damping 2/s)": lambda f: arapkit_pose(f),
        "arapkit, no damping": lambda f: arapkit_pose(f, damping=0.0),
        "arapkit, spokes-and-rims, raw cotan, no damping":
            lambda f: arapkit_pose(f, damping=0.0, energy="spokes-and-rims",
                                   weights="cotan"),
        f"libigl arap_solve, ym = {ym:.4g}": lambda f: libigl_pose(f, ym),
    }
    fps = (30, 60, 120, 240)
    print("| run | tip z at 1 s (h = 1/30 ... 1/240) | change 1/30 -> 1/60 | "
          "1/60 -> 1/120 | 1/120 -> 1/240 |")
    print("|---|---|---|---|---|")
    for name, run in runs.items():
        poses = {f: run(f) for f in fps}
        tips = ", ".join(f"{poses[f][:, 2].min():.3f}" for f in fps)
        changes = [np.abs(poses[a] - poses[b]).max() / diag
                   for a, b in zip(fps[:-1], fps[1:])]
        print(f"| {name} | {tips} | " + " | ".join(f"{100 * c:.2f} %" for c in changes)
              + " |")


def agreement() -> None:
    from arapkit.methods.dynamics import Simulator

    m, left, g = scene()
    ym = 50.0
    sim = Simulator.like_libigl(m, left, 1 / 30, ym=ym)
    f = sim.masses[:, None] * g
    U = libigl_pose(30, ym, steps=30)
    for _ in range(30):
        sim.step(forces=f)
    dev = np.abs(sim.positions - U).max() / m.bounding_box_diagonal
    moved = np.abs(U - m.vertices).max() / m.bounding_box_diagonal
    print(f"like_libigl vs libigl's arap_solve, 30 steps of 1/30 s, ym {ym:g}: max deviation "
          f"{dev:.2e} of the diagonal (the bar moved {moved:.2f} of it)")


def acceleration(repeats: int) -> None:
    from arapkit.methods.dynamics import simulate

    m, left, g = scene()
    best = {False: np.inf, True: np.inf}
    its = {}
    for _ in range(repeats):
        for acc in (False, True):
            t0 = time.perf_counter()
            tr = simulate(m, 61, dt=1 / 60, handles=left, gravity=g, accelerate=acc)
            best[acc] = min(best[acc], time.perf_counter() - t0)
            its[acc] = (tr.iterations.mean(), tr.iterations.max())
    for acc in (False, True):
        print(f"accelerate={acc}: iterations per step mean {its[acc][0]:.1f}, max "
              f"{its[acc][1]}; 60 steps in {best[acc]:.2f} s (min of {repeats})")
    print(f"ratio plain / accelerated: {best[False] / best[True]:.2f}x")


def tolerance_study() -> None:
    from arapkit.methods.dynamics import simulate

    m, left, g = scene()
    diag = m.bounding_box_diagonal
    ref = simulate(m, 61, dt=1 / 60, handles=left, gravity=g, tol=1e-12, max_iter=20000)
    print(f"reference (tol 1e-12): iterations per step mean {ref.iterations.mean():.1f}")
    print("| tol | iterations per step (mean, max) | largest deviation over 1 s |")
    print("|---|---|---|")
    for tol in (1e-4, 1e-5, 1e-6, 1e-7):
        tr = simulate(m, 61, dt=1 / 60, handles=left, gravity=g, tol=tol, max_iter=20000)
        err = np.abs(tr.vertices - ref.vertices).max() / diag
        print(f"| {tol:g} | {tr.iterations.mean():.1f}, {tr.iterations.max()} | "
              f"{100 * err:.3f} % of the diagonal |")


def parts_cost(repeats: int) -> None:
    from arapkit.mesh.groups import VertexGroups
    from arapkit.methods.dynamics import simulate

    m, left, g = scene()
    bone = np.flatnonzero(np.abs(m.vertices[:, 0] - 3.5) < 1.0)
    runs = {
        "plain": None,
        f"rigid bone ({len(bone)} vertices)": VertexGroups.from_lists(
            [("bone", bone, True)], m.n_vertices),
        "shared-rotation group (same vertices)": VertexGroups.from_lists(
            [("bone", bone, False)], m.n_vertices),
    }
    best = dict.fromkeys(runs, np.inf)
    its = {}
    for groups in runs.values():  # compiled and cached before the clock runs
        simulate(m, 3, dt=1 / 60, handles=left, gravity=g, groups=groups)
    for _ in range(repeats):
        for name, groups in runs.items():
            t0 = time.perf_counter()
            tr = simulate(m, 61, dt=1 / 60, handles=left, gravity=g, groups=groups)
            best[name] = min(best[name], time.perf_counter() - t0)
            its[name] = (tr.iterations.mean(), tr.iterations.max())
    print("| run | ms per frame | iterations per step (mean, max) | x plain |")
    print("|---|---|---|---|")
    for name in runs:
        print(f"| {name} | {1e3 * best[name] / 60:.1f} | {its[name][0]:.1f}, {its[name][1]} | "
              f"{best[name] / best['plain']:.2f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--only", choices=("parts",), help="run only this study")
    args = ap.parse_args()
    print(f"load average at start: {os.getloadavg()[0]:.2f}")
    if args.only is None:
        h_independence()
        agreement()
        acceleration(args.repeats)
        tolerance_study()
    parts_cost(args.repeats)
    print(f"load average at end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
