"""Shared pieces of the scale study: the dragon, its drags, timing and machine load.

Every script in ``benchmarks/scale/`` measures one part of the design in
``docs/studies/interactive-at-scale.md``. Meshes derived from the dragon (decimated,
subdivided) are made on the fly and cached under ``/tmp/arapkit-scale`` (never
committed); the optional libraries of the study are looked up in ``/tmp/scale-pkgs`` too
(``pip install --target``, see the doc), so the project's own environment stays untouched.
"""

from __future__ import annotations

import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "meshes"
DRAGON = DATA / "dragon_vrip.ply.gz"
CACHE = Path(os.environ.get("ARAPKIT_SCALE_CACHE", "/tmp/arapkit-scale"))
EXTRA = os.environ.get("ARAPKIT_SCALE_PKGS", "/tmp/scale-pkgs")
if os.path.isdir(EXTRA) and EXTRA not in sys.path:
    sys.path.append(EXTRA)  # appended: the project's own packages win


def machine_load() -> str:
    """The 1-minute load average and core count, for the record next to every figure."""
    one, five, _ = os.getloadavg()
    return f"load {one:.2f} (5 min {five:.2f}) on {os.cpu_count()} cores"


def peak_rss_mb() -> float:
    """This process's peak resident memory so far, MiB.

    ``VmHWM`` rather than ``ru_maxrss``: Linux carries ``ru_maxrss`` across ``exec``, so a
    child started by a big parent would report the parent's peak.
    """
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def timed(fn, *args, **kwargs):
    """``(result, seconds)`` of one call."""
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t0


def _cached_arrays(name: str, make) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces stored as ``CACHE/name.npz``, made by ``make()`` the first time."""
    path = CACHE / f"{name}.npz"
    if path.exists():
        z = np.load(path)
        return z["V"], z["F"]
    V, F = make()
    CACHE.mkdir(parents=True, exist_ok=True)
    np.savez(path, V=V, F=F)
    return V, F


def dragon():
    """The 437,645-vertex dragon scan as an :class:`arapkit.Mesh` (loaded once, then cached)."""
    import arapkit

    def load():
        m = arapkit.load_mesh(DRAGON)
        return m.vertices, m.faces

    V, F = _cached_arrays("dragon", load)
    return arapkit.Mesh(V, F, name="dragon_vrip")


def dragon_subdivided():
    """The dragon after one Loop subdivision (about 1.75M vertices)."""
    import trimesh.remesh

    import arapkit

    def make():
        m = dragon()
        return trimesh.remesh.subdivide_loop(m.vertices, m.faces, iterations=1)

    V, F = _cached_arrays("dragon_x4", make)
    return arapkit.Mesh(V, F, name="dragon_vrip x4")


def dragon_decimated(n_target: int):
    """The dragon decimated to about ``n_target`` vertices by fast-simplification."""
    import arapkit

    def make():
        import fast_simplification

        m = dragon()
        # writable copies: the wrapper refuses the mesh's read-only arrays
        V, F = fast_simplification.simplify(np.array(m.vertices, dtype=np.float32),
                                            np.array(m.faces, dtype=np.int64),
                                            target_count=2 * n_target)
        return V.astype(np.float64), F.astype(np.int64)

    V, F = _cached_arrays(f"dragon_{n_target}", make)
    return arapkit.Mesh(V, F, name=f"dragon_vrip ~{n_target // 1000}K")


def base_and_top(V: np.ndarray, frac: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """The lowest and the highest ``frac`` of the vertices along y (as bench_arap.py)."""
    order = np.argsort(V[:, 1], kind="stable")
    k = max(1, int(frac * len(V)))
    return np.sort(order[:k]), np.sort(order[-k:])


def _rot(axis: int, deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    i, j = [a for a in range(3) if a != axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


#: three drags of the same two handle regions (base fixed, top moved rigidly):
#: (rotation axis, degrees, translation in bbox diagonals)
DRAGS = {
    "pull": (1, 0.0, (0.25, 0.0, 0.125)),   # bench_arap.py's drag
    "twist": (1, 60.0, (0.0, 0.0, 0.0)),    # about the vertical axis through the top
    "bend": (2, 45.0, (0.0, 0.05, 0.0)),    # about the depth axis, lifted
}


def drag_motion(V: np.ndarray, top: np.ndarray, kind: str, frac: float = 1.0):
    """The rigid motion ``x -> x @ R.T + t`` of the top region, ``frac`` of the way.

    The rotation turns about the top region's rest centroid. The editor's gizmo gives the
    same kind of motion per handle group, so the proxy's handles get the very same one.
    """
    axis, deg, move = DRAGS[kind]
    diag = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    c = V[top].mean(axis=0)
    R = _rot(axis, frac * deg)
    t = c - c @ R.T + frac * np.asarray(move) * diag
    return R, t


def drag_targets(V: np.ndarray, base: np.ndarray, top: np.ndarray, kind: str,
                 frac: float = 1.0) -> np.ndarray:
    """Targets of ``concat(base, top)``: the base at rest, the top moved by drag ``kind``."""
    R, t = drag_motion(V, top, kind, frac)
    return np.concatenate([V[base], V[top] @ R.T + t])


def table(header: list[str], rows: list[list]) -> str:
    """A Markdown table (floats with 3 significant digits)."""
    def cell(x):
        return f"{x:.3g}" if isinstance(x, float) else str(x)

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(x) for x in r) + " |" for r in rows]
    return "\n".join(lines)
