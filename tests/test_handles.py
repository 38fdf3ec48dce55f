"""Handle JSON, .sel/.def and rigidity files (arapkit.io.handles, .seldef, .rigidity)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from arapkit.errors import InputError
from arapkit.io import (
    HandleGroup,
    HandleSet,
    load_def,
    load_handles,
    load_rings,
    load_sel,
    parse_handles,
    rotation_matrix,
    save_def,
    save_handles,
    save_mesh,
    save_rings,
    save_sel,
    select_box,
    select_nearest,
    select_sphere,
)


@pytest.fixture()
def grid() -> np.ndarray:
    """A 5 x 4 x 3 lattice of points with unit spacing (60 vertices)."""
    x, y, z = np.meshgrid(np.arange(5.0), np.arange(4.0), np.arange(3.0), indexing="ij")
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)


def _brute(V, pred):
    return [i for i, v in enumerate(V) if pred(v)]


# --------------------------------------------------------------------------- selections


def test_select_box_matches_brute_force(grid):
    got = select_box(grid, [1, 0.5, -1], [3, 2, 1]).tolist()
    want = _brute(grid, lambda v: 1 <= v[0] <= 3 and 0.5 <= v[1] <= 2 and -1 <= v[2] <= 1)
    assert got == want and len(want) == 3 * 2 * 2


def test_select_sphere_is_inclusive(grid):
    got = select_sphere(grid, [2, 2, 1], 1.0).tolist()
    want = _brute(grid, lambda v: (v[0] - 2) ** 2 + (v[1] - 2) ** 2 + (v[2] - 1) ** 2 <= 1.0)
    assert got == want and len(want) == 7  # centre and its 6 axis neighbours


def test_select_nearest_breaks_ties_by_index(grid):
    # the 6 axis neighbours of (2, 2, 1) tie at distance 1; the centre is nearest
    got = select_nearest(grid, [2, 2, 1], 3)
    d = np.linalg.norm(grid - [2, 2, 1], axis=1)
    order = sorted(range(len(grid)), key=lambda i: (d[i], i))[:3]
    assert got.tolist() == sorted(order)


def test_rotation_matrix_quarter_turns():
    np.testing.assert_allclose(rotation_matrix([0, 0, 2], 90) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(rotation_matrix([1, 0, 0], 90) @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    R = rotation_matrix([1, 2, 3], 37)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
    assert math.isclose(np.linalg.det(R), 1.0)


# --------------------------------------------------------------------------- JSON groups


def test_each_selection_kind_and_motion(grid):
    spec = [
        {"name": "base", "box": {"min": [-1, -1, -1], "max": [0, 9, 9]}, "fixed": True},
        {"name": "lift", "indices": [59, 58], "translate": [0, 0, 2.5]},
        {"name": "ball", "sphere": {"center": [2, 2, 1], "radius": 1}},
        {
            "name": "near",
            "nearest": {"point": [4, 0, 0], "k": 2},
            "targets": [[9, 9, 9], [8, 8, 8]],
        },
    ]
    hs = parse_handles(spec, grid, "h.json")
    by = {g.name: g for g in hs.groups}
    base = np.flatnonzero(grid[:, 0] == 0)
    assert by["base"].indices.tolist() == base.tolist() and by["base"].kind == "fixed"
    np.testing.assert_array_equal(by["base"].targets, grid[base])
    # explicit indices keep the order given
    assert by["lift"].indices.tolist() == [59, 58]
    np.testing.assert_array_equal(by["lift"].targets, grid[[59, 58]] + [0, 0, 2.5])
    assert by["ball"].kind == "fixed" and len(by["ball"].indices) == 7
    # (4,0,0) is vertex 48 (index = 12 x + 3 y + z); its neighbours (3,0,0) = 36,
    # (4,0,1) = 49 and (4,1,0) = 51 tie at distance 1 and the lowest index wins
    assert by["near"].indices.tolist() == [36, 48]
    np.testing.assert_array_equal(by["near"].targets, [[9, 9, 9], [8, 8, 8]])
    # the flattened arrays follow group order
    assert len(hs) == len(base) + 2 + 7 + 2
    np.testing.assert_array_equal(hs.indices[: len(base)], base)
    assert hs.fixed_mask.sum() == len(base) + 7


def test_rotate_about_centre_then_translate(grid):
    spec = [
        {
            "indices": [0, 1, 5],
            "rotate": {"axis": [0, 0, 1], "degrees": 90, "center": [1, 1, 0]},
            "translate": [0, 0, 10],
        }
    ]
    hs = parse_handles(spec, grid)
    # 90 degrees about z through (1,1): (x, y) -> (1 - (y - 1), 1 + (x - 1)) = (2 - y, x)
    P = grid[[0, 1, 5]]
    want = np.stack([2 - P[:, 1], P[:, 0], P[:, 2] + 10], axis=1)
    np.testing.assert_allclose(hs.targets, want, atol=1e-14)


def test_rotate_default_centre_is_group_centroid(grid):
    idx = select_box(grid, [0, 0, 0], [1, 1, 0]).tolist()
    hs = parse_handles([{"indices": idx, "rotate": {"axis": [0, 0, 1], "degrees": 180}}], grid)
    P = grid[idx]
    np.testing.assert_allclose(hs.targets, 2 * P.mean(0) * [1, 1, 0] - P * [1, 1, -1], atol=1e-14)


def test_groups_object_form_is_accepted(grid):
    hs = parse_handles({"groups": [{"indices": [3]}]}, grid)
    assert hs.groups[0].name == "group 1" and hs.indices.tolist() == [3]


@pytest.mark.parametrize(
    "spec, message",
    [
        ([{"name": "a", "indices": [0], "colour": "red"}], "group 1 ('a'): unknown key 'colour'"),
        ([{"name": "a", "box": {"min": [0, 0, 0], "max": [1, 1, 1], "x": 1}}], "unknown key 'x'"),
        (
            [{"name": "a", "indices": [0]}, {"name": "b", "indices": [60]}],
            "group 2 ('b'): vertex index 60 out of range (mesh has 60 vertices)",
        ),
        ([{"name": "a", "indices": [-1]}], "vertex index -1 out of range"),
        (
            [{"name": "far", "sphere": {"center": [50, 50, 50], "radius": 1}}],
            "group 1 ('far'): sphere selects no vertices",
        ),
        (
            [
                {"name": "a", "box": {"min": [0, 0, 0], "max": [1, 1, 1]}},
                {"name": "b", "indices": [1]},
            ],
            "group 2 ('b'): overlaps group 'a'",
        ),
        ([{"name": "a", "indices": [0]}, {"name": "a", "indices": [1]}], "already used"),
        ([{"indices": [0], "box": {"min": [0, 0, 0], "max": [1, 1, 1]}}], "exactly one selection"),
        ([{"translate": [1, 2, 3]}], "exactly one selection"),
        ([{"indices": [0], "fixed": True, "translate": [0, 0, 1]}], "cannot be combined"),
        (
            [{"indices": [0], "targets": [[0, 0, 0]], "rotate": {"axis": [0, 0, 1], "degrees": 3}}],
            "cannot be combined",
        ),
        ([{"indices": [0, 1], "targets": [[0, 0, 0]]}], "needs 2 positions"),
        ([{"indices": [0], "translate": [1, 2]}], "list of 3 finite numbers"),
        ([{"indices": [0], "translate": [1, True, 2]}], "list of 3 finite numbers"),
        ([{"indices": [0], "rotate": {"axis": [0, 0, 0], "degrees": 3}}], "non-zero"),
        ([{"indices": [0], "rotate": {"axis": [0, 0, 1]}}], "'rotate' needs 'degrees'"),
        ([{"indices": [0, 0]}], "listed twice"),
        ([{"indices": [0.5]}], "list of integers"),
        ([{"nearest": {"point": [0, 0, 0], "k": 61}}], "'k' must be an integer in 1..60"),
        ([{"box": {"min": [2, 0, 0], "max": [1, 1, 1]}}], "must not exceed"),
        ([{"sphere": {"center": [0, 0, 0], "radius": -1}}], "positive number"),
        ([], "no handle groups"),
        ({"handles": []}, "unknown top-level key 'handles'"),
        ("nope", "expected a list of handle groups"),
        ([{"indices": [0], "fixed": False}], "'fixed' may only be true"),
    ],
)
def test_bad_groups_name_file_and_group(grid, spec, message):
    with pytest.raises(InputError) as err:
        parse_handles(spec, grid, "h.json")
    text = str(err.value)
    assert text.startswith("h.json: ") and message in text and "\n" not in text


def test_load_handles_reports_bad_json(tmp_path, grid):
    p = tmp_path / "h.json"
    p.write_text('[{"indices": [0],}]')
    with pytest.raises(InputError, match=r"h.json: not valid JSON .*line 1"):
        load_handles(p, grid)
    with pytest.raises(InputError, match="file not found"):
        load_handles(tmp_path / "missing.json", grid)


def test_save_handles_round_trip(tmp_path, grid):
    spec = [
        {"name": "base", "box": {"min": [-1, -1, -1], "max": [0, 9, 9]}},
        {
            "name": "tip",
            "nearest": {"point": [4, 3, 2], "k": 4},
            "rotate": {"axis": [1, 1, 0], "degrees": 33},
            "translate": [0.1, 0.2, 0.3],
        },
    ]
    hs = parse_handles(spec, grid)
    save_handles(tmp_path / "explicit.json", hs)
    again = load_handles(tmp_path / "explicit.json", grid)
    assert [g.name for g in again.groups] == ["base", "tip"]
    np.testing.assert_array_equal(again.indices, hs.indices)
    np.testing.assert_array_equal(again.targets, hs.targets)  # repr round-trips floats exactly
    assert again.fixed_mask.tolist() == hs.fixed_mask.tolist()


def test_empty_handle_set_has_empty_arrays():
    hs = HandleSet([])
    assert hs.indices.shape == (0,) and hs.targets.shape == (0, 3) and len(hs) == 0
    g = HandleGroup("g", np.array([2]), np.ones((1, 3)), "moved")
    assert HandleSet([g]).fixed_mask.tolist() == [False]


# --------------------------------------------------------------------------- .sel / .def


def test_sel_def_pair(tmp_path, grid):
    status = np.ones(len(grid), dtype=int)
    status[grid[:, 0] == 0] = 0
    status[grid[:, 0] == 4] = 2
    sel = tmp_path / "g.sel"
    sel.write_text("# per vertex status\n# 60 vertices\n" + "\n".join(map(str, status)) + "\n")
    M = np.eye(4)
    M[:3, :3] = rotation_matrix([0, 1, 0], 90)
    M[:3, 3] = [1.0, 2.0, 3.0]
    save_def(tmp_path / "g.def", M)
    hs = load_handles(sel, grid)  # .def found next to the .sel
    fixed, moved = np.flatnonzero(status == 0), np.flatnonzero(status == 2)
    assert [g.name for g in hs.groups] == ["fixed", "handle"]
    np.testing.assert_array_equal(hs.groups[0].indices, fixed)
    np.testing.assert_array_equal(hs.groups[0].targets, grid[fixed])
    hom = np.c_[grid[moved], np.ones(len(moved))] @ M.T
    np.testing.assert_allclose(hs.groups[1].targets, hom[:, :3], atol=1e-14)


def test_save_sel_round_trip(tmp_path, grid):
    save_sel(tmp_path / "a.sel", len(grid), [0, 1], [59])
    hs = load_sel(tmp_path / "a.sel", grid)
    assert hs.groups[0].indices.tolist() == [0, 1] and hs.groups[1].indices.tolist() == [59]
    np.testing.assert_array_equal(hs.targets, grid[[0, 1, 59]])  # identity without a .def


def test_sel_errors(tmp_path, grid):
    (tmp_path / "short.sel").write_text("0\n1\n2\n")
    with pytest.raises(InputError, match="short.sel: 3 vertex statuses for a mesh of 60"):
        load_sel(tmp_path / "short.sel", grid)
    (tmp_path / "word.sel").write_text("0\nfree\n" + "1\n" * 58)
    with pytest.raises(InputError, match="status 'free' is not an integer"):
        load_sel(tmp_path / "word.sel", grid)
    (tmp_path / "free.sel").write_text("1\n" * 60)
    with pytest.raises(InputError, match="no vertex has status 0"):
        load_sel(tmp_path / "free.sel", grid)
    (tmp_path / "lonely.sel").write_text("0\n" * 60)
    with pytest.raises(InputError, match="needs a .def transform"):
        load_handles(tmp_path / "lonely.sel", grid)


def test_def_errors(tmp_path):
    (tmp_path / "a.def").write_text("1 0 0 0\n0 1 0 0\n0 0 1 0\n")
    with pytest.raises(InputError, match="a.def: expected 16 finite numbers .* got 12"):
        load_def(tmp_path / "a.def")
    (tmp_path / "b.def").write_text("1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n")
    with pytest.raises(InputError, match="last row must be 0 0 0 1"):
        load_def(tmp_path / "b.def")
    (tmp_path / "c.def").write_text("# comment\n1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 x\n")
    with pytest.raises(InputError, match="expected 16 numbers"):
        load_def(tmp_path / "c.def")


def test_def_only_with_sel(tmp_path, grid):
    (tmp_path / "h.json").write_text('[{"indices": [0]}]')
    save_def(tmp_path / "a.def", np.eye(4))
    with pytest.raises(InputError, match="only applies to .sel"):
        load_handles(tmp_path / "h.json", grid, transform=tmp_path / "a.def")


# --------------------------------------------------------------------------- rigidity maps


def test_rings_text_npy_and_ply(tmp_path):
    r = np.array([1, 2, 2, 6, 10])
    (tmp_path / "r.txt").write_text("# soft then hard\n1\n2\n\n2\n6\n10\n")
    assert load_rings(tmp_path / "r.txt", 5).tolist() == r.tolist()
    np.save(tmp_path / "r.npy", r.astype(np.int32))
    assert load_rings(tmp_path / "r.npy", 5).tolist() == r.tolist()
    np.save(tmp_path / "f.npy", r.astype(np.float64))  # integral floats are fine
    assert load_rings(tmp_path / "f.npy", 5).dtype == np.int64
    V = np.random.default_rng(0).random((5, 3))
    save_mesh(tmp_path / "m.ply", V, np.array([[0, 1, 2], [2, 3, 4]]), {"rings": r})
    assert load_rings(tmp_path / "m.ply", 5).tolist() == r.tolist()


@pytest.mark.parametrize(
    "name, content, message",
    [
        ("r.txt", "1\n2\n", "r.txt: 2 rigidity values for a mesh of 5 vertices"),
        ("r.txt", "1\n2\n0\n1\n1\n", "vertex 2 has r = 0"),
        ("r.txt", "1\n2\n2.5\n1\n1\n", "rigidity value '2.5' is not an integer"),
        ("r.npy", np.array([1.0, 2.0, 2.5, 1.0, 1.0]), "value 2.5 at vertex 2 is not an integer"),
        ("r.npy", np.ones((5, 1), dtype=int), "must be 1-D"),
        ("r.npy", np.ones(6, dtype=int), "6 rigidity values for a mesh of 5 vertices"),
        ("r.npy", b"garbage", "not a readable .npy"),
    ],
)
def test_bad_rings(tmp_path, name, content, message):
    p = tmp_path / name
    if isinstance(content, str):
        p.write_text(content)
    elif isinstance(content, bytes):
        p.write_bytes(content)
    else:
        np.save(p, content)
    with pytest.raises(InputError, match=message.replace(".", r"\.")) as err:
        load_rings(p, 5)
    assert str(err.value).startswith(str(p))


def test_ply_without_rings_property(tmp_path):
    save_mesh(tmp_path / "m.ply", np.eye(3), np.array([[0, 1, 2]]), {"energy": np.ones(3)})
    with pytest.raises(InputError, match=r"no vertex property 'rings' \(found: energy, x, y, z\)"):
        load_rings(tmp_path / "m.ply", 3)
    with pytest.raises(InputError, match="file not found"):
        load_rings(tmp_path / "missing.txt", 3)


def test_save_rings_round_trip(tmp_path):
    r = np.array([3, 1, 4, 1, 5])
    for name in ("r.txt", "r.npy"):
        save_rings(tmp_path / name, r)
        assert load_rings(tmp_path / name, 5).tolist() == r.tolist()
    with pytest.raises(InputError, match="needs the mesh"):
        save_rings(tmp_path / "r.ply", r)
    with pytest.raises(InputError, match=r"r must be 1\.\.100"):
        save_rings(tmp_path / "bad.txt", np.array([0, 1]))


def test_handles_json_file_end_to_end(tmp_path, grid):
    p = tmp_path / "h.json"
    p.write_text(json.dumps([{"name": "tip", "indices": [7], "translate": [0, 0, -1]}]))
    hs = load_handles(p, grid)
    assert hs.source == str(p)
    np.testing.assert_array_equal(hs.targets, [grid[7] + [0, 0, -1]])


def test_readme_example_is_valid():
    """The handle JSON example of docs/handles.md (the schema's page) parses on the bar."""
    import re
    from pathlib import Path

    from arapkit.mesh.shapes import bar

    page = Path(__file__).resolve().parents[1] / "docs" / "handles.md"
    text = page.read_text()
    block = re.search(r"<!-- same-as: examples/bar-bend.json -->\n```json\n(.*?)```", text,
                      re.S).group(1)
    V = bar().vertices
    hs = parse_handles(json.loads(block), V, "docs/handles.md")
    names = [g.name for g in hs.groups]
    assert names == ["base", "tip"]  # examples/bar-bend.json: no groups that fight
    tip = hs.groups[1]
    # -90 degrees about +y through (7,0,0) sends (7, y, z) to (7 - z, y, 0), then translate
    np.testing.assert_allclose(
        tip.targets,
        np.c_[5 - V[tip.indices, 2], V[tip.indices, 1], np.full(len(tip.indices), 2)],
        atol=1e-12,
    )
