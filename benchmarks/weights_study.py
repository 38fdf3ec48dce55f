"""Which edge weights should be the default? Raw cotangents, clamped cotangents and
intrinsic-Delaunay cotangents (Sharp & Crane 2020, the ``robust-laplacian`` package) on every
mesh of ``../shared/data/meshes`` (the table of ``docs/weights.md``).

For each mesh and weighting, with the hand-written handles of ``tests/data/real_handles``
(base fixed, top dragged sideways by 15 % of the bounding-box diagonal):

* ``neg``: negative weights; ``new_edges``: intrinsic edges that are not mesh edges;
* ``pd_r``: the ring sizes r = 1..6 whose reduced system factorises (positive definite);
* ``drift``: largest displacement, over the diagonal, when every handle stays at rest
  (r = 1; 0 means the rest shape is a fixed point), and the energy reported there;
* ``E_r``, ``it_r``, ``folds_r``: energy, iterations and fraction of edges whose dihedral
  angle turns by more than 60 degrees after the drag, at r = 1 and 3 (max 300 iterations);
* ``dx_cotan_r``: largest distance to the raw-cotangent result, over the diagonal.

Intrinsic weights live on the intrinsic triangulation's edge graph, which differs from the
mesh's on obtuse meshes; the study gives the solver that graph (the r-ring neighbourhoods
are then taken on it). The dragon scan runs r = 1 only, 100 iterations.

Usage::

    python benchmarks/weights_study.py               # every mesh, JSON lines on stdout
    python benchmarks/weights_study.py cow.off hand.off
    python benchmarks/weights_study.py --markdown rows.jsonl   # the docs table
"""

from __future__ import annotations

import json
import sys
import time
from functools import cached_property
from pathlib import Path

import numpy as np
import scipy.sparse as sp

import arapkit.methods.deformer as solver
from arapkit import Deformer, InputError, Mesh, load_mesh
from arapkit.io import load_handles
from arapkit.mesh.weights import CLAMP_FRACTION, edge_weights

ROOT = Path(__file__).resolve().parents[1]
MESHES = ROOT.parent / "shared" / "data" / "meshes"
HANDLES = ROOT / "tests" / "data" / "real_handles"
KINDS = ("cotan", "cotan-clamped", "intrinsic")


class GraphMesh(Mesh):
    """``mesh`` with its edge graph replaced (the intrinsic triangulation's edges)."""

    def __init__(self, mesh: Mesh, edges: np.ndarray) -> None:  # noqa: D107 - no validation
        for key in ("name", "notes", "dropped_faces", "vertices", "faces"):
            setattr(self, key, getattr(mesh, key))
        self._graph = edges

    @cached_property
    def edges(self) -> np.ndarray:
        return self._graph


def intrinsic_graph(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Edges and weights of the intrinsic-Delaunay cotangent Laplacian, floored like the
    clamped cotangents (right-triangle grids give exact zeros)."""
    import robust_laplacian

    L, _ = robust_laplacian.mesh_laplacian(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    U = sp.triu(sp.csr_matrix(L), 1).tocoo()
    w = -U.data
    return np.stack([U.row, U.col], 1).astype(np.int64), np.maximum(
        w, CLAMP_FRACTION * np.abs(w).mean())


def deformer(mesh: Mesh, kind: str, h: np.ndarray, r: int, graph) -> Deformer:
    if kind != "intrinsic":
        return Deformer(mesh, h, rings=r, weights=kind)
    edges, w = graph
    original = solver.edge_weights
    solver.edge_weights = lambda m, k: w  # study only: hand the solver the intrinsic graph
    try:
        return Deformer(GraphMesh(mesh, edges), h, rings=r, weights="cotan-clamped")
    finally:
        solver.edge_weights = original


def fold_fraction(mesh: Mesh, X: np.ndarray, degrees: float = 60.0) -> float:
    F, fe = mesh.faces, mesh.face_edges
    counts = np.bincount(fe.ravel(), minlength=len(mesh.edges))
    order = np.argsort(fe.ravel(), kind="stable")
    faces_by_edge = np.repeat(np.arange(len(F)), 3)[order]
    start = np.concatenate([[0], np.cumsum(counts)])
    two = np.flatnonzero(counts == 2)
    f1, f2 = faces_by_edge[start[two]], faces_by_edge[start[two] + 1]

    def dihedral(P):
        n = np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        return np.degrees(np.arccos(np.clip(np.sum(n[f1] * n[f2], 1), -1, 1)))

    turned = np.abs(dihedral(X) - dihedral(mesh.vertices)) > degrees
    return float(turned.sum()) / len(mesh.edges)


def available_kinds() -> tuple[str, ...]:
    """The weightings this machine can run (intrinsic needs ``pip install robust-laplacian``)."""
    try:
        import robust_laplacian  # noqa: F401
    except ImportError:
        print("note: robust-laplacian is not installed; intrinsic weights are skipped",
              file=sys.stderr)
        return tuple(k for k in KINDS if k != "intrinsic")
    return KINDS


def study(path: Path, ring_sizes=range(1, 7), drags=(1, 3), max_iter=300,
          kinds: tuple[str, ...] = KINDS) -> list[dict]:
    mesh = load_mesh(path)
    hs = load_handles(HANDLES / f"{path.name.split('.')[0]}.json", mesh.vertices)
    h, T = hs.indices, hs.targets
    diag = mesh.bounding_box_diagonal
    rows, shapes = [], {}
    for kind in kinds:
        t0 = time.perf_counter()
        graph = intrinsic_graph(mesh) if kind == "intrinsic" else None
        w = graph[1] if graph else edge_weights(mesh, kind)
        row = {"mesh": path.name, "n": mesh.n_vertices, "weights": kind,
               "neg": int((w < 0).sum()), "edges": len(w)}
        if graph:
            own = {tuple(e) for e in np.sort(mesh.edges, 1).tolist()}
            row["new_edges"] = sum(tuple(e) not in own for e in graph[0].tolist())
        ok = []
        for r in ring_sizes:
            try:
                deformer(mesh, kind, h, r, graph).prepare()
                ok.append(r)
            except InputError:
                pass
        row["pd_r"] = "".join(map(str, ok))
        try:
            still = deformer(mesh, kind, h, 1, graph).solve(mesh.vertices[h], max_iter=max_iter)
            row["drift"] = float(np.abs(still.vertices - mesh.vertices).max() / diag)
            row["E_rest"] = still.energy
        except InputError:
            row["drift"] = row["E_rest"] = None
        for r in drags:
            try:
                res = deformer(mesh, kind, h, r, graph).solve(T, max_iter=max_iter)
            except InputError:
                row[f"E_r{r}"] = row[f"folds_r{r}"] = None
                continue
            row[f"E_r{r}"], row[f"it_r{r}"] = res.energy, res.iterations
            row[f"folds_r{r}"] = fold_fraction(mesh, res.vertices)
            shapes[kind, r] = res.vertices
        row["seconds"] = round(time.perf_counter() - t0, 1)
        rows.append(row)
    for row in rows:
        for r in drags:
            if ("cotan", r) in shapes and (row["weights"], r) in shapes:
                d = np.abs(shapes[row["weights"], r] - shapes["cotan", r]).max()
                row[f"dx_cotan_r{r}"] = float(d / diag)
    return rows


def _pct(x) -> str:
    return "fails" if x is None else ("0" if x == 0 else f"{100 * x:.2g} %")


def markdown(rows: list[dict]) -> str:
    head = ("| mesh | weights | negative | PD for r | rest drift | E at rest | folds r=1 | "
            "folds r=3 | E r=1 (iters) | from raw cotan r=1 |\n|---|---|---|---|---|---|---|"
            "---|---|---|")
    out = [head]
    for r in rows:
        e1 = "fails" if r.get("E_r1") is None else f"{r['E_r1']:.3g} ({r['it_r1']})"
        er = "fails" if r.get("E_rest") is None else f"{r['E_rest']:.2g}"
        out.append(
            f"| {r['mesh']} | {r['weights']} | {r['neg']} | {r['pd_r'] or 'none'} | "
            f"{_pct(r['drift'])} | {er} | {_pct(r.get('folds_r1'))} | "
            f"{_pct(r.get('folds_r3')) if 'folds_r3' in r else 'n/a'} | {e1} | "
            f"{_pct(r.get('dx_cotan_r1'))} |")
    return "\n".join(out)


def main(argv: list[str]) -> int:
    if argv[:1] == ["--markdown"]:
        print(markdown([json.loads(line) for line in Path(argv[1]).read_text().splitlines()]))
        return 0
    if not MESHES.exists():
        print(f"skipped: {MESHES} not found")
        return 0
    paths = [MESHES / a for a in argv] or sorted(MESHES.iterdir())
    kinds = available_kinds()
    for p in paths:
        big = p.name.startswith("dragon")
        kw = {"ring_sizes": (1,), "drags": (1,), "max_iter": 100} if big else {}
        kw["kinds"] = kinds
        for row in study(p, **kw):
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
