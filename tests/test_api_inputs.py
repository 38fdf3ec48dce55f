"""What a trimesh or libigl user passes to the library: their mesh, their handle set.

``Deformer`` and the other doors that take a mesh accept an :class:`arapkit.Mesh`, a
``(vertices, faces)`` pair or a ``trimesh.Trimesh``; a handle set read by
``load_handles`` stands for its indices (as ``handles``) and its targets (as ``targets``);
functions that take positions take a mesh or a result too. Each is checked against the
same call made the documented way: the results must be identical, not merely close.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

import arapkit
from arapkit.errors import InputError
from arapkit.mesh import model

ROOT = Path(__file__).resolve().parents[1]
MESH = ROOT / "examples" / "cactus.off"
HANDLES = ROOT / "examples" / "cactus.json"


@pytest.fixture(scope="module")
def cactus():
    mesh = arapkit.load_mesh(MESH)
    hs = arapkit.load_handles(HANDLES, mesh.vertices)
    ref = arapkit.Deformer(mesh, hs.indices).solve(hs.targets)
    return mesh, hs, ref


def _trimesh(mesh):
    return trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)


class _Open3DLike:
    """What Open3D's ``TriangleMesh`` offers: ``vertices`` and ``triangles``, as sequences
    that ``np.asarray`` reads (open3d itself is not a test dependency)."""

    def __init__(self, mesh):
        self.vertices = [tuple(v) for v in mesh.vertices]
        self.triangles = [tuple(f) for f in mesh.faces]


@pytest.mark.parametrize("kind", ["trimesh", "open3d", "pair", "list"])
def test_deformer_takes_a_trimesh_or_a_vertices_faces_pair(cactus, kind):
    mesh, hs, ref = cactus
    given = {"trimesh": _trimesh(mesh), "open3d": _Open3DLike(mesh),
             "pair": (mesh.vertices, mesh.faces),
             "list": [mesh.vertices.tolist(), mesh.faces.tolist()]}[kind]
    res = arapkit.Deformer(given, hs.indices).solve(hs.targets)
    assert res.iterations == ref.iterations
    assert np.array_equal(res.vertices, ref.vertices)


def test_a_handle_set_stands_for_its_indices_and_targets(cactus):
    mesh, hs, ref = cactus
    res = arapkit.Deformer(mesh, hs).solve(hs)
    assert np.array_equal(res.vertices, ref.vertices)
    # moved on: the set's targets, not its indices, are what solve reads
    moved = arapkit.Deformer(mesh, hs).solve(hs.targets + [0.0, 0.5, 0.0])
    assert not np.array_equal(moved.vertices, ref.vertices)


def test_a_trimesh_is_converted_once(cactus, monkeypatch):
    mesh, hs, _ = cactus
    tm = _trimesh(mesh)
    made = []
    check = model.Mesh._check_vertices

    def counting(self, vertices):
        made.append(self.name)
        return check(self, vertices)

    monkeypatch.setattr(model.Mesh, "_check_vertices", counting)
    d = arapkit.Deformer(tm, hs)
    assert made == ["mesh"]  # Deformer.__new__ and __init__ share one conversion
    assert np.array_equal(d.mesh.vertices, mesh.vertices)


def test_the_other_mesh_doors_take_a_trimesh(cactus):
    mesh, hs, ref = cactus
    tm = _trimesh(mesh)
    assert np.array_equal(arapkit.laplacian_edit(tm, hs, hs),
                          arapkit.laplacian_edit(mesh, hs.indices, hs.targets))
    a = arapkit.Deformer(tm, hs, multires=True, proxy_vertices=500).solve(hs)
    b = arapkit.Deformer(mesh, hs.indices, multires=True, proxy_vertices=500).solve(hs.targets)
    assert np.array_equal(a.vertices, b.vertices)
    learned = arapkit.learn_rings(tm, [ref.vertices], r_max=3)
    assert np.array_equal(learned.rings, arapkit.learn_rings(mesh, [ref.vertices],
                                                              r_max=3).rings)


def test_the_torch_layer_takes_a_trimesh(cactus):
    torch = pytest.importorskip("torch", reason="the torch extra is not installed")
    from arapkit.torch import ARAPLayer

    mesh, hs, _ = cactus
    T = torch.tensor(hs.targets, dtype=torch.float64)
    a = ARAPLayer(_trimesh(mesh), hs.indices, dtype=torch.float64)(T)
    b = ARAPLayer(mesh, hs.indices, dtype=torch.float64)(T)
    assert torch.equal(a, b)


@pytest.mark.parametrize("kind", ["mesh", "trimesh"])
def test_positions_may_be_given_as_a_mesh(cactus, kind):
    mesh, hs, _ = cactus
    given = mesh if kind == "mesh" else _trimesh(mesh)
    got = arapkit.load_handles(HANDLES, given)
    assert np.array_equal(got.indices, hs.indices) and np.array_equal(got.targets, hs.targets)
    box = ([-1, -1, -1], [1, 1, 1])
    assert np.array_equal(arapkit.select_box(given, *box), arapkit.select_box(mesh.vertices,
                                                                              *box))
    assert arapkit.guess_up(given) == arapkit.guess_up(mesh.vertices)


def test_save_mesh_takes_a_mesh_a_trimesh_or_a_result(cactus, tmp_path):
    mesh, _, ref = cactus
    arapkit.save_mesh(tmp_path / "a.off", mesh)
    back = arapkit.load_mesh(tmp_path / "a.off")
    assert np.array_equal(back.vertices, mesh.vertices) and np.array_equal(back.faces,
                                                                           mesh.faces)
    arapkit.save_mesh(tmp_path / "b.ply", ref, like=mesh)
    assert np.array_equal(arapkit.load_mesh(tmp_path / "b.ply").vertices, ref.vertices)
    arapkit.save_mesh(tmp_path / "c.obj", trimesh.Trimesh(ref.vertices, mesh.faces,
                                                          process=False))
    c = arapkit.load_mesh(tmp_path / "c.obj")
    assert np.array_equal(c.vertices, ref.vertices) and np.array_equal(c.faces, mesh.faces)
    arapkit.save_mesh(tmp_path / "d.off", _Open3DLike(mesh))
    d = arapkit.load_mesh(tmp_path / "d.off")
    assert np.array_equal(d.vertices, mesh.vertices) and np.array_equal(d.faces, mesh.faces)


@pytest.mark.parametrize("given, says", [
    (str(MESH), "got str (load a file with arapkit.load_mesh)"),
    (None, "got NoneType"),
    # an (n, 3) array is a point cloud (docs/clouds.md); a flat one is nothing
    (np.zeros(5), "got ndarray"),
])
def test_what_is_not_a_mesh_gets_one_line(cactus, given, says):
    _, hs, _ = cactus
    with pytest.raises(InputError, match="^mesh: expected an arapkit.Mesh") as err:
        arapkit.Deformer(given, hs)
    assert str(err.value).endswith(says) and "\n" not in str(err.value)
