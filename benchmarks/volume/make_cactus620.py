"""Write ``cactus620.off``: examples/cactus.off coarsened to 620 vertices (1236 triangles).

The rule: libigl's shortest-edge collapse (``igl.decimate``) of the project's cactus down to
1236 faces, the size of the classic ARAP cactus (620 vertices) on which volumetric ARAP at
r = 3-5 was seen to fold where surface ARAP does not. Its twist, ``cactus620-twist.json``,
is examples/cactus-twist.json unchanged (pot fixed, top above the arms turned 150 degrees).

Usage::

    python benchmarks/volume/make_cactus620.py
"""

from __future__ import annotations

from pathlib import Path

HERE = Path(__file__).resolve().parent


def main() -> None:
    import igl

    from arapkit import load_mesh, save_mesh

    m = load_mesh(HERE.parents[1] / "examples" / "cactus.off")
    V, F, _, _ = igl.decimate(m.vertices, m.faces, 1236)
    save_mesh(HERE / "cactus620.off", V, F)
    print(f"cactus620.off: {len(V)} vertices, {len(F)} triangles")


if __name__ == "__main__":
    main()
