"""Where the default stopping test ends, by Anderson history size.

For each mesh and drag, ``Deformer(mesh, handles, accelerate=True, history=m).solve`` with
the default ``tol`` (relative energy decrease 1e-3) for several ``m``: the iterations, the
rejected extrapolations, and the final energy against the lowest any ``m`` reached. A
history size that stops sooner at a higher energy is not a faster solver, only an earlier
stop; this is the evidence behind the stopping-rule question in
``docs/studies/interactive-at-scale.md`` (decided: one rule for every size,
``docs/interactive.md``).

Run from the repository root (about 5 minutes on 2 cores)::

    PYTHONPATH=src .venv/bin/python benchmarks/scale/history.py
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import (  # noqa: E402
    DATA,
    base_and_top,
    drag_targets,
    dragon,
    dragon_decimated,
    machine_load,
    table,
)

HISTORIES = (1, 2, 3, 5, 8)


def cases():
    """(label, mesh, handles, targets): the bar bent 90°, then the scale study's bend."""
    import numpy as np

    from arapkit import load_mesh
    from arapkit.mesh.shapes import bar, bar_bend

    m = bar()
    h, t = bar_bend(m, 90)
    yield "bar, bent 90°", m, h, t
    meshes = [(name, lambda name=name: load_mesh(DATA / name))
              for name in ("bunny00.off", "refined_elephant.off")]
    meshes += [("dragon ~100K", lambda: dragon_decimated(100_000)), ("dragon", dragon)]
    for name, load in meshes:
        if name.endswith(".off") and not (DATA / name).exists():
            print(f"skipped {name}: the shared data folder is absent")
            continue
        m = load()
        base, top = base_and_top(m.vertices)
        yield (f"{name} ({m.n_vertices:,}), bend", m, np.concatenate([base, top]),
               drag_targets(m.vertices, base, top, "bend"))


def main() -> None:
    from arapkit import Deformer

    print(machine_load())
    rows = []
    for label, mesh, handles, targets in cases():
        got = []
        for m in HISTORIES:
            r = Deformer(mesh, handles, accelerate=True, history=m).solve(targets)
            got.append((m, r))
            print(f"{label}: m={m} {r.iterations} its, E {r.energy:.6g}", flush=True)
        low = min(r.energy for _, r in got)
        rows += [[label, m, r.iterations, r.timings.get("accel_rejected", 0),
                  f"{r.energy:.4g}", f"{100 * (r.energy / low - 1):.1f} %"] for m, r in got]
    print(table(["mesh, drag", "history m", "iterations", "rejected", "final energy",
                 "above the lowest"], rows))


if __name__ == "__main__":
    main()
