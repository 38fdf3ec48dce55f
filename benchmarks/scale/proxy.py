"""Proxy preview: ARAP on a decimated proxy, mapped back to the full mesh, against the truth.

For each drag of ``common.DRAGS`` (base fixed, top region moved rigidly):

1. the reference: the full mesh solved by ``Deformer(..., accelerate=True)`` to
   ``--ref-tol`` (default 1e-5; ``--check-ref`` solves again from the preview to see
   whether the reference is converged);
2. the proxy (fast-simplification to ``--proxy`` vertices) gets the same rigid handle
   motions on its vertices whose nearest full vertex is a handle, and is solved with
   r-ring ARAP at the rescaled r (``r_proxy = max(1, round(r * h_full / h_proxy))``, h the
   mean edge length: the neighbourhood keeps its surface radius; at r = 1 it cannot);
3. the preview: every full vertex v follows its k nearest proxy vertices q at rest,
   ``x_v = sum_q w_q (y_q + R_q (v - q))`` with inverse-distance weights (k = 1: the
   nearest one alone), and the handles are snapped to their targets. ``translate`` is the
   rotation-blind mapping ``x_v = v + (y_q - q)`` for comparison;
4. errors of the preview against the reference, max and 95th percentile, as fractions of
   the bounding-box diagonal; time per preview update (the map-back, numba, and one proxy
   solve warm-started from the previous frame of a 30-frame drag);
5. the full solve warm-started from the preview against one from rest (tol 1e-3,
   accelerated, the editor's "exact on release"): iterations, seconds, and the distance
   of each to the reference.

Usage::

    python benchmarks/scale/proxy.py                       # dragon, proxies 20K and 50K
    python benchmarks/scale/proxy.py --mesh 100k --proxy 20000
    python benchmarks/scale/proxy.py --drags pull --proxy 20000 --k 1 4
"""

from __future__ import annotations

import argparse
import time

import numba
import numpy as np
from common import (
    DRAGS,
    base_and_top,
    drag_motion,
    drag_targets,
    dragon,
    dragon_decimated,
    machine_load,
    table,
    timed,
)
from scipy.spatial import cKDTree


@numba.njit(parallel=True, fastmath=False, cache=False)
def skin(Y, R, idx, w, D, out):
    """``out[v] = sum_j w[v, j] (Y[q] + R[q] @ D[v, j])`` with ``q = idx[v, j]``."""
    n, k = idx.shape
    for v in numba.prange(n):
        for a in range(3):
            out[v, a] = 0.0
        for j in range(k):
            q = idx[v, j]
            for a in range(3):
                out[v, a] += w[v, j] * (Y[q, a] + R[q, a, 0] * D[v, j, 0]
                                        + R[q, a, 1] * D[v, j, 1] + R[q, a, 2] * D[v, j, 2])


class Skinning:
    """Rest-time binding of the full vertices to their k nearest proxy vertices."""

    def __init__(self, V: np.ndarray, Q: np.ndarray, k: int) -> None:
        d, idx = cKDTree(Q).query(V, k=k)
        d, idx = d.reshape(len(V), k), idx.reshape(len(V), k)
        w = 1.0 / np.maximum(d, 1e-12 * d.max())
        self.idx = np.ascontiguousarray(idx, dtype=np.int64)
        self.w = np.ascontiguousarray(w / w.sum(axis=1, keepdims=True))
        self.D = np.ascontiguousarray(V[:, None, :] - Q[self.idx])
        self.out = np.empty_like(V)

    def __call__(self, Y: np.ndarray, R: np.ndarray) -> np.ndarray:
        skin(Y, R, self.idx, self.w, self.D, self.out)
        return self.out


def proxy_handles(V, Q, base, top):
    """Proxy vertices whose nearest full vertex is a base / top handle."""
    near = cKDTree(V).query(Q, k=1)[1]
    is_base = np.zeros(len(V), bool)
    is_base[base] = True
    is_top = np.zeros(len(V), bool)
    is_top[top] = True
    return np.flatnonzero(is_base[near]), np.flatnonzero(is_top[near])


def mean_edge(mesh) -> float:
    E = mesh.edges
    return float(np.linalg.norm(mesh.vertices[E[:, 0]] - mesh.vertices[E[:, 1]], axis=1).mean())


def errors(X, ref, diag) -> tuple[float, float]:
    e = np.linalg.norm(X - ref, axis=1) / diag
    return float(e.max()), float(np.percentile(e, 95))


def main(argv=None) -> None:
    from arapkit import Deformer

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", choices=["dragon", "100k"], default="dragon")
    ap.add_argument("--proxy", nargs="+", type=int, default=[20000, 50000])
    ap.add_argument("--drags", nargs="+", default=list(DRAGS), choices=list(DRAGS))
    ap.add_argument("--k", nargs="+", type=int, default=[1, 4])
    ap.add_argument("--rings", type=int, default=1)
    ap.add_argument("--ref-tol", type=float, default=1e-5,
                    help="tolerance of the reference solve (relative energy decrease)")
    ap.add_argument("--ref-iter", type=int, default=3000)
    ap.add_argument("--check-ref", action="store_true",
                    help="also solve to --ref-tol from the preview: is the reference converged?")
    args = ap.parse_args(argv)
    mesh = dragon() if args.mesh == "dragon" else dragon_decimated(100000)
    V, diag = mesh.vertices, mesh.bounding_box_diagonal
    base, top = base_and_top(V)
    h = np.concatenate([base, top])
    print(f"{mesh.name}: {mesh.n_vertices} vertices; {machine_load()}")
    full, t_open = timed(Deformer, mesh, h, rings=args.rings, accelerate=True)
    _, t_fact = timed(full.prepare)
    print(f"full open: precompute {t_open:.2f} s + factorise {t_fact:.2f} s")
    refs, cold = {}, {}
    for kind in args.drags:
        T = drag_targets(V, base, top, kind)
        refs[kind] = full.solve(T, tol=args.ref_tol, max_iter=args.ref_iter)
        cold[kind] = full.solve(T)  # tol 1e-3, accelerated, from rest
        print(f"{kind}: reference {refs[kind].iterations} it {refs[kind].timings['total_s']:.1f}"
              f" s; from rest to 1e-3 {cold[kind].iterations} it "
              f"{cold[kind].timings['total_s']:.1f} s", flush=True)
    err_rows, time_rows, warm_rows = [], [], []
    h_full = mean_edge(mesh)
    for n_proxy in args.proxy:
        pm = dragon_decimated(n_proxy) if args.mesh == "dragon" else _decimate(mesh, n_proxy)
        Q = pm.vertices
        r_proxy = max(1, round(args.rings * h_full / mean_edge(pm)))
        pb, pt = proxy_handles(V, Q, base, top)
        ph = np.concatenate([pb, pt])
        prox, t_popen = timed(Deformer, pm, ph, rings=r_proxy, accelerate=True)
        _, t_pfact = timed(prox.prepare)
        binds = {k: timed(Skinning, V, Q, k) for k in args.k}
        print(f"proxy {pm.n_vertices} vertices, r {r_proxy}, {len(ph)} handles: open "
              f"{t_popen + t_pfact:.2f} s; binding " + ", ".join(
                  f"k={k} {t:.2f} s" for k, (_, t) in binds.items()), flush=True)
        for kind in args.drags:
            T = drag_targets(V, base, top, kind)

            def ptargets(frac, kind=kind, Q=Q, pb=pb, pt=pt):
                # the top group's own rigid motion, applied to the proxy's handles
                R, t = drag_motion(V, top, kind, frac)
                return np.concatenate([Q[pb], Q[pt] @ R.T + t])

            pres = prox.solve(ptargets(1.0), tol=1e-5, max_iter=3000)
            # one frame of a 30-frame drag: warm from the previous frame's proxy shape
            prev = prox.solve(ptargets(29 / 30), tol=1e-5, max_iter=3000)
            frame = prox.solve(ptargets(1.0), init=prev.vertices, tol=1e-4)
            ref = refs[kind].vertices
            X_t = V + (pres.vertices - Q)[binds[args.k[0]][0].idx[:, 0]]
            X_t[h] = T
            err_rows.append([n_proxy, kind, "translate", *errors(X_t, ref, diag)])
            for k, (sk, _) in binds.items():
                sk(pres.vertices, pres.rotations)  # compile / warm the kernel
                reps = []
                for _ in range(5):
                    t0 = time.perf_counter()
                    X = sk(pres.vertices, pres.rotations)
                    reps.append(time.perf_counter() - t0)
                X = X.copy()
                X[h] = T
                err_rows.append([n_proxy, kind, f"rotation k={k}", *errors(X, ref, diag)])
                time_rows.append([n_proxy, kind, k, 1e3 * frame.timings["total_s"],
                                  frame.iterations, 1e3 * float(np.median(reps)),
                                  1e3 * (frame.timings["total_s"] + float(np.median(reps)))])
                if k == max(args.k):
                    w = full.solve(T, init=X)
                    c = cold[kind]
                    warm_rows.append([n_proxy, kind, c.iterations, c.timings["total_s"],
                                      errors(c.vertices, ref, diag)[0], w.iterations,
                                      w.timings["total_s"], errors(w.vertices, ref, diag)[0]])
                    if args.check_ref:
                        w5 = full.solve(T, init=X, tol=args.ref_tol, max_iter=args.ref_iter)
                        print(f"check {kind}: from the preview to the reference's tol "
                              f"{w5.iterations} it, "
                              f"max dist to the reference {errors(w5.vertices, ref, diag)[0]:.2e}"
                              f", energy {w5.energy:.6e} vs reference {refs[kind].energy:.6e}",
                              flush=True)
            print(err_rows[-1], time_rows[-1], flush=True)
    print()
    print(table(["proxy", "drag", "mapping", "max err / diag", "p95 err / diag"], err_rows))
    print()
    print(table(["proxy", "drag", "k", "proxy frame ms", "proxy its", "map-back ms",
                 "update ms"], time_rows))
    print()
    print(table(["proxy", "drag", "rest: its", "rest: s", "rest: max dist", "preview: its",
                 "preview: s", "preview: max dist"], warm_rows))
    print(machine_load())


def _decimate(mesh, n):
    """A proxy of an arbitrary mesh (fast-simplification), for ``--mesh 100k``."""
    import fast_simplification

    import arapkit

    U, G = fast_simplification.simplify(np.array(mesh.vertices, dtype=np.float32),
                                        np.array(mesh.faces, dtype=np.int64),
                                        target_count=2 * n)
    return arapkit.Mesh(U.astype(np.float64), G.astype(np.int64), name=f"proxy {n}")


if __name__ == "__main__":
    main()
