"""Mesh model: loading and validation of bad inputs (issue 2, deliverable 2)."""

from __future__ import annotations

import gzip
from collections import Counter

import numpy as np
import pytest
from conftest import data_path

from arapkit import InputError, Mesh, load_mesh
from arapkit.mesh.shapes import bar

TRI = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])


def test_bar_counts():
    m = bar()
    # 70x4x4 cells: (71*5*5) grid points minus the (69*3*3) interior ones
    assert m.n_vertices == 71 * 25 - 69 * 9 == 1154
    # each of the 4 long sides has 70*4 quads, each cap 4*4, two triangles per quad
    assert m.n_faces == 2 * (4 * 70 * 4 + 2 * 16)
    assert m.n_components == 1 and m.boundary_loops == []
    # Euler characteristic of a sphere
    assert m.n_vertices - len(m.edges) + m.n_faces == 2


def test_non_finite_vertex_names_vertex():
    V = TRI.copy()
    V[2, 1] = np.nan
    with pytest.raises(InputError, match="vertex 2 has a non-finite"):
        Mesh(V, [[0, 1, 2]])


def test_face_index_out_of_range_names_face():
    with pytest.raises(InputError, match="face 1 references vertex 7 .*4 vertices"):
        Mesh(TRI, [[0, 1, 2], [1, 3, 7]])


def test_polygons_are_triangulated_and_reported():
    m = Mesh(TRI, [[0, 1, 3, 2]])
    assert m.n_faces == 2
    assert any("split into triangles" in n for n in m.notes)


def test_too_few_corners():
    with pytest.raises(InputError, match="face 0 has 2 corners"):
        Mesh(TRI, [[0, 1]])


def test_degenerate_and_repeated_faces_dropped():
    V = np.vstack([TRI, [[2.0, 0, 0]]])
    faces = [[0, 1, 2], [2, 1, 0], [1, 2, 3], [0, 0, 1], [0, 1, 4]]
    m = Mesh(V, faces)
    assert m.faces.tolist() == [[0, 1, 2], [1, 2, 3]]
    joined = " ".join(m.notes)
    assert "repeat a vertex (first: face 3)" in joined
    assert "zero area (first: face 4)" in joined
    assert "repeat an earlier face (first: face 1)" in joined
    assert "vertex 4" in joined  # now unreferenced, kept fixed
    assert m.dropped_faces == {"repeated_vertex": 1, "zero_area": 1, "duplicate": 1}


def test_unreferenced_vertex_kept():
    V = np.vstack([TRI, [[5.0, 5, 5]]])
    m = Mesh(V, [[0, 1, 2], [1, 3, 2]])
    assert m.n_vertices == 5 and m.unreferenced.tolist() == [4]
    assert any("stay fixed" in n for n in m.notes)


def test_truncated_off(tmp_path):
    src = data_path("meshes", "plane.off").read_text().splitlines()
    p = tmp_path / "trunc.off"
    p.write_text("\n".join(src[: len(src) // 2]))
    with pytest.raises(InputError, match="trunc.off: truncated"):
        load_mesh(p)


def test_missing_and_unsupported(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        load_mesh(tmp_path / "nope.off")
    (tmp_path / "x.xyz").write_text("1 2 3")
    with pytest.raises(InputError, match="unsupported mesh format"):
        load_mesh(tmp_path / "x.xyz")


def test_garbage_ply(tmp_path):
    p = tmp_path / "bad.ply"
    p.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n")
    with pytest.raises(InputError, match="bad.ply"):
        load_mesh(p)


def test_obj_keeps_order_and_triangulates(tmp_path):
    p = tmp_path / "q.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1 4/1\n")
    m = load_mesh(p)
    assert m.vertices[:, :2].tolist() == [[0, 0], [1, 0], [1, 1], [0, 1]]
    assert m.n_faces == 2 and any("split" in n for n in m.notes)


def test_real_meshes_load():
    m = load_mesh(data_path("meshes", "cow.off"))
    assert (m.n_vertices, m.n_faces) == (2904, 5804)
    raw = data_path("meshes", "cow.off").read_text().split()
    # first vertex is the first coordinate triple after the header
    assert np.allclose(m.vertices[0], [float(x) for x in raw[4:7]])
    c = load_mesh(data_path("meshes", "cylinder.off"))
    # boundary edges counted independently: undirected edges used by exactly one face
    counts = Counter(tuple(sorted(e)) for f in c.faces.tolist()
                     for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])))
    boundary = {v for e, k in counts.items() if k == 1 for v in e}
    assert sum(len(loop) for loop in c.boundary_loops) == len(boundary) > 0


def test_gzip_ply_and_snowden(tmp_path):
    obj = load_mesh(data_path("meshes", "npm_snowden_lo.obj"))
    assert obj.n_vertices == 18743
    # components by an independent union-find over the faces
    parent = list(range(obj.n_vertices))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for f in obj.faces.tolist():
        for b in f[1:]:
            parent[find(b)] = find(f[0])
    assert obj.n_components == len({find(v) for v in range(obj.n_vertices)}) > 1
    assert obj.n_nonmanifold_edges > 0
    p = tmp_path / "tri.ply.gz"
    ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n" \
          "property float z\nelement face 1\nproperty list uchar int vertex_indices\n" \
          "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    p.write_bytes(gzip.compress(ply.encode()))
    m = load_mesh(p)
    assert m.n_vertices == 3 and m.n_faces == 1


@pytest.mark.parametrize("faces", [[None], [[], None], [[0, 1, 2], 7], [[0, 1, 2], "012"]])
def test_a_face_that_is_no_polygon_is_refused_in_one_line(faces):
    """Found by the hostile-input properties: a face entry that is None, a number or text
    was a TypeError traceback."""
    with pytest.raises(InputError, match=r"face \d+ is not a list of vertex indices"):
        Mesh(np.zeros((3, 3)), faces)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_component_labels_are_scipys(seed):
    """The compiled union-find labels the components exactly as SciPy's
    ``connected_components`` does (numbered by their lowest vertex), on graphs of many
    parts, vertices in no face among them, and on an EdgeGraph."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from arapkit.arap.graph import EdgeGraph

    rng = np.random.default_rng(seed)
    n = 3000
    F = rng.integers(0, n, (900, 3))  # sparse: hundreds of parts, and unused vertices
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    m = Mesh(rng.normal(size=(n, 3)), F)
    E = m.edges
    A = coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n))
    k, want = connected_components(A, directed=False)
    assert 100 < k < n and m.n_components == k
    assert np.array_equal(m.component_labels, want)
    g = EdgeGraph.from_mesh(m)
    assert g.n_components == k and np.array_equal(g.component_labels, want)


def test_content_hash_tells_meshes_apart_by_every_number():
    """The proxy cache's key: equal for equal content, different for one vertex moved by
    one unit in the last place or one face's corners turned."""
    m = bar()
    same = Mesh(m.vertices.copy(), m.faces.copy())
    assert same.content_hash == m.content_hash
    V = m.vertices.copy()
    V[17, 1] = np.nextafter(V[17, 1], np.inf)
    assert Mesh(V, m.faces).content_hash != m.content_hash
    F = m.faces.copy()
    F[5] = F[5, [1, 2, 0]]
    assert Mesh(m.vertices, F).content_hash != m.content_hash
