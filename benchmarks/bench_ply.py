"""PLY reading speed: arapkit's own reader against a baseline tree, trimesh and plyfile.

Three files: the 437,645-vertex ASCII gzip dragon from ``../shared/data`` (skipped when
absent), and two binary little-endian files of 1,000,000 faces built here: a triangle grid
with ``energy``, ``rings`` and colour properties, and the same grid as quads and triangles
mixed (one quad, then two triangles ...), which trimesh's binary reader cannot read.

Every round times, in one process and interleaved, ``load_mesh`` of this tree and of the
baseline tree (imported as ``arapkit_a``, e.g. the commit before plyfile left the core),
then the bare readers: :func:`arapkit.io.ply.read_ply`, trimesh's ``load(process=False)``
and plyfile's ``PlyData.read`` (each skipped when not installed or when it cannot read the
file). The summary is the minimum over rounds, in seconds, and the ratio to this tree.

Usage::

    git archive <commit> src | tar -x -C /tmp/base
    python benchmarks/bench_ply.py --baseline /tmp/base/src --rounds 5
"""

from __future__ import annotations

import argparse
import gzip
import io
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DRAGON = ROOT.parent / "shared" / "data" / "meshes" / "dragon_vrip.ply.gz"


def grid(cells: int) -> tuple[np.ndarray, np.ndarray]:
    """An n x n vertex grid of at least ``cells`` cells, as (cells, 4) vertex indices."""
    n = int(np.ceil(np.sqrt(cells))) + 1
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    V = np.stack([x.ravel(), y.ravel(), np.sin(3 * x.ravel()) * 0.1], axis=1)
    i = np.arange(n - 1)
    a = (i[:, None] * n + i[None, :]).ravel()
    return V, np.stack([a, a + 1, a + n + 1, a + n], axis=1)


def vertex_bytes(V: np.ndarray) -> tuple[list[str], bytes]:
    """Header lines and records of the vertices with custom properties."""
    rng = np.random.default_rng(0)
    dt = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"),
          ("blue", "u1"), ("energy", "<f8"), ("rings", "<i4")]
    rec = np.empty(len(V), dtype=dt)
    rec["x"], rec["y"], rec["z"] = V.T
    for c in ("red", "green", "blue"):
        rec[c] = rng.integers(0, 256, len(V))
    rec["energy"], rec["rings"] = rng.random(len(V)), rng.integers(1, 9, len(V))
    names = {"<f4": "float", "u1": "uchar", "<f8": "double", "<i4": "int"}
    return [f"property {names[t]} {k}" for k, t in dt], rec.tobytes()


def binary_file(V: np.ndarray, cells: np.ndarray, faces: int, mixed: bool) -> bytes:
    """A binary little-endian PLY of ``faces`` triangles, or quads and triangles mixed."""
    props, vert = vertex_bytes(V)
    if mixed:
        # a quad, then the next cell as two triangles: 3 faces per two cells
        pairs = faces // 3
        rec = np.empty(pairs, dtype=[("k", "u1"), ("q", "<i4", (4,)), ("k1", "u1"),
                                     ("t1", "<i4", (3,)), ("k2", "u1"), ("t2", "<i4", (3,))])
        q, t = cells[0 : 2 * pairs : 2], cells[1 : 2 * pairs : 2]
        rec["k"], rec["q"], rec["k1"], rec["k2"] = 4, q, 3, 3
        rec["t1"], rec["t2"] = t[:, [0, 1, 2]], t[:, [0, 2, 3]]
        count = 3 * pairs
    else:
        tri = np.concatenate([cells[:, [0, 1, 2]], cells[:, [0, 2, 3]]])[:faces]
        rec = np.empty(len(tri), dtype=[("k", "u1"), ("i", "<i4", (3,))])
        rec["k"], rec["i"] = 3, tri
        count = len(tri)
    head = ["ply", "format binary_little_endian 1.0", f"element vertex {len(V)}", *props,
            f"element face {count}", "property list uchar int vertex_indices", "end_header"]
    return ("\n".join(head) + "\n").encode() + vert + rec.tobytes()


def readers(baseline: str | None):
    """name -> function(path, data) for every reader that is installed."""
    import arapkit.io as new

    out = {"load_mesh (this tree)": lambda p, d: new.load_mesh(p)}
    if baseline:
        import arapkit_a.io as old

        out["load_mesh (baseline)"] = lambda p, d: old.load_mesh(p)
    from arapkit.io.ply import read_ply

    out["arapkit.io.ply.read_ply"] = lambda p, d: read_ply(d, p)
    try:
        import trimesh

        out["trimesh.load"] = lambda p, d: trimesh.load(io.BytesIO(d), file_type="ply",
                                                        process=False)
    except ImportError:
        pass
    try:
        import plyfile

        out["plyfile.PlyData.read"] = lambda p, d: plyfile.PlyData.read(io.BytesIO(d))
    except ImportError:
        pass
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", help="src folder of the tree to compare with")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--faces", type=int, default=1_000_000)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_ply_"))
    if args.baseline:
        shutil.copytree(Path(args.baseline) / "arapkit", tmp / "arapkit_a")
        sys.path.insert(0, str(tmp))
    sys.path.insert(0, str(ROOT / "src"))
    # enough cells for both files (triangles take half a cell, the mixed file 2/3)
    V, cells = grid(2 * args.faces // 3 + 1)
    files = {}
    if DRAGON.exists():
        files["dragon ASCII gzip (437,645 v / 871,414 f)"] = DRAGON
    for mixed in (False, True):
        name = "binary mixed quads+triangles" if mixed else "binary triangles"
        path = tmp / (f"{'mixed' if mixed else 'tri'}.ply")
        path.write_bytes(binary_file(V, cells, args.faces, mixed))
        files[f"{name} ({len(V):,} v / {args.faces:,} f)"] = path
    funcs = readers(args.baseline)
    best: dict[tuple[str, str], float] = {}
    for r in range(args.rounds):
        for fname, path in files.items():
            data = path.read_bytes()
            if path.name.endswith(".gz"):
                data = gzip.decompress(data)
            for rname, f in funcs.items():
                t = time.perf_counter()
                try:
                    f(str(path), data)
                except Exception as e:  # a reader that cannot read this file
                    best[fname, rname] = float("nan")
                    if r == 0:
                        print(f"  {rname} on {fname}: {type(e).__name__}: {e}"[:160])
                    continue
                dt = time.perf_counter() - t
                best[fname, rname] = min(best.get((fname, rname), np.inf), dt)
        print(f"round {r + 1}/{args.rounds} done", flush=True)
    for fname in files:
        print(f"\n{fname}")
        ref = best[fname, "load_mesh (this tree)"]
        for rname in funcs:
            t = best[fname, rname]
            print(f"  {rname:28s} {t:7.3f} s   {t / ref:5.2f} x this tree's load_mesh")
    shutil.rmtree(tmp)


if __name__ == "__main__":
    main()
