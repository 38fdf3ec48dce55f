"""Make ``docs/learn-panda.png``: rigidity learned from the panda walk (``docs/learning.md``).

Learns r = 1..6 from ``../shared/data/sequences/panda_walk_seq.npz`` (61 frames, the first
is the reference) with the automatic omega, draws the reference coloured by r (1 blue ...
6 red) and prints the vertex counts per r and the mean r of the body parts named in
``docs/learning.md``, for omega = auto, 0.02 and the paper's 0.3.

Usage::

    python docs/learn_panda_figure.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "sequences" / "panda_walk_seq.npz"


def regions(V: np.ndarray) -> dict[str, np.ndarray]:
    """Head (-y end), lower legs (below 25% height), shoulders and hips (30-60% height
    above the feet); the same definition as tests/test_learn.py."""
    x, y, z = V.T
    h = (z - z.min()) / np.ptp(z)
    low = h < 0.1
    feet = np.array([[x[s].mean(), y[s].mean()]
                     for s in (low & (x < 0) & (y < 0), low & (x >= 0) & (y < 0),
                               low & (x < 0) & (y >= 0), low & (x >= 0) & (y >= 0))])
    to_foot = np.min(np.hypot(x[:, None] - feet[:, 0], y[:, None] - feet[:, 1]), axis=1)
    return {"head": y < y.min() + 0.17 * np.ptp(y), "lower legs": h < 0.25,
            "shoulders/hips": (h >= 0.3) & (h < 0.6) & (to_foot < 0.1 * np.ptp(y))}


def main(argv: list[str]) -> int:
    from arapkit import Mesh, learn_rings
    from arapkit.learn.fit import rings_figure
    from arapkit.plots.figures import save_figure

    if not DATA.exists():
        print(f"skipped: {DATA} not found")
        return 0
    out = Path(argv[0]) if argv else ROOT / "docs" / "learn-panda.png"
    data = np.load(DATA)
    V, F = data["V"], data["F"]
    mesh = Mesh(V[0], F, name="panda")
    res = learn_rings(mesh, V[1:], omega="auto")
    parts = regions(V[0])
    for omega in ("auto", 0.02, 0.3):
        r = res.with_omega(omega)
        means = ", ".join(f"{k} {r.rings[s].mean():.2f}" for k, s in parts.items())
        print(f"omega {r.omega:.4f} ({r.omega_rule}): per r {r.histogram()}; mean r: {means}")
    fig = rings_figure(mesh.vertices, mesh.faces, res.rings,
                       title=f"panda walk (60 examples): learned r, omega = {res.omega:.3f} "
                       "(auto)")
    save_figure(fig, out, dpi=110)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
