"""Point clouds and graphs as shapes: the model, the neighbourhood graph, its weights, and the
solver on them (arapkit.mesh.cloud, arapkit.mesh.neighbours, arapkit.mesh.cloud_weights,
arapkit.arap.domains).

Oracles: brute-force nearest neighbours and pair distances, the weight formulas written out
here, the plain edge-graph problem (``ARAPProblem.from_graph``), a rigid motion applied by
hand, and the mesh's own ARAP result for a cloud sampled from the mesh.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import arapkit
from arapkit import Deformer, Graph, InputError, PointCloud
from arapkit.arap.domains import all_weight_kinds, domain_of
from arapkit.arap.problem import ARAPProblem
from arapkit.arap.solve import arap_solve
from arapkit.io import load_handles, load_mesh
from arapkit.mesh.cloud import as_shape
from arapkit.mesh.cloud_weights import graph_weights, point_spacing
from arapkit.mesh.neighbours import check_edges, knn_edges, radius_edges
from arapkit.methods.registry import method, methods

CACTUS = "examples/cactus.off"
CACTUS_HANDLES = "examples/cactus.json"


def _brute_knn(P: np.ndarray, k: int) -> set[tuple[int, int]]:
    """Every point's k nearest others by a full distance matrix, symmetrised."""
    D = np.linalg.norm(P[:, None] - P[None], axis=2)
    np.fill_diagonal(D, np.inf)
    out = set()
    for i in range(len(P)):
        # a stable sort by (distance, index): ties are broken as the tree breaks them
        for j in np.argsort(D[i], kind="stable")[:k]:
            out.add((min(i, int(j)), max(i, int(j))))
    return out


def _sample(mesh, n: int, seed: int = 0):
    """``n`` points uniformly by area on ``mesh``: their faces and barycentric weights."""
    rng = np.random.default_rng(seed)
    V, F = mesh.vertices, mesh.faces
    area = np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    f = rng.choice(len(F), n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return f, np.stack([1 - u - v, u, v], axis=1)


# ----------------------------------------------------------------------------- the graph


@pytest.mark.parametrize("k", [1, 4, 10])
def test_knn_graph_is_the_brute_force_symmetrised_knn(k):
    rng = np.random.default_rng(k)
    P = rng.random((300, 3)) * [3, 1, 0.2]
    E = knn_edges(P, k)
    assert {tuple(e) for e in E.tolist()} == _brute_knn(P, k)
    assert (E[:, 0] < E[:, 1]).all() and len(np.unique(E, axis=0)) == len(E)
    # every point has at least k neighbours
    assert np.bincount(E.ravel(), minlength=len(P)).min() >= k


def test_knn_graph_with_coincident_points_has_no_loops_and_k_neighbours():
    P = np.repeat(np.random.default_rng(1).random((40, 3)), 3, axis=0)  # every point 3x
    E = knn_edges(P, 4)
    assert (E[:, 0] != E[:, 1]).all()
    assert np.bincount(E.ravel(), minlength=len(P)).min() >= 4
    assert knn_edges(P[:3], 10).tolist() == [[0, 1], [0, 2], [1, 2]]  # fewer than k + 1


def test_radius_graph_is_every_pair_closer_than_the_radius():
    P = np.random.default_rng(2).random((200, 3))
    r = 0.15
    D = np.linalg.norm(P[:, None] - P[None], axis=2)
    want = {(i, j) for i in range(len(P)) for j in range(i + 1, len(P)) if D[i, j] < r}
    assert {tuple(e) for e in radius_edges(P, r).tolist()} == want


def test_a_cloud_builds_its_graph_by_its_rule():
    P = np.random.default_rng(3).random((100, 3))
    assert np.array_equal(PointCloud(P).edges, knn_edges(P, 10))
    assert np.array_equal(PointCloud(P, neighbours=6).edges, knn_edges(P, 6))
    assert np.array_equal(PointCloud(P, radius=0.2).edges, radius_edges(P, 0.2))
    with pytest.raises(InputError, match="give neighbours or radius, not both"):
        PointCloud(P, neighbours=5, radius=0.1)


@pytest.mark.parametrize("points, message", [
    (np.zeros((0, 3)), "the point cloud is empty"),
    (np.array([[0, 0, 0], [1, np.nan, 0]]), "point 1 has a non-finite coordinate"),
    (np.zeros((4, 2)), r"points must have shape \(n, 3\)"),
    ([["a", "b", "c"]], "expected real numbers"),
])
def test_bad_points_are_refused_in_one_line(points, message):
    with pytest.raises(InputError, match=message) as e:
        PointCloud(points, name="scan")
    assert "\n" not in str(e.value) and str(e.value).startswith("scan: ")


@pytest.mark.parametrize("edges, message", [
    ([[0, 3]], "edge 0 references a vertex outside 0..2"),
    ([[1, 1]], "edge 0 joins vertex 1 to itself"),
    ([[0, 1], [2, 1], [1, 0]], r"edge 2 \[1, 0\] repeats edge 0"),
    ([[0.5, 1]], "integer vertex indices"),
    ([[0, 1, 2]], r"edges must be an \(m, 2\) integer array"),
])
def test_bad_graph_edges_are_refused_in_one_line(edges, message):
    with pytest.raises(InputError, match=message):
        Graph(np.eye(3), edges, name="g")
    with pytest.raises(InputError, match=message):
        check_edges(edges, 3, "g")


def test_a_graph_keeps_its_edge_order_and_weights_and_checks_them():
    g = Graph(np.eye(3), [[2, 1], [0, 1]], weights=[3.0, 4.0])
    assert g.edges.tolist() == [[2, 1], [0, 1]] and g.weights.tolist() == [3.0, 4.0]
    with pytest.raises(InputError, match=r"weight of edge 1 \(0, 1\) is -1.0"):
        Graph(np.eye(3), [[2, 1], [0, 1]], weights=[3.0, -1.0])
    with pytest.raises(InputError, match="expected 2 edge weights"):
        Graph(np.eye(3), [[2, 1], [0, 1]], weights=[3.0])


# --------------------------------------------------------------------------- the weights


def test_gaussian_weights_follow_the_local_spacing():
    P = np.random.default_rng(4).random((80, 3)) * [1, 1, 5]  # sparser along z
    E = knn_edges(P, 6)
    d = np.linalg.norm(P[E[:, 0]] - P[E[:, 1]], axis=1)
    s = np.zeros(len(P))
    for i in range(len(P)):  # each point's mean edge length, by a loop
        s[i] = d[(E == i).any(axis=1)].mean()
    assert np.allclose(point_spacing(P, E), s)
    want = np.exp(-d**2 / (2 * s[E[:, 0]] * s[E[:, 1]]))
    assert np.allclose(graph_weights(P, E, "gaussian"), want, rtol=1e-14)
    # the width is local: the same cloud 1000 times denser along z weighs alike
    Q = P * [1, 1, 1e-3]
    assert np.allclose(graph_weights(Q, E, "gaussian").mean(), want.mean(), rtol=0.5)
    assert np.array_equal(graph_weights(P, E, "uniform"), np.ones(len(E)))


def test_laplacian_weights_are_the_robust_laplacians_on_the_edges():
    rl = pytest.importorskip("robust_laplacian", reason="weights='laplacian' needs "
                             "pip install 'arapkit[clouds]'")
    P = np.random.default_rng(5).random((300, 3)) * [1, 1, 0.01]  # a thin sheet
    E = knn_edges(P, 10)
    w = graph_weights(P, E, "laplacian", k=10)
    L = rl.point_cloud_laplacian(P, n_neighbors=10)[0].tocsr()
    off = -np.asarray(L[E[:, 0], E[:, 1]]).ravel()
    floor = 1e-3 * off[off > 0].mean()
    assert np.allclose(w, np.maximum(off, floor)) and (w > 0).all()
    # most kNN edges are Laplacian edges, and the Laplacian's are cotangent-like: on an
    # equilateral lattice every interior weight is (cot 60 + cot 60) / 2
    tri = np.array([[i + 0.5 * (j % 2), j * np.sqrt(3) / 2, 0.0]
                    for i in range(12) for j in range(12)])
    Et = knn_edges(tri, 6)
    wt = graph_weights(tri, Et, "laplacian", k=6)
    short = np.isclose(np.linalg.norm(tri[Et[:, 0]] - tri[Et[:, 1]], axis=1), 1.0)
    interior = (np.abs(tri[:, :2] - tri[:, :2].mean(axis=0)) < 3).all(axis=1)
    inner = short & interior[Et].all(axis=1)
    assert np.allclose(wt[inner], 1 / np.sqrt(3), rtol=1e-6)


def test_mesh_weights_on_a_cloud_and_unknown_kinds_are_refused_in_one_line():
    c = PointCloud(np.random.default_rng(6).random((30, 3)), name="scan.ply")
    for kind in ("cotan", "cotan-clamped", "cotan-clamped-each"):
        with pytest.raises(InputError, match=f"scan.ply: weights '{kind}' need triangles"):
            Deformer(c, [0], weights=kind)
    with pytest.raises(InputError, match="weights 'heat' are unknown"):
        Deformer(c, [0], weights="heat")
    assert set(all_weight_kinds()) >= {"gaussian", "uniform", "laplacian", "cotan-clamped"}


# ---------------------------------------------------------------------- the solver doors


def test_domains_and_methods_say_what_applies_to_clouds():
    assert domain_of(PointCloud(np.eye(3))).has_faces is False
    assert domain_of(Graph(np.eye(3), [[0, 1]])).name == "cloud"
    assert domain_of(load_mesh(CACTUS)).has_faces is True
    for_clouds = {m.name for m in methods() if m.applies_to(False)}
    assert {"rring", "embedded"} <= for_clouds
    assert not {"spokes-and-rims", "sr-arap", "laplacian"} & for_clouds
    assert method("rring").needs_faces is False and method("sr-arap").needs_faces is True


@pytest.mark.parametrize("kw, message", [
    ({"energy": "spokes-and-rims"}, "energy='spokes-and-rims' needs a triangle mesh"),
    ({"energy": "sr-arap"}, "energy='sr-arap' needs a triangle mesh"),
    ({"volumetric": True}, "volumetric ARAP fills a closed triangle surface"),
    ({"init": "laplacian"}, "init='laplacian' .* needs a triangle mesh"),
])
def test_what_needs_triangles_refuses_a_cloud_in_one_line(kw, message):
    c = PointCloud(load_mesh(CACTUS).vertices, name="cactus points")
    with pytest.raises(InputError, match=message) as e:
        Deformer(c, [0, 1], **kw)
    assert "\n" not in str(e.value) and "and cactus points is a point cloud" in str(e.value)


def test_a_laplacian_start_asked_at_solve_time_is_refused_too():
    c = PointCloud(load_mesh(CACTUS).vertices, name="c")
    with pytest.raises(InputError, match="init='laplacian'"):
        Deformer(c, [0]).solve(c.points[[0]], init="laplacian")


def test_arrays_open3d_and_trimesh_clouds_are_shapes():
    P = np.random.default_rng(7).random((20, 3))

    class Open3DLike:
        points = P
        normals = np.tile([0.0, 0, 1], (20, 1))

    class TrimeshPointCloudLike:
        vertices = P

    assert isinstance(as_shape(P), PointCloud)
    o3d = as_shape(Open3DLike())
    assert np.array_equal(o3d.points, P) and o3d.normals[0].tolist() == [0, 0, 1]
    assert np.array_equal(as_shape(TrimeshPointCloudLike()).points, P)
    res = Deformer(P, [0, 1]).solve(P[[0, 1]] + 1.0)
    assert np.allclose(res.vertices, P + 1.0)


def test_a_cloud_solve_is_the_graph_problem_with_its_weights(tmp_path):
    """Deformer(cloud) solves exactly the r-ring problem of its graph and weights."""
    mesh = load_mesh(CACTUS)
    c = PointCloud(mesh.vertices)
    hs = load_handles(CACTUS_HANDLES, c.points)
    rings = np.where(c.points[:, 1] > 6.0, 3, 1)
    d = Deformer(c, hs.indices, rings=rings)
    res = d.solve(hs.targets)
    w = graph_weights(c.points, c.edges, "gaussian")
    p = ARAPProblem.from_graph(c.points, c.edges, w, hs.indices, rings=rings)
    want = arap_solve(p, hs.targets)
    assert d.weights_kind == "gaussian" and np.array_equal(d.w, w)
    assert res.iterations == want.iterations
    assert np.abs(res.vertices - want.vertices).max() < 1e-12 * c.bounding_box_diagonal
    # handles met exactly, the energy never rises, the free points moved
    assert np.abs(res.vertices[hs.indices] - hs.targets).max() < 1e-12
    assert np.all(np.diff(res.history) <= 1e-12 * res.history[0])
    assert np.linalg.norm(res.vertices - c.points, axis=1).max() > 0.05 * c.bounding_box_diagonal


def test_a_rigid_handle_motion_moves_the_cloud_rigidly():
    c = PointCloud(np.random.default_rng(8).random((500, 3)) * [4, 1, 1])
    h = np.flatnonzero((c.points[:, 0] < 0.5) | (c.points[:, 0] > 3.5))
    R = Rotation.from_rotvec([0.4, -0.3, 1.1]).as_matrix()
    t = np.array([1.0, 2.0, -3.0])
    res = Deformer(c, h, rings=2).solve(c.points[h] @ R.T + t)
    assert np.abs(res.vertices - (c.points @ R.T + t)).max() < 1e-9
    assert res.rotations is not None and np.abs(res.rotations - R).max() < 1e-9


def test_a_graph_with_its_own_weights_solves_its_own_problem():
    rng = np.random.default_rng(9)
    P = rng.random((60, 3))
    E = knn_edges(P, 5)
    w = rng.random(len(E)) + 0.1
    g = Graph(P, E, w)
    res = Deformer(g, [0, 1, 2, 3], rings=2).solve(P[:4] + [[0, 0, 0.3]] * 4 * np.eye(4)[:, :1])
    want = arap_solve(ARAPProblem.from_graph(P, E, w, [0, 1, 2, 3], rings=2),
                      P[:4] + [[0, 0, 0.3]] * 4 * np.eye(4)[:, :1])
    assert np.abs(res.vertices - want.vertices).max() < 1e-12
    # without weights the graph is weighted as a cloud's
    assert np.array_equal(Deformer(Graph(P, E), [0]).w, graph_weights(P, E, "gaussian"))
    # named weights override the graph's own
    assert np.array_equal(Deformer(g, [0], weights="uniform").w, np.ones(len(E)))


def test_parts_of_a_cloud_without_handles_follow_or_refuse():
    """Disconnected kNN components obey free_components as a mesh's do."""
    rng = np.random.default_rng(10)
    A = rng.random((200, 3))
    c = PointCloud(np.vstack([A, A + [10, 0, 0]]), name="two")
    assert c.n_components == 2
    h = np.flatnonzero(c.points[:200, 0] < 0.3)
    T = c.points[h] + [0, 0, 1.0]
    res = Deformer(c, h).solve(T)
    # the loose part follows the handled one rigidly (here: the same translation)
    assert np.allclose(res.vertices[200:], c.points[200:] + [0, 0, 1.0], atol=1e-9)
    fixed = Deformer(c, h, free_components="fix").solve(T)
    assert np.array_equal(fixed.vertices[200:], c.points[200:])
    with pytest.raises(InputError, match="two: .*add a handle there"):
        Deformer(c, h, free_components="error")


def test_a_cloud_sampled_from_a_mesh_deforms_as_the_mesh_does():
    """The cactus sampled at twice its vertex count (uniformly by area): the cloud's
    deformation lies within 0.5 % (RMS) and 1.2 % (max) of the diagonal of the mesh's own
    r = 1 result at the same points, for the same handle groups (the measured figures
    are 0.23 % and 0.60 %; see docs/clouds.md)."""
    mesh = load_mesh(CACTUS)
    hm = load_handles(CACTUS_HANDLES, mesh.vertices)
    ref = Deformer(mesh, hm.indices, tol=1e-6).solve(hm.targets).vertices
    f, B = _sample(mesh, 2 * mesh.n_vertices)
    P = np.einsum("nk,nkd->nd", B, mesh.vertices[mesh.faces[f]])
    want = np.einsum("nk,nkd->nd", B, ref[mesh.faces[f]])
    hc = load_handles(CACTUS_HANDLES, P)
    got = Deformer(PointCloud(P), hc.indices, tol=1e-6).solve(hc.targets).vertices
    free = np.setdiff1d(np.arange(len(P)), hc.indices)
    err = np.linalg.norm(got[free] - want[free], axis=1) / mesh.bounding_box_diagonal
    assert np.sqrt(np.mean(err**2)) < 0.005 and err.max() < 0.012
    # the arms did swing: the mesh's result is far from rest
    assert np.linalg.norm(want - P, axis=1).max() > 0.1 * mesh.bounding_box_diagonal


def test_public_names():
    assert {"PointCloud", "Graph"} <= set(arapkit.__all__)


def _kabsch_residual(A: np.ndarray, B: np.ndarray, w: np.ndarray) -> float:
    """min over rotations R of sum_i w_i |B_i - R A_i|^2, by SVD (brute force)."""
    S = (w[:, None] * A).T @ B
    U, _, Vt = np.linalg.svd(S)
    R = Vt.T @ U.T
    if np.linalg.det(R) < 0:
        Vt[2] *= -1
        R = Vt.T @ U.T
    return float(np.sum(w * np.sum((B - A @ R.T) ** 2, axis=1)))


def test_a_ring_scale_below_one_blends_springs_on_a_graph():
    """r counted on a finer cloud (ring_scale s < 1, a coarse-to-fine proxy's): each point's
    one-ring weighted by a = (r s)^2 plus a rotation per edge, 2 (1 - a) w_e |e' - R_e e|^2
    (a spring), summed by brute force at the best rotations."""
    rng = np.random.default_rng(11)
    c = PointCloud(rng.random((60, 3)), neighbours=6)
    h = np.array([0, 1, 2, 3])
    s = 0.5
    d = Deformer(c, h, ring_scale=s)
    a = min(1.0, s * s)  # r = 1 everywhere
    P = c.points + 0.05 * rng.normal(size=c.points.shape)
    E, w = c.edges, d.w
    want = 0.0
    for k in range(c.n_vertices):
        mine = np.flatnonzero((E == k).any(axis=1))
        want += a * _kabsch_residual(c.points[E[mine, 0]] - c.points[E[mine, 1]],
                                     P[E[mine, 0]] - P[E[mine, 1]], w[mine])
    stretch = (np.linalg.norm(P[E[:, 0]] - P[E[:, 1]], axis=1)
               - np.linalg.norm(c.points[E[:, 0]] - c.points[E[:, 1]], axis=1))
    want += np.sum(2 * (1 - a) * w * stretch**2)
    assert d.energy_of(P, P[h]) == pytest.approx(want, rel=1e-9)
    # descent: every step lowers it
    res = d.solve(P[h] + [0, 0, 0.2], tol=1e-9, max_iter=300)
    assert np.all(np.diff(res.history) <= 1e-12 * res.history[0])
