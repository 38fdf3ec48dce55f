"""How far arapkit's ARAP, SR-ARAP and spokes-and-rims are from CGAL's, and why (the table
of ``docs/methods.md``, "Agreement with CGAL on obtuse meshes and partial ROIs").

The case: ``examples/cactus.off`` (2,162 vertices, 256 obtuse corners) twisted by
``examples/cactus-twist.json``: the pot held, the top of the trunk turned 150 degrees. It is
posed two ways for CGAL's ``Surface_mesh_deformation`` (the driver of
``tests/cgal_oracle.py``): the whole mesh as region of interest with the pot and the top as
control vertices, and the ROI of a ``.sel`` file (statuses 1 and 2: everything but the pot,
the top as control vertices). arapkit always holds the pot as a handle. Each arapkit
weighting (and, for SR-ARAP, ``sr_roi``) is compared with CGAL by the largest vertex
distance over the bounding-box diagonal. Both sides run to convergence (arapkit tol 1e-13,
CGAL 20,000 iterations at tol 1e-14); SR-ARAP needs about 16,000 iterations.

Needs ``g++``, the CGAL and Eigen 3 headers (``apt-get install libcgal-dev libeigen3-dev``).
About 5 minutes on a 2-core machine. Usage, from the repository root::

    python benchmarks/cgal_agreement.py
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from cgal_oracle import build_driver, run_cgal  # noqa: E402

from arapkit import Deformer, load_handles, load_mesh  # noqa: E402

METHODS = {"sre": ("SR-ARAP (alpha 0.02)", "sr-arap"), "arap": ("ARAP", "rring"),
           "rims": ("spokes-and-rims", "spokes-and-rims")}
WEIGHTS = ("cotan-clamped-each", "cotan-clamped", "cotan")


def main() -> None:
    mesh_path = ROOT / "examples" / "cactus.off"
    m = load_mesh(mesh_path)
    pot, top = load_handles(ROOT / "examples" / "cactus-twist.json", m.vertices).groups
    h = np.concatenate([pot.indices, top.indices])
    T = np.concatenate([m.vertices[pot.indices], top.targets])
    roi = np.setdiff1d(np.arange(m.n_vertices), pot.indices)
    diag = m.bounding_box_diagonal
    print("| method | CGAL's ROI | arapkit weights | sr_roi | max difference / diagonal |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        driver = build_driver(tmp)
        if isinstance(driver, str):
            sys.exit(driver)
        for tag, (label, energy) in METHODS.items():
            for partial in (False, True):
                U = run_cgal(driver, mesh_path, top.indices if partial else h,
                             top.targets if partial else T, tag, 0.02, tmp,
                             roi=roi if partial else None, iterations=20000, tol=1e-14)
                runs = [(w, False) for w in WEIGHTS]
                if tag == "sre" and partial:
                    runs += [(w, True) for w in WEIGHTS[:2]]
                for w, use_roi in runs:
                    opts = {"sr_roi": roi} if use_roi else {}
                    res = Deformer(m, h, weights=w, energy=energy, **opts).solve(
                        T, tol=1e-13, max_iter=20000)
                    d = np.abs(U - res.vertices).max() / diag
                    print(f"| {label} | {'partial' if partial else 'whole mesh'} | {w} | "
                          f"{'yes' if use_roi else '—'} | {d:.2g} |", flush=True)


if __name__ == "__main__":
    main()
