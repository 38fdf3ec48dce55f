"""Atomic writes, mesh export with vertex properties, JSON reports.

Covers arapkit.io.atomic, .writers and .readers.
"""

from __future__ import annotations

import gzip
import io
import json
import os

import numpy as np
import pytest
import trimesh

from arapkit.errors import InputError
from arapkit.io import (
    atomic_open,
    atomic_write,
    check_output_path,
    mesh_format,
    read_ply_vertex_properties,
    save_mesh,
    to_jsonable,
    write_json,
)


@pytest.fixture()
def tetra():
    rng = np.random.default_rng(7)
    # irrational-looking coordinates: any float32 or short-decimal rounding would show
    V = rng.random((4, 3)) * np.pi
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return V, F


def _leftovers(folder):
    return [p.name for p in folder.iterdir() if p.name.endswith(".tmp")]


def test_atomic_write_replaces_and_cleans_up(tmp_path):
    p = tmp_path / "a.txt"
    p.write_text("old")
    atomic_write(p, "new")
    assert p.read_text() == "new" and _leftovers(tmp_path) == []


def test_failed_write_leaves_old_file(tmp_path):
    p = tmp_path / "a.txt"
    p.write_text("old")
    with pytest.raises(RuntimeError), atomic_open(p, "w") as f:
        f.write("half")
        raise RuntimeError("crash while writing")
    assert p.read_text() == "old" and _leftovers(tmp_path) == []


def test_atomic_write_needs_existing_folder(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        atomic_write(tmp_path / "nope" / "a.txt", "x")


def test_written_file_gets_umask_permissions(tmp_path):
    atomic_write(tmp_path / "a.txt", "x")
    umask = os.umask(0)
    os.umask(umask)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o666 & ~umask


def test_ply_round_trip_is_exact_and_carries_properties(tmp_path, tetra):
    V, F = tetra
    energy = np.array([0.1, 1e-30, 2.5, np.pi])
    rings = np.array([1, 2, 6, 10], dtype=np.int64)
    save_mesh(tmp_path / "t.ply", V, F, {"energy": energy, "rings": rings})
    # an independent reader (trimesh) sees the same geometry, bit for bit
    tm = trimesh.load(tmp_path / "t.ply", process=False)
    np.testing.assert_array_equal(np.asarray(tm.vertices), V)
    np.testing.assert_array_equal(np.asarray(tm.faces), F)
    props = read_ply_vertex_properties(tmp_path / "t.ply")
    np.testing.assert_array_equal(props["energy"], energy)
    assert props["rings"].tolist() == rings.tolist() and props["rings"].dtype == np.int32
    header = (tmp_path / "t.ply").read_bytes().split(b"end_header")[0].decode()
    assert "property double energy" in header and "property int rings" in header


@pytest.mark.parametrize("ext", ["off", "obj"])
def test_text_formats_round_trip_doubles(tmp_path, tetra, ext):
    V, F = tetra
    save_mesh(tmp_path / f"t.{ext}", V, F, {"energy": np.zeros(4)})
    tm = trimesh.load(tmp_path / f"t.{ext}", process=False)
    np.testing.assert_array_equal(np.asarray(tm.vertices), V)
    np.testing.assert_array_equal(np.asarray(tm.faces), F)


@pytest.mark.parametrize("ext", ["stl", "glb"])
def test_binary_formats_are_readable(tmp_path, tetra, ext):
    V, F = tetra
    save_mesh(tmp_path / f"t.{ext}", V, F)
    tm = trimesh.load(tmp_path / f"t.{ext}", force="mesh")
    assert len(tm.faces) == 4
    # both formats store float32
    np.testing.assert_allclose(np.sort(tm.vertices, axis=0), np.sort(V, axis=0), rtol=1e-6)


def test_gz_output(tmp_path, tetra):
    V, F = tetra
    save_mesh(tmp_path / "t.off.gz", V, F)
    raw = gzip.decompress((tmp_path / "t.off.gz").read_bytes())
    tm = trimesh.load(io.BytesIO(raw), file_type="off", process=False)
    np.testing.assert_array_equal(np.asarray(tm.vertices), V)
    save_mesh(tmp_path / "t.ply.gz", V, F, {"rings": np.arange(1, 5)})
    assert read_ply_vertex_properties(tmp_path / "t.ply.gz")["rings"].tolist() == [1, 2, 3, 4]


def test_mesh_format_rejects_unknown_extensions():
    assert mesh_format("a/b.PLY") == ("ply", False)
    with pytest.raises(InputError, match=r"out.xyz2: unsupported mesh format '\.xyz2'"):
        mesh_format("out.xyz2")
    with pytest.raises(InputError, match="no extension"):
        mesh_format("out")


def test_bad_vertex_property_is_a_bug_not_input(tmp_path, tetra):
    V, F = tetra
    with pytest.raises(ValueError, match="shape"):
        save_mesh(tmp_path / "t.ply", V, F, {"energy": np.zeros(3)})
    assert not (tmp_path / "t.ply").exists()


def test_read_ply_errors(tmp_path):
    (tmp_path / "bad.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\n")
    with pytest.raises(InputError, match="bad.ply"):
        read_ply_vertex_properties(tmp_path / "bad.ply")
    with pytest.raises(InputError, match="file not found"):
        read_ply_vertex_properties(tmp_path / "missing.ply")


def test_check_output_path(tmp_path):
    inp = tmp_path / "in.off"
    inp.write_text("OFF\n")
    assert check_output_path(tmp_path / "out.ply", [inp]) == tmp_path / "out.ply"
    with pytest.raises(InputError, match=r"out.ply: output folder '.*missing' does not exist"):
        check_output_path(tmp_path / "missing" / "out.ply")
    with pytest.raises(InputError, match="is a folder"):
        check_output_path(tmp_path, [inp])
    with pytest.raises(InputError, match="would overwrite an input file"):
        check_output_path(tmp_path / "." / "in.off", [inp, None])
    assert check_output_path(inp, [inp], force=True) == inp


def test_json_is_strict_and_numpy_safe(tmp_path):
    data = {
        "n": np.int64(3),
        "x": np.float32(0.5),
        "bad": float("inf"),
        "flag": np.bool_(True),
        "arr": np.arange(3),
        "nested": [{"p": tmp_path}],
    }
    write_json(tmp_path / "r.json", data)
    back = json.loads((tmp_path / "r.json").read_text())
    assert back == {
        "n": 3,
        "x": 0.5,
        "bad": None,
        "flag": True,
        "arr": [0, 1, 2],
        "nested": [{"p": str(tmp_path)}],
    }
    assert to_jsonable((1, np.nan)) == [1, None]
