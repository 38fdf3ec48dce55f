"""Make the filmstrips of ``docs/dynamics.md`` (run from the repository root).

* ``docs/figures/dynamics-cantilever.png``: ``examples/bar.off`` pinned at its left end
  (x = 0), released under gravity (9.81 m/s^2 along -z) with the defaults (stiffness
  3e4 N/m, 1 kg/m^2, damping 2/s, steps of 1/60 s): it swings down, past its rest sag,
  and settles. Six frames over 2 s.
* ``docs/figures/dynamics-whip.png``: the same bar held by its left end only, that end
  keyed up by 2 m in 0.25 s (no gravity, the defaults): the free end lags 2.4 m behind,
  whips up past the straight shape and settles. Six frames over 3 s.

Both are what ``arapkit simulate ... --figure`` draws (:func:`arapkit.plots.filmstrip.
filmstrip_figure`).

Usage::

    python docs/dynamics_figure.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "figures"


def main() -> None:
    from arapkit import load_mesh
    from arapkit.methods.dynamics import Keyframes, simulate
    from arapkit.plots.figures import save_figure
    from arapkit.plots.filmstrip import filmstrip_figure, pick_frames

    m = load_mesh(ROOT / "examples" / "bar.off")
    x = m.vertices[:, 0]
    left = np.flatnonzero(x == x.min())

    tr = simulate(m, 121, dt=1 / 60, handles=left, gravity=[0, 0, -9.81])
    ks = pick_frames(len(tr.vertices), 6)
    fig = filmstrip_figure(m.faces, [tr.vertices[k] for k in ks], [tr.times[k] for k in ks],
                           handles=left, title="bar.off pinned at x = 0, released under "
                           "gravity: stiffness 3e4 N/m, 1 kg/m², damping 2/s, dt 1/60 s")
    save_figure(fig, OUT / "dynamics-cantilever.png")

    rest = m.vertices[left]
    keys = Keyframes([0.0, 0.25], [rest, rest + [0.0, 0.0, 2.0]])  # lifted 2 m in 0.25 s
    tr = simulate(m, 181, dt=1 / 60, handles=left, targets=keys)
    ks = [0, 8, 15, 25, 40, 180]
    fig = filmstrip_figure(m.faces, [tr.vertices[k] for k in ks], [tr.times[k] for k in ks],
                           handles=left, title="bar.off, its left end lifted 2 m in 0.25 s "
                           "(no gravity, defaults): the free end lags, whips up and settles")
    save_figure(fig, OUT / "dynamics-whip.png")
    print(f"wrote {OUT / 'dynamics-cantilever.png'} and {OUT / 'dynamics-whip.png'}")


if __name__ == "__main__":
    main()
