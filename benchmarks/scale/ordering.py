"""Why CHOLMOD through scikit-sparse factorises faster than cholespy: the ordering.

Factorises the cached 437K reduced system of ``solvers.py`` (run that first) with
scikit-sparse's simplicial CHOLMOD under each fill-reducing ordering and prints the
analysis + factorisation time and nnz(L). cholespy (what arapkit uses) is timed on the
same matrix for comparison.

Usage::

    python benchmarks/scale/ordering.py            # after solvers.py has cached the system
    python benchmarks/scale/ordering.py --mesh x4
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.sparse as sp
from common import CACHE, machine_load, table


def main(argv=None) -> None:
    from sksparse.cholmod import analyze

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", choices=["dragon", "x4"], default="dragon")
    args = ap.parse_args(argv)
    z = np.load(CACHE / f"system_{args.mesh}.npz")
    A = sp.csc_matrix(sp.csr_matrix((z["data"], z["indices"], z["indptr"]),
                                    shape=tuple(z["shape"])))
    print(f"{args.mesh}: {A.shape[0]} free vertices; {machine_load()}")
    rows = []
    for order in ("natural", "amd", "metis", "nesdis", "default"):
        t0 = time.perf_counter()
        f = analyze(A, mode="simplicial", ordering_method=order)
        t1 = time.perf_counter()
        f.cholesky_inplace(A)
        t2 = time.perf_counter()
        rows.append([order, t1 - t0, t2 - t1, f"{f.L().nnz / 1e6:.1f}M"])
        print(rows[-1], flush=True)
    from cholespy import CholeskySolverD, MatrixType

    C = A.tocoo()
    t0 = time.perf_counter()
    CholeskySolverD(A.shape[0], C.row.astype(np.int32), C.col.astype(np.int32), C.data,
                    MatrixType.COO)
    rows.append(["cholespy (its own)", "", time.perf_counter() - t0, "?"])
    print(table(["ordering", "analyse s", "factorise s", "nnz(L)"], rows))
    print(machine_load())


if __name__ == "__main__":
    main()
