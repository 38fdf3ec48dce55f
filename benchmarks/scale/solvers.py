"""Linear solvers for the global step at 437K (and 1.75M) vertices.

The matrix is arapkit's own reduced system ``A_ff`` for r = 1 (the default weights) on the
dragon with bench_arap.py's handles (lowest and highest 5 % along y), assembled from
the public parts of ``Deformer(mesh, handles).problem`` exactly as
:meth:`arapkit.arap.constraints.Elimination.from_edges` does. Each solver then runs in a
child process of its own so that its peak memory (``ru_maxrss``) is its own:

* ``cholespy``: what arapkit uses today (CHOLMOD, simplicial);
* ``cholmod-supernodal`` / ``cholmod-simplicial``: scikit-sparse's CHOLMOD (system
  SuiteSparse 5.12 with reference BLAS here) in both modes;
* ``pyamg-cg``: CG preconditioned by one smoothed-aggregation V-cycle, to a relative
  residual of 1e-8, from zero and warm-started from the previous solution of a slightly
  different right-hand side (as in the local/global loop);
* ``gravomg``: Gravo MG (geometric multigrid) on the same ``A_ff`` (free vertices'
  rest positions, identity mass matrix);
* ``splu``: scipy's SuperLU (a general LU, the fallback everyone has);
* ``pardiso``: Intel MKL PARDISO through pypardiso (wrapper BSD-3, MKL under Intel's
  Simplified Software License, a 220 MB wheel, x86-64 only), symmetric positive definite
  (mtype 2) on the upper triangle, nested-dissection ordering, no iterative refinement;
* ``cvxopt-simplicial`` / ``cvxopt-supernodal``: CHOLMOD as CVXOPT's wheel bundles it
  (GPL-3; AMD ordering, which cholespy cannot be told to use).

Reported: analyse+factorise (or set-up) seconds, one solve of 3 right-hand sides
(median of 3), relative residual, peak memory above the matrix-only baseline.

Usage::

    python benchmarks/scale/solvers.py                    # 437K, every solver
    python benchmarks/scale/solvers.py --mesh x4          # the dragon subdivided once
    python benchmarks/scale/solvers.py --solvers cholespy pyamg-cg
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from common import CACHE, base_and_top, dragon, dragon_subdivided, machine_load, peak_rss_mb, table

SOLVERS = ("cholespy", "cholmod-supernodal", "cholmod-simplicial", "pyamg-cg", "gravomg",
           "splu", "pardiso", "cvxopt-simplicial", "cvxopt-supernodal")


def reduced_system(mesh) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """``A_ff`` (internal numbering), the free vertices and a 3-column right-hand side."""
    from arapkit import Deformer

    base, top = base_and_top(mesh.vertices)
    p = Deformer(mesh, np.concatenate([base, top])).problem
    n, E, w = p.n_vertices, p.edges, p.energy.system_w
    cons = p.iperm[p.constrained]
    free = np.setdiff1d(np.arange(n), cons)
    slot = np.full(n, -1, dtype=np.int64)
    slot[free] = np.arange(len(free))
    sa, sb = slot[E[:, 0]], slot[E[:, 1]]
    ff = (sa >= 0) & (sb >= 0)
    diag = np.bincount(sa[sa >= 0], w[sa >= 0], len(free)) + np.bincount(
        sb[sb >= 0], w[sb >= 0], len(free))
    A = sp.coo_matrix((np.concatenate([-w[ff], -w[ff], diag]),
                       (np.concatenate([sa[ff], sb[ff], np.arange(len(free))]),
                        np.concatenate([sb[ff], sa[ff], np.arange(len(free))]))),
                      shape=(len(free),) * 2).tocsr()
    # a right-hand side like the loop's: A applied to a smoothly bent copy of the rest shape
    P = p.vertices[free]
    X = P + 0.1 * np.sin(3.0 * P[:, [1, 2, 0]] / max(np.ptp(P), 1e-300))
    return A, free, np.ascontiguousarray(A @ X)


def neighbour_table(A: sp.csr_matrix) -> np.ndarray:
    """Gravo MG's neighbour input: each row's off-diagonal columns, padded with -1."""
    A = A.tocsr()
    deg = np.diff(A.indptr) - 1
    out = -np.ones((A.shape[0], int(deg.max())), dtype=np.int64)
    for i in range(A.shape[0]):  # only for gravomg; a few seconds at 437K
        cols = A.indices[A.indptr[i]:A.indptr[i + 1]]
        cols = cols[cols != i]
        out[i, :len(cols)] = cols
    return out


def run_child(name: str, path: Path) -> dict:
    """Factorise / set up and solve in this process; return the figures."""
    z = np.load(path)
    A = sp.csr_matrix((z["data"], z["indices"], z["indptr"]), shape=tuple(z["shape"]))
    B = z["B"]
    base_mb = peak_rss_mb()
    t0 = time.perf_counter()
    extra = {}
    if name == "cholespy":
        from cholespy import CholeskySolverD, MatrixType

        C = A.tocoo()
        f = CholeskySolverD(A.shape[0], C.row.astype(np.int32), C.col.astype(np.int32),
                            C.data, MatrixType.COO)

        def solve(b):
            x = np.empty_like(b)
            f.solve(np.ascontiguousarray(b), x)
            return x
    elif name.startswith("cholmod"):
        from sksparse.cholmod import cholesky

        mode = name.split("-")[1]
        f = cholesky(A.tocsc(), mode=mode)
        solve = f
        extra["nnz(L)"] = int(f.L().nnz)
    elif name == "pyamg-cg":
        import pyamg

        ml = pyamg.smoothed_aggregation_solver(A, symmetry="hermitian", max_coarse=2000)
        M = ml.aspreconditioner(cycle="V")
        extra["levels"] = len(ml.levels)
        its = []

        def solve(b, x0=None):
            from scipy.sparse.linalg import cg

            X = np.empty_like(b)
            for k in range(b.shape[1]):
                before = len(its)
                X[:, k], _ = cg(A, b[:, k], x0=None if x0 is None else x0[:, k], rtol=1e-8,
                                M=M, callback=lambda _: its.append(0))
                its[before:] = [len(its) - before]  # one entry per column: its CG iterations
            return X
    elif name == "gravomg":
        import gravomg

        neigh = neighbour_table(A)
        f = gravomg.MultigridSolver(np.ascontiguousarray(z["P"]), neigh,
                                    sp.identity(A.shape[0], format="csr"), tolerance=1e-8,
                                    max_iter=200)

        def solve(b):
            return np.column_stack([f.solve(A, np.ascontiguousarray(b[:, k:k + 1])).ravel()
                                    for k in range(b.shape[1])])
    elif name == "pardiso":
        from pypardiso import PyPardisoSolver

        U = sp.triu(A, format="csr")
        U.sort_indices()
        f = PyPardisoSolver(mtype=2)  # real symmetric positive definite: the upper triangle
        f.set_iparm(1, 1)  # use the iparm given here, not PARDISO's defaults
        f.set_iparm(2, 2)  # METIS nested dissection
        f.set_iparm(8, 0)  # no iterative refinement
        f.set_iparm(10, 13)
        f.set_iparm(13, 0)
        f.set_phase(12)  # analyse and factorise
        f._call_pardiso(U, np.zeros((A.shape[0], 1), order="F"))

        def solve(b):
            f.set_phase(33)
            return f._call_pardiso(U, np.asfortranarray(b))
    elif name.startswith("cvxopt"):
        import cvxopt
        from cvxopt import cholmod

        cholmod.options["supernodal"] = 2 if name.endswith("supernodal") else 0
        L = sp.tril(A, format="coo")
        M = cvxopt.spmatrix(cvxopt.matrix(L.data), cvxopt.matrix(L.row.astype(np.int64)),
                            cvxopt.matrix(L.col.astype(np.int64)), size=A.shape)
        f = cholmod.symbolic(M)
        cholmod.numeric(M, f)

        def solve(b):
            X = cvxopt.matrix(np.asfortranarray(b))
            cholmod.solve(f, X)  # one right-hand side at a time inside CVXOPT
            return np.array(X)
    elif name == "splu":
        from scipy.sparse.linalg import splu

        f = splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A")
        solve = f.solve
        extra["nnz(L+U)"] = int(f.L.nnz + f.U.nnz)
    else:
        raise SystemExit(f"unknown solver {name}")
    t_setup = time.perf_counter() - t0
    ts = []
    for _ in range(3):
        t0 = time.perf_counter()
        X = solve(B)
        ts.append(time.perf_counter() - t0)
    res = float(np.linalg.norm(A @ X - B) / np.linalg.norm(B))
    if name == "pyamg-cg":
        extra["cg iterations (cold)"] = int(np.median(its))
        its.clear()
        B2 = B * (1 + 1e-3)  # the next iteration's right-hand side differs a little
        t0 = time.perf_counter()
        solve(B2, X)
        extra["warm solve s"] = round(time.perf_counter() - t0, 3)
        extra["cg iterations (warm)"] = int(np.median(its))
    return {"setup_s": t_setup, "solve_s": float(np.median(ts)), "residual": res,
            "mem_mb": peak_rss_mb() - base_mb, **extra}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", choices=["dragon", "x4"], default="dragon")
    ap.add_argument("--solvers", nargs="+", default=list(SOLVERS))
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per solver")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--matrix", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(run_child(args.child, Path(args.matrix))))
        return
    path = CACHE / f"system_{args.mesh}.npz"
    if not path.exists():
        mesh = dragon() if args.mesh == "dragon" else dragon_subdivided()
        A, free, B = reduced_system(mesh)
        from arapkit import Deformer

        CACHE.mkdir(parents=True, exist_ok=True)
        base, top = base_and_top(mesh.vertices)
        P = Deformer(mesh, np.concatenate([base, top])).problem.vertices[free]
        np.savez(path, data=A.data, indices=A.indices, indptr=A.indptr, shape=A.shape, B=B, P=P)
    nf = int(np.load(path)["shape"][0])
    print(f"{args.mesh}: A_ff is {nf} x {nf}; {machine_load()}")
    rows = []
    for name in args.solvers:
        cmd = [sys.executable, __file__, "--child", name, "--matrix", str(path)]
        try:
            out = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
        except subprocess.TimeoutExpired:
            rows.append([name, f"> {args.timeout:.0f} s", "", "", "", ""])
            continue
        if out.returncode:
            why = (out.stderr.strip().splitlines() or [f"exit status {out.returncode}"])[-1]
            rows.append([name, "failed: " + why[:80], "", "", "", ""])
            continue
        r = json.loads(out.stdout.strip().splitlines()[-1])
        more = {k: v for k, v in r.items()
                if k not in ("setup_s", "solve_s", "residual", "mem_mb")}
        rows.append([name, r["setup_s"], r["solve_s"], f"{r['residual']:.1e}", r["mem_mb"],
                     ", ".join(f"{k} {v}" for k, v in more.items())])
        print(rows[-1], flush=True)
    print()
    print(table(["solver", "set-up s", "3-RHS solve s", "rel. residual", "peak MiB", "notes"],
                rows))
    print(machine_load())


if __name__ == "__main__":
    main()
