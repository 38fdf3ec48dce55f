"""Fitting a template to a scan: arapkit.fit against trimesh's nricp, and against ground truth.

Four measurements (issue 46, section 3), each side by side in one run:

a. trimesh's own test pair (``tests/data/trimesh_nricp``: reference.obj -> target.obj, its
   13 landmarks): accuracy by trimesh's own measures (mean closest-point distance, mean
   landmark error) and time, arapkit against ``nricp_amberg`` and ``nricp_sumner`` with
   the steps of trimesh's test, interleaved, repeated; the bars are trimesh's (1e-3, 4e-4)
   and a third of the faster peer's time.
b. a 13,750-vertex template (anny frame 0) fitted to a later frame given as a point cloud
   with normals, 12 landmarks for every method: error against the ground truth (the frames
   share connectivity) and time; bar: 10x faster than both peers, lower error.
c. pose pairs with exact ground truth (anny 0 -> 1..8; panda 0 -> 5, 10 .. 60, subdivided
   twice to 14,371 vertices): the later frame sampled as a cloud (one point per template
   vertex, normals of the triangles), 0.2 % noise, the 30 % facing away from a random view
   missing, 12 landmarks (farthest-point samples, their true positions); RMS error to the
   truth as a fraction of the diagonal, and the time of a fit with the template's Fitter
   kept (the first fit of a landmark set also makes its factors). Bars: median <= 0.5 %,
   >= 90 % of pairs under 1 %, median time <= 1 s.
d. the same pairs with a rigidity map learned (``arapkit.learn_rings``, r 1..6, omega
   auto) from the other frames of the sequence (all but the pair's two), against every
   single r in 1..4; bar: the learned map's median error below the best single r's.

Times are wall-clock and CPU time of this process (``time.process_time``): on a shared
machine the CPU time is the closer to what an idle machine shows.

Usage::

    python benchmarks/bench_fit.py              # a-d (about 20 minutes on 2 busy cores)
    python benchmarks/bench_fit.py --only a b   # some of them
    python benchmarks/bench_fit.py --quick      # fewer pairs and repeats
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / ".." / "shared" / "data" / "sequences"
TRIMESH = ROOT / "tests" / "data" / "trimesh_nricp"
#: a clean mesh target ends one stage softer (as trimesh's test tunes its own steps)
CLEAN_SCHEDULE = (0.3, 0.1, 0.03, 0.01, 0.003, 0.001)


# -- data --------------------------------------------------------------------------------


def sample_surface(V, F, n, rng, noise=0.0, missing=0.0, view=None):
    """``n`` points by area with their triangles' normals, Gaussian noise of ``noise`` times
    the diagonal, less the fraction ``missing`` facing most away from ``view``."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cross = np.cross(b - a, c - a)
    area = np.linalg.norm(cross, axis=1)
    f = rng.choice(len(F), size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    P = a[f] + u[:, None] * (b[f] - a[f]) + v[:, None] * (c[f] - a[f])
    N = cross[f] / area[f, None]
    P = P + rng.normal(0.0, noise * np.linalg.norm(np.ptp(V, axis=0)), P.shape)
    if missing:
        keep = np.sort(np.argsort(N @ np.asarray(view))[int(missing * n):])
        P, N = P[keep], N[keep]
    return P, N


def farthest_points(V, k, rng):
    """``k`` vertices by farthest-point sampling from a random start."""
    idx = [int(rng.integers(len(V)))]
    d = np.linalg.norm(V - V[idx[0]], axis=1)
    for _ in range(k - 1):
        idx.append(int(d.argmax()))
        d = np.minimum(d, np.linalg.norm(V - V[idx[-1]], axis=1))
    return np.array(idx)


def subdivide(V, F):
    """Midpoint subdivision of every frame of V (frames x n x 3): linear, so the truth of
    the new vertices is exact in every frame."""
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    uE, inv = np.unique(E, axis=0, return_inverse=True)
    m = V.shape[1] + inv.ravel().reshape(3, len(F)).T
    a, b, c = F.T
    F2 = np.concatenate([np.stack([a, m[:, 0], m[:, 2]], 1), np.stack([m[:, 0], b, m[:, 1]], 1),
                         np.stack([m[:, 2], m[:, 1], c], 1), m])
    return np.concatenate([V, 0.5 * (V[:, uE[:, 0]] + V[:, uE[:, 1]])], axis=1), F2


def sequences(quick: bool):
    """(name, V frames, F, pairs) of the pose sequences."""
    d = np.load(DATA / "anny_makehuman_pose_seq.npz")
    pairs = [(0, k) for k in range(1, 9)]
    yield "anny", d["V"].astype(np.float64), d["F"], pairs[::2] if quick else pairs
    d = np.load(DATA / "panda_walk_seq.npz")
    V, F = subdivide(*subdivide(d["V"].astype(np.float64), d["F"]))
    pairs = [(0, k) for k in range(5, 61, 5)]
    yield "panda", V, F, pairs[::3] if quick else pairs


def rms(X, G):
    return float(np.sqrt(((X - G) ** 2).sum(axis=1).mean()) / np.linalg.norm(np.ptp(G, axis=0)))


def timed(fn, *args, **kwargs):
    """``fn(*args, **kwargs)``, its wall-clock and CPU seconds."""
    t, c = time.perf_counter(), time.process_time()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t, time.process_time() - c


# -- a: trimesh's pair -----------------------------------------------------------------------


def bench_a(repeat: int) -> dict:
    import trimesh

    import arapkit

    ref = arapkit.load_mesh(TRIMESH / "reference.obj")
    tgt = arapkit.load_mesh(TRIMESH / "target.obj")
    pairs = np.array(json.loads((TRIMESH / "landmark_pairs.json").read_text()))
    lm_t = tgt.vertices[pairs[:, 1]]
    target = trimesh.Trimesh(tgt.vertices, tgt.faces, process=False)
    # trimesh's test: the source placed by procrustes on the landmarks first, then the steps
    source = trimesh.Trimesh(ref.vertices, ref.faces, process=False)
    T = trimesh.registration.procrustes(ref.vertices[pairs[:, 0]], lm_t)[0]
    source.vertices = trimesh.transformations.transform_points(source.vertices, T)
    amberg_steps = [[0.02, 3, 0.5, 10], [0.007, 3, 0.5, 10], [0.002, 3, 0.5, 10]]
    sumner_steps = [[wc, 0.0001, 1, 1000, 1] for wc in (0.1, 0.1, 1, 5, 10, 50, 100, 1000,
                                                          10000)]
    runs = {
        "arapkit.fit": lambda: arapkit.fit(ref, tgt, (pairs[:, 0], lm_t),
                                           schedule=CLEAN_SCHEDULE).vertices,
        "nricp_amberg": lambda: trimesh.registration.nricp_amberg(
            source, target, source_landmarks=pairs[:, 0], target_positions=lm_t,
            steps=amberg_steps, distance_threshold=0.05),
        "nricp_sumner": lambda: trimesh.registration.nricp_sumner(
            source, target, source_landmarks=pairs[:, 0], target_positions=lm_t,
            steps=sumner_steps, distance_threshold=0.05),
    }
    runs["arapkit.fit"]()  # compiles (or loads) the kernels
    times = {k: [] for k in runs}
    cpu = {k: [] for k in runs}
    out = {}
    for _ in range(repeat):  # interleaved: the machine's load hits all alike
        for name, fn in runs.items():
            out[name], wall, c = timed(fn)
            times[name].append(wall)
            cpu[name].append(c)
    rows = {}
    for name, X in out.items():
        d = trimesh.proximity.closest_point(target, X)[1]
        dl = np.linalg.norm(X[pairs[:, 0]] - lm_t, axis=1)
        rows[name] = {"mean_cp": float(d.mean()), "max_cp": float(d.max()),
                      "landmark_mean": float(dl.mean()),
                      "wall_s": float(np.median(times[name])),
                      "cpu_s": float(np.median(cpu[name]))}
    fastest = min(rows["nricp_amberg"]["wall_s"], rows["nricp_sumner"]["wall_s"])
    print(f"\n## a. trimesh's pair ({len(ref.vertices)} -> {len(tgt.vertices)} vertices, 13 "
          f"landmarks), median of {repeat} interleaved runs")
    print("| method | mean closest-point distance | max | mean landmark error | wall s | "
          "CPU s |")
    print("|---|---|---|---|---|---|")
    for name, r in rows.items():
        print(f"| {name} | {r['mean_cp']:.2e} | {r['max_cp']:.3f} | {r['landmark_mean']:.1e} | "
              f"{r['wall_s']:.3f} | {r['cpu_s']:.3f} |")
    ours = rows["arapkit.fit"]
    print(f"bars: mean cp < 1e-3: {ours['mean_cp'] < 1e-3}; landmarks < 4e-4: "
          f"{ours['landmark_mean'] < 4e-4}; time {ours['wall_s'] / fastest:.2f} of the faster "
          f"peer's (bar 0.33): {ours['wall_s'] <= fastest / 3}")
    return rows


# -- b: a 13K template, trimesh alongside -------------------------------------------------------


def bench_b(frame: int) -> dict:
    import trimesh

    import arapkit

    d = np.load(DATA / "anny_makehuman_pose_seq.npz")
    V, F = d["V"].astype(np.float64), d["F"]
    rng = np.random.default_rng(0)
    lm = farthest_points(V[0], 12, rng)
    P, N = sample_surface(V[frame], F, len(V[0]), rng)
    template = arapkit.Mesh(V[0], F, name="anny frame 0")
    source = trimesh.Trimesh(V[0], F, process=False)
    arapkit.fit(template, P, (lm, V[frame][lm]), normals=N)  # kernels compiled
    runs = {
        "arapkit.fit": lambda: arapkit.fit(template, P, (lm, V[frame][lm]), normals=N).vertices,
        # a point-cloud target needs use_faces=False (it raises otherwise)
        "nricp_amberg": lambda: trimesh.registration.nricp_amberg(
            source, P, source_landmarks=lm, target_positions=V[frame][lm], use_faces=False),
        "nricp_sumner": lambda: trimesh.registration.nricp_sumner(
            source, P, source_landmarks=lm, target_positions=V[frame][lm], use_faces=False),
    }
    rows = {}
    for name, fn in runs.items():
        X, wall, c = timed(fn)
        rows[name] = {"rms_error": rms(X, V[frame]), "wall_s": wall, "cpu_s": c}
    print(f"\n## b. anny frame 0 -> frame {frame} as a point cloud ({len(P)} points with normals, "
          f"{len(V[0])}-vertex template, 12 landmarks; trimesh's default steps)")
    print("| method | RMS error to the truth (% of diagonal) | wall s | CPU s |")
    print("|---|---|---|---|")
    for name, r in rows.items():
        print(f"| {name} | {100 * r['rms_error']:.3f} | {r['wall_s']:.2f} | {r['cpu_s']:.2f} |")
    ours = rows["arapkit.fit"]
    peers = [rows["nricp_amberg"], rows["nricp_sumner"]]
    print(f"bars: >= 10x faster than both: "
          f"{all(p['wall_s'] >= 10 * ours['wall_s'] for p in peers)} (x"
          f"{min(p['wall_s'] for p in peers) / ours['wall_s']:.1f}); lower error than both: "
          f"{all(ours['rms_error'] < p['rms_error'] for p in peers)}")
    return rows


# -- c and d: pose pairs ---------------------------------------------------------------------


def pair_targets(V, F, pairs, seed=0):
    """Each pair's scan (points, normals) and landmarks, made once."""
    rng = np.random.default_rng(seed)
    lm = farthest_points(V[0], 12, rng)
    out = []
    for _, k in pairs:
        view = rng.normal(size=3)
        P, N = sample_surface(V[k], F, V.shape[1], rng, noise=0.002, missing=0.3,
                              view=view / np.linalg.norm(view))
        out.append((k, P, N))
    return lm, out


def bench_c(quick: bool) -> dict:
    import arapkit

    results = {}
    for name, V, F, pairs in sequences(quick):
        template = arapkit.Mesh(V[0], F, name=name)
        lm, targets = pair_targets(V, F, pairs)
        fitter = arapkit.Fitter(template)
        fitter.fit(targets[0][1], (lm, V[targets[0][0]][lm]), normals=targets[0][2])  # warm
        # timed from a fresh Fitter: its precomputation apart, the factors in the first fit
        fitter, setup_wall, setup_cpu = timed(arapkit.Fitter, template)
        rows = []
        for k, P, N in targets:
            res, wall, c = timed(fitter.fit, P, (lm, V[k][lm]), normals=N)
            rows.append({"frame": k, "rms_error": rms(res.vertices, V[k]), "wall_s": wall,
                         "cpu_s": c, "iterations": res.report.iterations,
                         "factorisations": res.report.factorisations,
                         "pose_change": rms(V[0], V[k])})
        results[name] = {"vertices": V.shape[1], "pairs": rows, "setup_wall_s": setup_wall,
                         "setup_cpu_s": setup_cpu}
    _summary_c(results)
    return results


def _summary_c(results: dict) -> None:
    print("\n## c. pose pairs: scan with 0.2 % noise, 30 % missing (one side), 12 landmarks")
    print("| sequence | vertices | pairs | median RMS error | pairs under 1 % | median wall s | "
          "median CPU s | errors (pose change) |")
    print("|---|---|---|---|---|---|---|---|")
    every = []
    for name, r in results.items():
        e = np.array([p["rms_error"] for p in r["pairs"]])
        every += [p for p in r["pairs"]]
        detail = ", ".join(f"{100 * p['rms_error']:.2f} ({100 * p['pose_change']:.1f})"
                           for p in r["pairs"])
        print(f"| {name} | {r['vertices']} | {len(e)} | {100 * np.median(e):.3f} % | "
              f"{np.mean(e < 0.01):.0%} | {np.median([p['wall_s'] for p in r['pairs']]):.2f} | "
              f"{np.median([p['cpu_s'] for p in r['pairs']]):.2f} | {detail} |")
    e = np.array([p["rms_error"] for p in every])
    wall = np.median([p["wall_s"] for p in every])
    cpu = np.median([p["cpu_s"] for p in every])
    print(f"| all | | {len(e)} | {100 * np.median(e):.3f} % | {np.mean(e < 0.01):.0%} | "
          f"{wall:.2f} | {cpu:.2f} | |")
    for name, r in results.items():
        print(f"{name}: Fitter(template) {r['setup_wall_s']:.2f} s wall, {r['setup_cpu_s']:.2f} "
              "s CPU, once per template; the first fit also factorises its stages")
    print(f"bars: median <= 0.5 %: {np.median(e) <= 0.005}; >= 90 % under 1 %: "
          f"{np.mean(e < 0.01) >= 0.9}; median time <= 1 s: wall {wall <= 1.0}, CPU {cpu <= 1.0}")


def bench_d(quick: bool, rings=(1, 2, 3, 4)) -> dict:
    import arapkit

    results = {}
    for name, V, F, pairs in sequences(quick):
        template = arapkit.Mesh(V[0], F, name=name)
        lm, targets = pair_targets(V, F, pairs)
        errors = {f"r = {r}": [] for r in rings}
        errors["learned"] = []
        fitters = {r: arapkit.Fitter(template, r) for r in rings}
        learn_s = []
        for k, P, N in targets:
            for r in rings:
                res = fitters[r].fit(P, (lm, V[k][lm]), normals=N)
                errors[f"r = {r}"].append(rms(res.vertices, V[k]))
            others = [j for j in range(1, len(V)) if j != k]
            learned, wall, _ = timed(arapkit.learn_rings, template, V[others], r_max=6,
                                     omega="auto")
            learn_s.append(wall)
            res = arapkit.Fitter(template, learned.rings).fit(P, (lm, V[k][lm]), normals=N)
            errors["learned"].append(rms(res.vertices, V[k]))
        results[name] = {"errors": errors, "learn_s": float(np.median(learn_s))}
    print("\n## d. learned rigidity (from the other frames) against single r, same pairs as c")
    print("| sequence | " + " | ".join(results[next(iter(results))]["errors"]) + " |")
    print("|---|" + "---|" * len(results[next(iter(results))]["errors"]))
    pooled: dict[str, list] = {}
    for name, r in results.items():
        cells = []
        for key, e in r["errors"].items():
            pooled.setdefault(key, []).extend(e)
            cells.append(f"{100 * np.median(e):.3f} %")
        print(f"| {name} (median) | " + " | ".join(cells) + " |")
    print("| all (median) | " + " | ".join(f"{100 * np.median(e):.3f} %"
                                          for e in pooled.values()) + " |")
    single = {k: np.median(v) for k, v in pooled.items() if k != "learned"}
    best = min(single, key=single.get)
    learned = np.median(pooled["learned"])
    print(f"bar: learned {100 * learned:.3f} % against the best single r ({best}) "
          f"{100 * single[best]:.3f} %: {'met' if learned < single[best] else 'not met'} "
          f"(difference {100 * (learned - single[best]):+.3f} points)")
    for name, r in results.items():
        print(f"{name}: learning took {r['learn_s']:.1f} s a pair (median)")
    return results


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--only", nargs="+", choices="abcd", default=list("abcd"))
    p.add_argument("--quick", action="store_true", help="fewer pairs and repeats")
    p.add_argument("--repeat", type=int, default=5, help="interleaved runs of a")
    p.add_argument("--frame", type=int, default=4, help="anny frame of b")
    p.add_argument("--json", metavar="FILE", help="also write every number as JSON")
    args, _ = p.parse_known_args(argv)  # run_all passes its own options to every script
    if not (DATA / "anny_makehuman_pose_seq.npz").exists():
        print(f"skipped: {DATA} not found (benchmarks need ../shared/data)")
        return 0
    try:
        import rtree  # noqa: F401 - trimesh's nricp needs it
    except ImportError:
        print("skipped: trimesh.registration needs rtree (pip install rtree)")
        return 0
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"# bench_fit: {os.cpu_count()} cores, load average {load:.1f} at the start")
    out = {}
    if "a" in args.only:
        out["a"] = bench_a(2 if args.quick else args.repeat)
    if "b" in args.only:
        out["b"] = bench_b(args.frame)
    if "c" in args.only:
        out["c"] = bench_c(args.quick)
    if "d" in args.only:
        out["d"] = bench_d(args.quick)
    if hasattr(os, "getloadavg"):
        print(f"# load average {os.getloadavg()[0]:.1f} at the end")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
