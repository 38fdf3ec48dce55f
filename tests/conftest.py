"""Shared fixtures: the real-mesh data folder ``../shared/data`` beside the project."""

from __future__ import annotations

import shutil
import subprocess
from collections import deque
from pathlib import Path

import pytest

from arapkit import Mesh

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"


def data_path(*parts: str) -> Path:
    """Path into ../shared/data, skipping the calling test when it is absent."""
    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"{p} not found: real-mesh tests need ../shared/data beside the project")
    return p


@pytest.fixture
def data_dir() -> Path:
    """The ../shared/data folder (skips when absent)."""
    return data_path()


def bfs_distances(mesh: Mesh, k: int) -> dict[int, int]:
    """Edge-graph distance from k to every vertex it reaches (plain BFS, test reference)."""
    nbrs: dict[int, list[int]] = {v: [] for v in range(mesh.n_vertices)}
    for i, j in mesh.edges.tolist():
        nbrs[i].append(j)
        nbrs[j].append(i)
    dist, queue = {k: 0}, deque([k])
    while queue:
        u = queue.popleft()
        for v in nbrs[u]:
            if v not in dist:
                dist[v] = dist[u] + 1
                queue.append(v)
    return dist


def independent_ring_edges(mesh: Mesh, k: int, r: int) -> set[tuple[int, int]]:
    """Edges reachable by a path of at most r edges from k: one endpoint within r - 1."""
    dist = bfs_distances(mesh, k)
    return {
        (i, j) for i, j in mesh.edges.tolist()
        if min(dist.get(i, 1 << 30), dist.get(j, 1 << 30)) <= r - 1
    }


def _make_unwritable(folder: Path) -> None:
    """Make ``folder`` refuse new files, even to root; skip when this system cannot."""
    if shutil.which("chattr") is None:
        pytest.skip("chattr not available to make a folder immutable")
    proc = subprocess.run(["chattr", "+i", str(folder)], capture_output=True, text=True)
    if proc.returncode != 0:
        pytest.skip(f"chattr +i failed here ({proc.stderr.strip()}): needs root on ext4/xfs")


@pytest.fixture
def locked(tmp_path):
    folder = tmp_path / "locked"
    folder.mkdir()
    _make_unwritable(folder)
    yield folder
    subprocess.run(["chattr", "-i", str(folder)], check=False)
