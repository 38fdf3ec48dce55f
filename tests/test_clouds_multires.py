"""Coarse to fine on a large point cloud: a voxel subsample previews and starts the exact
solve (arapkit.methods.multires.subsampler, the domain's coarsening), as for meshes.

The cloud is the 44K vertex set of the bar of tests/test_multires.py, subsampled to a 20K
proxy. Oracles: a rigid motion applied by hand, a fresh solver for the same problem, the
plain solve from rest, and a brute-force voxel grid.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from arapkit import Deformer, PointCloud
from arapkit.mesh.shapes import bar, bar_bend
from arapkit.methods.deformer import coarse_to_fine
from arapkit.methods.multires import MultiresDeformer, coarsening_of, subsample
from arapkit.methods.multires.subsampler import cell_size, voxel_cells


@pytest.fixture(scope="module")
def big():
    mesh = bar(segments=(450, 24, 24))
    h, t = bar_bend(mesh, 90)
    return PointCloud(mesh.vertices, name="bar points"), h, t


@pytest.fixture(scope="module")
def multi(big):
    cloud, h, _ = big
    return MultiresDeformer(cloud, h)


def test_the_proxy_is_a_voxel_subsample_of_real_points(big, multi):
    cloud = big[0]
    proxy, home = multi.proxy_mesh, multi._home
    assert isinstance(proxy, PointCloud) and coarsening_of(cloud).name == "subsample"
    assert 15_000 < proxy.n_vertices < 25_000
    # every proxy point is a point of the cloud, and every point's home is in its cell
    rows = {tuple(p) for p in cloud.points.tolist()}
    assert all(tuple(q) in rows for q in proxy.points.tolist())
    assert np.array_equal(np.bincount(home, minlength=proxy.n_vertices) > 0,
                          np.ones(proxy.n_vertices, bool))
    # brute force: the grid's cells are the homes' groups, and each keeps its point
    # nearest the cell's centroid
    P = cloud.points
    cells, count = voxel_cells(P, cell_size(P, 20_000))
    assert count == proxy.n_vertices
    assert len(np.unique(np.stack([cells, home], axis=1), axis=0)) == count
    for c in range(0, count, 397):
        members = np.flatnonzero(cells == c)
        centroid = P[members].mean(axis=0)
        nearest = members[np.argmin(np.linalg.norm(P[members] - centroid, axis=1))]
        assert np.array_equal(proxy.points[home[nearest]], P[nearest])
        assert (home[members] == home[nearest]).all()
    assert np.linalg.norm(multi.binding.offsets, axis=1).max() < 0.02 * cloud.bounding_box_diagonal


def test_small_clouds_are_their_own_proxy():
    c = PointCloud(np.random.default_rng(0).random((500, 3)))
    p, home = subsample(c, 300)
    assert p is c and np.array_equal(home, np.arange(500))


def test_rigid_handle_motion_gives_a_rigid_preview_and_result(big, multi):
    cloud, h, _ = big
    R = Rotation.from_rotvec([0.3, -0.7, 0.4]).as_matrix()
    t = np.array([0.5, -2.0, 1.0])
    V = cloud.points
    want = V @ R.T + t
    p = multi.preview(V[h] @ R.T + t, restart=True)
    assert np.abs(p.proxy.rotations - R).max() < 1e-10
    assert np.abs(p.vertices - want).max() < 1e-10 * cloud.bounding_box_diagonal
    res = multi.solve(V[h] @ R.T + t)
    assert np.abs(res.vertices - want).max() < 1e-10 * cloud.bounding_box_diagonal


def test_solve_equals_a_fresh_solver_and_is_deterministic(big, multi):
    cloud, h, t = big
    other = MultiresDeformer(cloud, h)
    assert np.array_equal(other.proxy_mesh.points, multi.proxy_mesh.points)
    a, b = multi.preview(t, restart=True), other.preview(t, restart=True)
    assert np.array_equal(a.vertices, b.vertices)
    ra, rb = multi.solve(t), other.solve(t)
    assert np.array_equal(ra.vertices, rb.vertices)
    multi.preview(cloud.points[h] + 0.3, max_iter=5)  # whatever the proxy did before
    assert np.array_equal(multi.solve(t).vertices, ra.vertices)
    assert multi.energy_of(ra.vertices, t) == pytest.approx(ra.energy, rel=1e-9)


def test_the_settled_preview_and_the_exact_solve_agree_and_the_start_pays(big, multi):
    """The settled preview lies within 0.5 % of the diagonal of the exact result (0.15 %
    measured), and the exact solve from it needs fewer full iterations than from rest, to
    an energy as low."""
    cloud, h, t = big
    res = multi.solve(t)
    p = multi.preview(t, restart=True)
    diag = cloud.bounding_box_diagonal
    assert np.abs(p.vertices - res.vertices).max() < 0.005 * diag
    plain = Deformer(cloud, h, multires=False, accelerate=True).solve(t)
    assert res.converged and plain.converged
    assert res.iterations < plain.iterations
    assert res.energy <= plain.energy * (1 + 1e-3)
    assert res.timings["proxy_iterations"] > 0
    assert np.abs(res.vertices[h] - t).max() < 1e-12


def test_the_rigidity_map_reaches_the_proxy_counted_at_its_scale(big):
    cloud, h, t = big
    r = np.where(cloud.points[:, 0] > 3.5, 4, 1).astype(np.int32)
    d = MultiresDeformer(cloud, h, rings=r, proxy_vertices=2_000)
    s = d.edge_ratio
    assert 0 < s < 1
    want = np.clip(np.rint(r[d.binding.near_full] * s), 1, None)
    assert np.array_equal(d.proxy.rings, want)
    assert d.full.rings.tolist() == r.tolist()
    d.set_rings(np.ones_like(r) * 6)
    assert np.array_equal(d.proxy.rings, np.clip(np.rint(6 * s), 1, None) * np.ones(len(want)))


def test_levels_work_on_a_cloud_and_keep_rigid_motions_rigid(big):
    cloud, h, t = big
    d = MultiresDeformer(cloud, h, proxy_vertices=2_000, levels=[8_000])
    res = d.solve(t)
    assert res.converged and res.timings["level_iterations"] > 0 and len(d.levels) == 1
    assert isinstance(d.levels[0].mesh, PointCloud)
    R = Rotation.from_rotvec([0.0, 0.5, 0.1]).as_matrix()
    rigid = d.solve(cloud.points[h] @ R.T)
    assert np.abs(rigid.vertices - cloud.points @ R.T).max() < 1e-10 * cloud.bounding_box_diagonal


def test_large_clouds_are_solved_coarse_to_fine_by_default():
    import types

    from arapkit.methods.deformer import MULTIRES_AUTO_VERTICES

    at = types.SimpleNamespace(n_vertices=MULTIRES_AUTO_VERTICES)
    assert coarse_to_fine(at, None, {})
    c = PointCloud(np.random.default_rng(1).random((3000, 3)))
    assert type(Deformer(c, [0], multires=True)) is MultiresDeformer
    assert type(Deformer(c, [0])) is Deformer
