"""Shared fixtures: the real-mesh data folder ``../shared/data`` beside the project."""

from __future__ import annotations

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


def independent_ring_edges(mesh: Mesh, k: int, r: int) -> set[tuple[int, int]]:
    """Edges reachable by a path of at most r edges from k: one endpoint within r - 1."""
    nbrs = {v: set() for v in range(mesh.n_vertices)}
    for i, j in mesh.edges.tolist():
        nbrs[i].add(j)
        nbrs[j].add(i)
    dist = {k: 0}
    q = deque([k])
    while q:
        u = q.popleft()
        for v in nbrs[u]:
            if v not in dist:
                dist[v] = dist[u] + 1
                q.append(v)
    return {
        (i, j) for i, j in mesh.edges.tolist()
        if min(dist.get(i, 1 << 30), dist.get(j, 1 << 30)) <= r - 1
    }
