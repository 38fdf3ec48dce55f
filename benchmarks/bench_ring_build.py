"""r-ring build: time, peak memory and final size against the estimate made before it.

Each (mesh, r) runs in a fresh process per source tree, so that the peak resident memory
(``ru_maxrss``) belongs to that build alone: the process loads the mesh, compiles the
kernels on r = 1, notes its resident memory, estimates the build
(:func:`arapkit.arap.ringcost.estimate_ring_cost`, where the tree has it), then builds the
neighbourhoods once and reports the time, the peak over the noted memory and the size of
the structure. Trees are run interleaved (A, B, A, B) so that load from other processes
hits both.

Meshes: the MakeHuman body of ``anny_makehuman_pose_seq.npz`` (frame 0, 13,750 vertices, the
size of the 13,826-vertex teddy of issue 47) and ``bunny00.off`` (37,706 vertices), both
from ``../shared/data``. A case whose estimated peak exceeds ``--max-gb`` is not run (the
machine is shared) and reported with its estimate.

Usage::

    git archive <commit> src | tar -x -C /tmp/base      # the tree to compare with
    python benchmarks/bench_ring_build.py src /tmp/base/src --r 10 20 50 100
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
DATA = HERE.parent.parent / "shared" / "data"
MESHES = {"anny": DATA / "sequences" / "anny_makehuman_pose_seq.npz",
          "bunny": DATA / "meshes" / "bunny00.off"}


def load(name: str):
    """The benchmark's mesh ``name`` (the body's first frame, or the bunny)."""
    import numpy as np

    from arapkit import Mesh, load_mesh

    if name == "anny":
        d = np.load(MESHES[name])
        return Mesh(d["V"][0], d["F"], name="anny frame 0")
    return load_mesh(MESHES[name])


def child(name: str, r: int) -> None:
    """One build in this process; prints a JSON line."""
    import resource
    import time

    import numpy as np

    from arapkit.arap.rings import neighbourhoods_from_arrays
    from arapkit.mesh.weights import edge_weights

    m = load(name)
    n, E = m.n_vertices, m.edges
    w = edge_weights(m, "cotan-clamped")
    neighbourhoods_from_arrays(n, E, m.vertices, w, np.ones(n, np.int32))  # compile
    out: dict = {"mesh": name, "n": n, "r": r}
    try:
        from arapkit.arap.ringcost import estimate_ring_cost
    except ImportError:  # a tree from before the estimate
        estimate_ring_cost = None
    if estimate_ring_cost is not None:
        t0 = time.perf_counter()
        est = estimate_ring_cost(n, E, r)
        out.update(est_ms=1e3 * (time.perf_counter() - t0), est_bytes=est.bytes,
                   est_peak=est.peak_bytes, est_s=est.seconds,
                   est_edges=est.edge_entries, est_disk=est.disk_entries)
    with open("/proc/self/statm") as f:
        base = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    rings = np.full(n, r, np.int32)
    t0 = time.perf_counter()
    nb = neighbourhoods_from_arrays(n, E, m.vertices, w, rings)
    out["seconds"] = time.perf_counter() - t0
    out["peak_bytes"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 - base
    out["bytes"] = sum(a.nbytes for a in (nb.rings, nb.edge_ptr, nb.edge_idx, nb.edge_layer,
                                          nb.disk_ptr, nb.disk_idx, nb.disk_coef,
                                          nb.edge_count))
    out["edges"], out["disk"] = int(nb.edge_ptr[-1]), int(nb.disk_ptr[-1])
    print(json.dumps(out))


def run(src: str, name: str, r: int) -> dict:
    env = dict(os.environ, PYTHONPATH=src)
    # the trees' own refusal must not stop a case that --max-gb let through
    env["ARAPKIT_RING_MEMORY_MB"] = str(10**7)
    proc = subprocess.run([sys.executable, __file__, "--child", name, str(r)], env=env,
                          capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        return {"error": proc.stderr.strip().splitlines()[-1:]}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trees", nargs="*", help="source folders (src of a checkout)")
    ap.add_argument("--r", type=int, nargs="+", default=[10, 20, 50, 100])
    ap.add_argument("--meshes", nargs="+", default=list(MESHES))
    ap.add_argument("--max-gb", type=float, default=10.0,
                    help="skip a case whose estimated peak (the first tree's) is larger")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child[0], int(args.child[1]))
        return
    sys.path.insert(0, args.trees[0])
    import numpy as np

    from arapkit.arap.ringcost import estimate_ring_cost

    print("| mesh | r | tree | build s | peak RSS MiB | structure MiB | peak / structure "
          "| estimate: MiB (ratio) | estimate: s | estimate ms |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in args.meshes:
        m = load(name)
        for r in args.r:
            est = estimate_ring_cost(m.n_vertices, m.edges, r)
            # a tree from before the count kernel also held an int64 copy of the edge ids
            worst = est.peak_bytes + 8 * est.edge_entries
            for k, tree in enumerate(args.trees):
                need = est.peak_bytes if k == 0 else worst  # the first tree is this one
                if need > args.max_gb * 2**30:
                    print(f"| {name} | {r} | {tree} | not run: estimated "
                          f"{need / 2**30:.1f} GiB | | | | | {est.seconds:.0f} | |")
                    continue
                res = run(tree, name, r)
                if "error" in res:
                    print(f"| {name} | {r} | {tree} | error: {res['error']} |")
                    continue
                mib = res["bytes"] / 2**20
                line = (f"| {name} ({res['n']:,}) | {r} | {tree} | {res['seconds']:.2f} | "
                        f"{res['peak_bytes'] / 2**20:.0f} | {mib:.0f} | "
                        f"{res['peak_bytes'] / res['bytes']:.2f} |")
                if "est_bytes" in res:
                    ratio = res["est_bytes"] / res["bytes"]
                    line += (f" {res['est_peak'] / 2**20:.0f} ({ratio:.3f}) | "
                             f"{res['est_s']:.2f} | {res['est_ms']:.0f} |")
                else:
                    line += " | | |"
                print(line, flush=True)
    del np


if __name__ == "__main__":
    main()
