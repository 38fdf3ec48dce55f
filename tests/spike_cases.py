"""Single-vertex drags and the spike they pull: shared by tests and benchmarks/bench_smooth.py.

A case is a mesh, a region held at rest and one vertex dragged along its rest normal by 20 %
of the bounding-box diagonal (issue 49). The spike is the dragged vertex's height above the
least-squares plane through its 2-ring (the vertices at most two edges away, itself left out),
in mean edge lengths of the rest mesh, less that height at rest: 0 where the surface stays
smooth at the handle, about the drag itself for a needle.

Computed here with NumPy only, independently of the solver.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from arapkit import Mesh, load_mesh
from arapkit.mesh.shapes import bar

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "meshes"
#: the drag, in bounding-box diagonals
DRAG = 0.2


@dataclass(frozen=True)
class DragCase:
    """A mesh, its held vertices and the dragged vertex with its target."""

    name: str
    mesh: Mesh
    held: np.ndarray
    vertex: int
    target: np.ndarray

    @property
    def handles(self) -> np.ndarray:
        """Held vertices, then the dragged one."""
        return np.concatenate([self.held, [self.vertex]])

    @property
    def targets(self) -> np.ndarray:
        """Targets in the order of :attr:`handles`."""
        return np.vstack([self.mesh.vertices[self.held], self.target])


def vertex_normals(mesh: Mesh, V: np.ndarray | None = None) -> np.ndarray:
    """Area-weighted unit vertex normals (of positions ``V``, default the rest shape)."""
    V = mesh.vertices if V is None else V
    F = mesh.faces
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    n = np.zeros_like(V)
    for c in range(3):
        np.add.at(n, F[:, c], fn)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def two_ring(mesh: Mesh, v: int) -> np.ndarray:
    """Vertices at most two edges from ``v``, ``v`` left out."""
    A = mesh.adjacency.tocsr()
    one = A[v].indices
    ring = np.unique(np.concatenate([one, *[A[j].indices for j in one]]))
    return ring[ring != v]


def height(mesh: Mesh, P: np.ndarray, v: int) -> float:
    """Signed distance of ``P[v]`` from the plane fitted to its 2-ring (positive on the side
    of its normal), in mean edge lengths of the rest mesh."""
    X = P[two_ring(mesh, v)]
    c = X.mean(axis=0)
    normal = np.linalg.svd(X - c)[2][-1]  # the direction of least spread
    if normal @ vertex_normals(mesh, P)[v] < 0:
        normal = -normal
    return float((P[v] - c) @ normal / mesh.mean_edge_length)


def spike(mesh: Mesh, P: np.ndarray, v: int) -> float:
    """The height the deformation adds to ``v`` above its 2-ring's plane, in mean edge
    lengths: ``|height(P) - height(rest)|``. On a flat rest (the bar) the rest height is
    0; on the bumpy sphere it is not, and it is no spike of the method's making."""
    return abs(height(mesh, P, v) - height(mesh, mesh.vertices, v))


def _drag(name: str, mesh: Mesh, held: np.ndarray, v: int) -> DragCase:
    n = vertex_normals(mesh)[v]
    target = mesh.vertices[v] + DRAG * mesh.bounding_box_diagonal * n
    return DragCase(name, mesh, np.asarray(held, dtype=np.int64), int(v), target)


def _nearest(mesh: Mesh, point) -> int:
    return int(np.argmin(np.linalg.norm(mesh.vertices - np.asarray(point), axis=1)))


def bar_case() -> DragCase:
    """The bar with both end caps held, the middle of its top face pulled up."""
    m = bar()
    x = m.vertices[:, 0]
    held = np.flatnonzero((x == x.min()) | (x == x.max()))
    lo, hi = m.vertices.min(axis=0), m.vertices.max(axis=0)
    return _drag("bar", m, held, _nearest(m, [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2]]))


def bumpy_sphere(subdivisions: int = 4) -> Mesh:
    """A unit icosphere with smooth bumps of 6 % of its radius."""
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    V = np.asarray(s.vertices)
    theta = np.arccos(np.clip(V[:, 2], -1, 1))
    phi = np.arctan2(V[:, 1], V[:, 0])
    r = 1.0 + 0.06 * np.sin(5 * theta) * np.cos(4 * phi)
    return Mesh(V * r[:, None], np.asarray(s.faces), name="bumpy sphere")


def sphere_case() -> DragCase:
    """The bumpy sphere with its lower third held, its top vertex pulled out."""
    m = bumpy_sphere()
    z = m.vertices[:, 2]
    return _drag("bumpy sphere", m, np.flatnonzero(z < -0.33), int(np.argmax(z)))


def cactus_case() -> DragCase:
    """The cactus with its pot held, a vertex on the front of the trunk pulled out."""
    m = load_mesh(ROOT / "examples" / "cactus.off")
    held = np.flatnonzero(m.vertices[:, 1] < 2.1)  # the pot of examples/cactus.json
    V = m.vertices
    trunk = np.flatnonzero((np.abs(V[:, 0]) < 0.5) & (np.abs(V[:, 1] - 6.0) < 0.5))
    return _drag("cactus", m, held, int(trunk[np.argmax(V[trunk, 2])]))


def cylinder_case() -> DragCase | None:
    """The open half cylinder of the shared data with its rim held, the top of its middle
    pulled out; None when the shared data is absent."""
    path = DATA / "cylinder.off"
    if not path.exists():
        return None
    m = load_mesh(path)
    held = np.concatenate(m.boundary_loops)
    lo, hi = m.vertices.min(axis=0), m.vertices.max(axis=0)
    return _drag("cylinder", m, held, _nearest(m, [(lo[0] + hi[0]) / 2, 0.0, hi[2]]))


def cases() -> list[DragCase]:
    """Every case whose data is present."""
    out = [bar_case(), cactus_case(), cylinder_case(), sphere_case()]
    return [c for c in out if c is not None]
