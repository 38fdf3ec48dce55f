"""2D (issue 48): folds on the extreme-drag suite beside libigl's dim=2 ARAP, and the speed of
puppet warping (drag frames, pins added and removed, meshing, rasterising).

Prints:

1. for each scenario of ``tests/drag_suite.py`` (every frame warm from the last): the most
   triangles folded in any frame and the frames with folds, for arapkit with its flip guard
   (the default), arapkit with ``flips="allow"`` (plain ARAP), libigl's ``dim=2``
   ``arap_solve`` with SPOKES (the same energy) and with its default energy (ELEMENTS for
   2D triangles); and the time per iteration of arapkit's guarded loop against libigl's
   (SPOKES, same mesh, same rounds);
2. on the 10K-vertex puppet (the project's sprite at 1024 px, meshed at 6.5 px): a drag of
   the hand pin, 60 frames of at most ``--frame-iters`` iterations warm from the last
   (pins met exactly in each): median and 95th percentile frame time; per-part times of an
   iteration (the global solve, the local step, the flip guard's test);
3. adding and removing a pin on that puppet through the factor update
   (:mod:`arapkit.arap.pinupdate`) against a refactorisation, and the solve per iteration
   with the updated factor;
4. meshing the 1024 x 1024 sprite and rasterising one warped frame of it.

Timings on a shared machine are noisy: section 2-4 figures are medians (and minima, the
best estimate of the unloaded cost) over repeats; ratios compare figures of the same rounds.

Usage::

    python benchmarks/bench_2d.py            # everything (a few minutes)
    python benchmarks/bench_2d.py --quick    # fewer repeats, no libigl timing
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from drag_suite import scenarios  # noqa: E402

from arapkit import Deformer  # noqa: E402
from arapkit.arap.flips import max_step  # noqa: E402
from arapkit.mesh.planar import signed_areas  # noqa: E402


def folds_of(P, F) -> int:
    return int((signed_areas(P, F) <= 0).sum())


def ours(sc, flips: str):
    V2 = np.ascontiguousarray(sc.mesh.vertices[:, :2])
    d = Deformer((V2, sc.mesh.faces), sc.handles, flips=flips)
    P, folds, its, t = V2.copy(), [], 0, 0.0
    for i, T in enumerate(sc.frames):
        t0 = time.perf_counter()
        r = d.solve(T, init=P, angles=sc.angle(i), tol=1e-4, max_iter=1000)
        t += time.perf_counter() - t0
        P = r.vertices
        folds.append(folds_of(P, sc.mesh.faces))
        its += r.iterations
    return folds, 1e3 * t / max(its, 1)


def libigl(sc, energy):
    import igl

    V2 = np.ascontiguousarray(sc.mesh.vertices[:, :2])
    F = sc.mesh.faces.astype(np.int64)
    data = igl.ARAPData()
    data.energy = energy
    data.max_iter = 100
    igl.arap_precomputation(V2, F, 2, sc.handles.astype(np.int32), data)
    U, folds = V2.copy(), []
    t0 = time.perf_counter()
    for T in sc.frames:  # libigl has no pin turns: the suite's angles are left out
        U = igl.arap_solve(np.ascontiguousarray(T), data, U)
        folds.append(folds_of(U, F))
    ms = 1e3 * (time.perf_counter() - t0) / (100 * len(sc.frames))
    return folds, ms


def fold_table(quick: bool) -> None:
    print("\n1. folds on the extreme-drag suite (max folded triangles in a frame / frames "
          "with folds)")
    try:
        import igl
    except ImportError:
        igl = None
    head = f"{'scenario':<14}{'frames':>7}{'arapkit':>10}{'plain':>10}"
    if igl is not None:
        head += f"{'libigl spokes':>15}{'libigl elements':>17}{'ms/it ours':>12}{'ms/it igl':>11}"
    print(head)
    for sc in scenarios():
        g, ms = ours(sc, "prevent")
        p, _ = ours(sc, "allow")
        row = (f"{sc.name:<14}{len(sc.frames):>7}{f'{max(g)}/{sum(x > 0 for x in g)}':>10}"
               f"{f'{max(p)}/{sum(x > 0 for x in p)}':>10}")
        if igl is not None:
            s, ms_igl = libigl(sc, igl.ARAP_ENERGY_TYPE_SPOKES)
            e, _ = libigl(sc, igl.ARAP_ENERGY_TYPE_ELEMENTS)
            row += (f"{f'{max(s)}/{sum(x > 0 for x in s)}':>15}"
                    f"{f'{max(e)}/{sum(x > 0 for x in e)}':>17}{ms:>12.3f}{ms_igl:>11.3f}")
        print(row)
    print("(the suite: tests/drag_suite.py, 451-vertex strip; libigl without pin turns)")


def puppet(spacing: float = 6.5):
    from arapkit.image.meshing import mesh_mask, shape_mask
    from arapkit.image.sprite import puppet_pins, puppet_sprite

    img = puppet_sprite(1024)
    at = puppet_pins(1024)
    mask = shape_mask(img)
    return img, at, mask, mesh_mask(mask, spacing, pins=at, name="puppet")


def stats(ts) -> str:
    ts = 1e3 * np.asarray(ts)
    return f"median {np.median(ts):.2f} ms, p95 {np.percentile(ts, 95):.2f}, min {ts.min():.2f}"


def drag(mesh, at, frame_iters: int, rounds: int) -> None:
    print(f"\n2. drag frames on the puppet ({mesh.n_vertices} vertices, {mesh.n_faces} "
          f"triangles), at most {frame_iters} iterations a frame")
    d = Deformer(mesh, np.arange(len(at)))
    d.prepare()
    times, its, igl_ms = [], [], []
    for _ in range(rounds):
        igl_ms.append(libigl_iteration(mesh, at))
        P, T = mesh.vertices[:, :2].copy(), at.copy()
        for _f in range(60):
            T[0] += [1.5, -3.0]  # the hand pin, 3.4 px a frame (200 px over the drag)
            t0 = time.perf_counter()
            r = d.solve(T, init=P, max_iter=frame_iters)
            times.append(time.perf_counter() - t0)
            its.append(r.iterations)
            P = r.vertices
            assert np.abs(P[:len(at), :2] - T).max() == 0.0 and r.folds == 0
    print(f"   frame: {stats(times)}; {np.mean(its):.1f} iterations a frame")
    if igl_ms[0] is not None:
        print(f"   libigl dim=2 arap_solve, one iteration on the same mesh: "
              f"{stats(np.array(igl_ms) / 1e3)}")
    # the parts of one iteration, each alone
    p, be = d.problem, d.backend
    el = p.elimination
    rhs = np.random.default_rng(0).normal(size=(len(el.free), 2))
    out = np.empty_like(rhs)
    Pi = np.ascontiguousarray(P[p.perm, :2])
    R = np.empty((p.energy.n_owners, 2, 2))
    F = p.graph.faces
    sign = np.sign(signed_areas(p.rest_positions, F))
    parts = {"global solve": lambda: el.solve(rhs, out), "local step": lambda: be.local(Pi, R),
             "flip test": lambda: max_step(Pi, Pi + 0.01, F, sign, np.zeros(len(F)))}
    for name, f in parts.items():
        ts = []
        for _ in range(50 * rounds):
            t0 = time.perf_counter()
            f()
            ts.append(time.perf_counter() - t0)
        print(f"   {name:<13} {stats(ts)}")


def libigl_iteration(mesh, at) -> float | None:
    """ms per iteration of libigl's dim=2 ``arap_solve`` (SPOKES) on ``mesh`` (10 iterations)."""
    try:
        import igl
    except ImportError:
        return None
    V2 = np.ascontiguousarray(mesh.vertices[:, :2])
    data = igl.ARAPData()
    data.energy = igl.ARAP_ENERGY_TYPE_SPOKES
    data.max_iter = 10
    igl.arap_precomputation(V2, mesh.faces.astype(np.int64), 2,
                            np.arange(len(at), dtype=np.int32), data)
    T = at.copy()
    T[0] += [30, -60]
    t0 = time.perf_counter()
    igl.arap_solve(np.ascontiguousarray(T), data, V2.copy())
    return 1e2 * (time.perf_counter() - t0)


def pins(mesh, at, rounds: int) -> None:
    print("\n3. adding and removing a pin (no refactorisation) against a refactorisation")
    base = np.arange(len(at))
    extra = int(np.argmin(np.linalg.norm(mesh.vertices[:, :2] - [560.0, 600.0], axis=1)))
    d = Deformer(mesh, base)
    d.prepare()
    add, remove, refactor = [], [], []
    for _ in range(10 * rounds):
        t0 = time.perf_counter()
        d.set_handles(np.r_[base, extra])
        d.prepare()
        add.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        d.set_handles(base[1:])
        d.prepare()
        remove.append(time.perf_counter() - t0)
        d.set_handles(base)
        t0 = time.perf_counter()
        d.set_handles(np.r_[base, extra], update_factor=False)
        d.prepare()
        refactor.append(time.perf_counter() - t0)
        d.set_handles(base, update_factor=False)
        d.prepare()
    print(f"   add a pin:    {stats(add)}")
    print(f"   remove a pin: {stats(remove)}")
    print(f"   refactorise:  {stats(refactor)}  (ratio of medians "
          f"{np.median(refactor) / np.median(add):.1f}x)")
    d.set_handles(np.r_[base, extra])
    el = d.problem.elimination
    rhs = np.random.default_rng(0).normal(size=(len(el.free), 2))
    ts = []
    for _ in range(50 * rounds):
        t0 = time.perf_counter()
        el.solve(rhs)
        ts.append(time.perf_counter() - t0)
    print(f"   global solve with the updated factor: {stats(ts)}")


def images(img, at, mask, rounds: int) -> None:
    from arapkit.image.meshing import mesh_mask
    from arapkit.image.warp import ImageWarp

    print("\n4. meshing and rasterising the 1024 x 1024 sprite")
    ts = []
    for _ in range(3 * rounds):
        t0 = time.perf_counter()
        m = mesh_mask(mask, pins=at)
        ts.append(time.perf_counter() - t0)
    print(f"   meshing (default density, {m.n_vertices} vertices): {stats(ts)}")
    w = ImageWarp(img, at)
    to = at.copy()
    to[0] += [120, -300]
    w.frame(to, max_iter=300)
    ts = []
    for _ in range(5 * rounds):
        t0 = time.perf_counter()
        w.render(w.vertices)
        ts.append(time.perf_counter() - t0)
    print(f"   rasterising a warped frame: {stats(ts)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--frame-iters", type=int, nargs="+", default=[1, 3])
    a = ap.parse_args()
    rounds = 1 if a.quick else 3
    fold_table(a.quick)
    img, at, mask, mesh = puppet()
    for k in a.frame_iters:
        drag(mesh, at, k, rounds)
    pins(mesh, at, rounds)
    images(img, at, mask, rounds)


if __name__ == "__main__":
    main()
