"""Data augmentation: random, reproducible deformation jobs for a set of meshes.

The jobs are ordinary batch jobs (:mod:`arapkit.workflows.jobfile`) with inline handle
groups, so ``arapkit batch --augment N`` writes them as a job file and runs them like any
other. :func:`augment_jobs` has the example.
"""

from __future__ import annotations

import os
import zlib
from collections.abc import Sequence

import numpy as np

from ..errors import InputError
from ..io import load_mesh
from ..validate import integer

__all__ = ["augment_jobs"]


def _disjoint_groups(V: np.ndarray, a: int, b: int, k: int) -> int:
    """Largest k' <= k whose k'-nearest sets around vertices a and b do not overlap."""
    da = np.linalg.norm(V - V[a], axis=1)
    db = np.linalg.norm(V - V[b], axis=1)
    while k > 1:
        sa = set(np.argpartition(da, k - 1)[:k].tolist())
        sb = set(np.argpartition(db, k - 1)[:k].tolist())
        if not sa & sb:
            break
        k //= 2
    return k


def _rounded(x, digits: int = 6) -> list[float] | float:
    # short, stable numbers in the job file
    return [round(float(v), digits) for v in x] if np.ndim(x) else round(float(x), digits)


def _stems(paths: Sequence[str]) -> list[str]:
    """Output name stems, one per mesh: the file name, made unique by trailing ``_``."""
    stems: list[str] = []
    for path in paths:
        stem = os.path.basename(path).split(".")[0] or "mesh"
        while stem in stems:  # two meshes named alike in different folders
            stem += "_"
        stems.append(stem)
    return stems


def _mesh_jobs(path: str, stem: str, n: int, seed: int, max_rings: int) -> list[dict]:
    """The ``n`` jobs of one mesh: they depend on ``seed`` and its file name only."""
    mesh = load_mesh(path)
    V, nv = mesh.vertices, mesh.n_vertices
    if nv < 2:
        raise InputError(f"{path}: needs at least two vertices to place handles")
    diag = mesh.bounding_box_diagonal
    rng = np.random.default_rng([int(seed), zlib.crc32(os.path.basename(path).encode())])
    jobs = []
    for s in range(n):
        a = int(rng.integers(nv))
        dist = np.linalg.norm(V - V[a], axis=1)
        far = np.argsort(dist, kind="stable")[-max(1, nv // 10):]
        b = int(rng.choice(far))
        k = _disjoint_groups(V, a, b, min(max(3, nv // 50), nv // 2 or 1))
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        degrees = rng.uniform(-45.0, 45.0)
        move = rng.normal(size=3)
        move *= rng.uniform(0.0, 0.2) * diag / np.linalg.norm(move)
        rings = int(rng.integers(1, max_rings + 1))
        handles = [
            {"name": "fixed", "nearest": {"point": _rounded(V[a]), "k": k}},
            {"name": "moved", "nearest": {"point": _rounded(V[b]), "k": k},
             "rotate": {"axis": _rounded(axis), "degrees": _rounded(degrees, 3),
                        "center": _rounded(V[b])},
             "translate": _rounded(move)},
        ]
        jobs.append({"mesh": path, "handles": handles, "rings": rings,
                     "output": f"{stem}-{s:04d}.ply"})
    return jobs


def augment_jobs(meshes: Sequence[str | os.PathLike], n: int, seed: int = 0,
                 max_rings: int = 3) -> list[dict]:
    """``n`` random deformation jobs per mesh, reproducible from ``seed``.

    Each job fixes the vertices nearest a random vertex ``a`` and moves those nearest a
    vertex ``b`` drawn from the 10% of vertices farthest from ``a``: a rotation about a
    random axis through ``b`` by up to 45 degrees, then a translation of up to 20% of the
    bounding-box diagonal. Groups have ``max(3, n_vertices // 50)`` vertices (fewer if the
    two would overlap); r is drawn from ``1..max_rings``. A mesh's jobs depend only on
    ``seed``, its file name and the sample number, not on the other meshes.

    Returns
    -------
    list of dict
        Jobs with inline handle groups and outputs ``STEM-0000.ply`` ...

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from arapkit.io import save_mesh
    >>> from arapkit.mesh.shapes import bar
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "bar.off"
    >>> m = bar(); _ = save_mesh(p, m.vertices, m.faces)
    >>> jobs = augment_jobs([p], 2, seed=1)
    >>> [j["output"] for j in jobs], jobs == augment_jobs([p], 2, seed=1)
    (['bar-0000.ply', 'bar-0001.ply'], True)
    """
    n = integer(n, "--augment", lo=1)
    paths = [os.path.abspath(os.fspath(p)) for p in meshes]
    return [job for path, stem in zip(paths, _stems(paths), strict=True)
            for job in _mesh_jobs(path, stem, n, seed, max_rings)]
