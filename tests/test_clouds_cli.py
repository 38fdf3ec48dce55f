"""Point clouds through the command line and batch jobs: ``arapkit deform`` keeps the points'
attributes, ``--figure`` draws points, ``compare`` runs the methods that apply, and what
does not apply is refused in one line with exit 2.

Oracles: the library's own solve of the same cloud (Deformer), the input file's properties
read back, the rotations of the solve applied to the normals by hand.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from arapkit import Deformer, load_handles, load_points
from arapkit.cli import main
from arapkit.io import read_ply

ROOT = Path(__file__).resolve().parents[1]
CLOUD = ROOT / "examples" / "cactus-points.ply"
HANDLES = ROOT / "examples" / "cactus.json"


def _deform(capsys, *argv) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(["deform", *map(str, argv)])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_deform_keeps_the_points_attributes_and_is_the_librarys_solve(tmp_path, capsys):
    out, rep = tmp_path / "out.ply", tmp_path / "rep.json"
    code, stdout, err = _deform(capsys, CLOUD, "--handles", HANDLES, "-o", out, "--report",
                                rep, "-q")
    assert code == 0, err
    assert "graph: kNN, k = 10" in stdout and "(a point cloud)" in stdout
    cloud = load_points(CLOUD)
    hs = load_handles(HANDLES, cloud.points)
    want = Deformer(cloud, hs.indices).solve(hs.targets)
    src = read_ply(CLOUD.read_bytes(), str(CLOUD)).elements["vertex"].data
    got = read_ply(out.read_bytes(), str(out)).elements["vertex"].data
    V = np.stack([got["x"], got["y"], got["z"]], axis=1)
    assert np.abs(V - want.vertices).max() < 1e-12
    # every property of the input, with its type; normals turned by the solve's rotations
    for name in ("red", "green", "blue", "part"):
        assert got[name].dtype == src[name].dtype and np.array_equal(got[name], src[name])
    N = np.stack([got[c] for c in ("nx", "ny", "nz")], axis=1)
    assert got["nx"].dtype == np.float32
    assert np.abs(N - np.einsum("nij,nj->ni", want.rotations, cloud.normals)).max() < 1e-6
    assert np.allclose(got["energy"], want.vertex_energy) and (got["rings"] == 1).all()
    report = json.loads(rep.read_text())
    assert report["input"]["graph"] == "kNN, k = 10" and report["input"]["n_faces"] == 0
    assert report["parameters"]["weights"] == "gaussian"
    assert report["result"]["max_handle_error"] < 1e-12


def test_deform_takes_the_graph_and_weight_options(tmp_path, capsys):
    out = tmp_path / "o.xyzn"
    code, stdout, err = _deform(capsys, CLOUD, "--handles", HANDLES, "-o", out, "-k", "6",
                                "--weights", "uniform", "--rings", "2", "-q")
    assert code == 0, err
    cloud = load_points(CLOUD, neighbours=6)
    hs = load_handles(HANDLES, cloud.points)
    want = Deformer(cloud, hs.indices, rings=2, weights="uniform").solve(hs.targets)
    assert np.abs(load_points(out).points - want.vertices).max() < 1e-12
    code, _, err = _deform(capsys, CLOUD, "--handles", HANDLES, "-o", tmp_path / "r.ply",
                           "--radius", "0.6", "-q")
    assert code == 0, err


def test_figures_draw_points(tmp_path, capsys):
    fig, dry = tmp_path / "f.png", tmp_path / "d.png"
    code, _, err = _deform(capsys, CLOUD, "--handles", HANDLES, "-o", tmp_path / "o.ply",
                           "--figure", fig, "-q")
    assert code == 0, err
    code, stdout, err = _deform(capsys, CLOUD, "--handles", HANDLES, "--dry-run", "--figure",
                                dry)
    assert code == 0, err and stdout.startswith("point cloud: ")
    from matplotlib.image import imread

    for path in (fig, dry):
        img = imread(path)
        assert img.shape[0] > 200 and img[..., :3].std() > 0.05  # something was drawn


@pytest.mark.parametrize("extra, message", [
    (["--energy", "sr-arap"], "--energy sr-arap needs a triangle mesh"),
    (["--energy", "spokes-and-rims"], "--energy spokes-and-rims needs a triangle mesh"),
    (["--weights", "cotan-clamped"], "weights 'cotan-clamped' need triangles"),
    (["--init", "laplacian"], "--init laplacian (Laplacian editing) needs"),
    (["--weld"], "weld merges a mesh's split vertices"),
    (["-o", "{tmp}/o.stl"], "unsupported point cloud format '.stl'"),
    (["-k", "0"], "must be at least 1"),
])
def test_what_does_not_apply_to_a_cloud_exits_2_in_one_line(tmp_path, capsys, extra, message):
    extra = [e.format(tmp=tmp_path) for e in extra]
    out = [] if "-o" in extra else ["-o", str(tmp_path / "o.ply")]
    code, _, err = _deform(capsys, CLOUD, "--handles", HANDLES, *out, *extra, "-q")
    assert code == 2 and len(err.strip().splitlines()) == 1 and message in err, err
    assert not any(p.suffix in (".ply", ".stl") for p in tmp_path.iterdir())


def test_graph_options_on_a_mesh_are_refused(tmp_path, capsys):
    code, _, err = _deform(capsys, ROOT / "examples" / "cactus.off", "--handles", HANDLES,
                           "-o", tmp_path / "o.ply", "-k", "8", "-q")
    assert code == 2 and "sets a point cloud's graph; this file is a triangle mesh" in err


def test_compare_runs_the_methods_that_apply(tmp_path, capsys):
    capsys.readouterr()
    code = main(["compare", str(CLOUD), "--handles", str(HANDLES), "-o", str(tmp_path / "c"),
                 "--rings", "3"])
    out = capsys.readouterr()
    assert code == 0, out.err
    # the methods compare runs that are defined on triangles, named from the registry
    from arapkit.methods.registry import methods

    left_out = [m.name for m in methods("compare") if not m.applies_to(False)]
    assert "sr-arap" in left_out
    assert f"{', '.join(left_out)} need(s) a triangle mesh and did not run" in out.err
    rows = (tmp_path / "c" / "compare.csv").read_text().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == ["ARAP", "embedded", "r-ring r=3"]
    assert sorted(p.name for p in (tmp_path / "c").iterdir()) == [
        "arap.ply", "compare.csv", "compare.png", "embedded.ply", "r_ring_r_3.ply"]
    cloud = load_points(CLOUD)
    hs = load_handles(HANDLES, cloud.points)
    want = Deformer(cloud, hs.indices, rings=3).solve(hs.targets).vertices
    got = load_points(tmp_path / "c" / "r_ring_r_3.ply")
    assert np.abs(got.points - want).max() < 1e-12 and got.normals is not None
    code = main(["compare", str(CLOUD), "--handles", str(HANDLES), "-o", str(tmp_path / "d"),
                 "--volumetric"])
    err = capsys.readouterr().err
    assert code == 2 and "volumetric ARAP fills a closed triangle surface" in err


def test_batch_jobs_deform_clouds_as_deform_does(tmp_path, capsys):
    pytest.importorskip("distributed", reason="batch jobs need arapkit[batch]")
    from arapkit.workflows.batch import normalise_job, report_path, run_job

    shutil.copy(CLOUD, tmp_path / "c.ply")
    job = normalise_job({"mesh": "c.ply", "handles": str(HANDLES), "output": "o.ply",
                         "neighbours": 8, "rings": 2}, tmp_path)
    row = run_job(job, tmp_path / "out", resume=False)
    assert row["status"] == "ok", row["error"]
    # the report's command reproduces the job through deform, byte for byte
    command = json.loads(report_path(tmp_path / "out" / "o.ply").read_text())["command"]
    assert "--neighbours=8" in command
    again = tmp_path / "again.ply"
    argv = command[1:command.index("-o")] + ["-o", str(again), "-q", "--force"]
    assert main(argv) == 0, capsys.readouterr().err
    assert (tmp_path / "out" / "o.ply").read_bytes() == again.read_bytes()
    bad = normalise_job({"mesh": "c.ply", "handles": str(HANDLES), "output": "o.ply",
                         "energy": "sr-arap"}, tmp_path)
    row = run_job(bad, tmp_path / "out2", resume=False)
    assert row["status"] == "failed" and "needs a triangle mesh" in row["error"]
    assert "\n" not in row["error"]
    from arapkit import InputError

    with pytest.raises(InputError, match="give 'neighbours' or 'radius', not both"):
        normalise_job({"mesh": "c.ply", "handles": "h.json", "output": "o.ply",
                       "neighbours": 8, "radius": 0.5}, tmp_path)
    with pytest.raises(InputError, match="job: o.stl: unsupported point cloud format '.stl'"):
        normalise_job({"mesh": "c.xyz", "handles": "h.json", "output": "o.stl"}, tmp_path)


def test_info_describes_a_cloud(capsys):
    capsys.readouterr()
    assert main(["info", str(CLOUD), "--json"]) == 0
    facts = json.loads(capsys.readouterr().out)
    assert facts["points"] == 2000 and facts["graph"] == "kNN, k = 10"
    assert facts["normals"] and facts["colours"] and "part" in facts["properties"]
    assert facts["edges"] == len(load_points(CLOUD).edges)


def test_sel_def_handles_and_a_rings_file_on_a_cloud(tmp_path, capsys):
    """A Botsch-Sorkine ``.sel`` / ``.def`` pair and a per-point rigidity file work on a
    cloud as on a mesh: the CLI's result is the library's solve with the same handles, r and
    transform applied by hand."""
    from arapkit.io import save_def, save_rings, save_sel

    cloud = load_points(CLOUD)
    P = cloud.points
    fixed = np.flatnonzero(P[:, 1] < 1.5)  # the pot
    top = np.flatnonzero(P[:, 1] > 11.5)  # the trunk's top
    save_sel(tmp_path / "c.sel", len(P), fixed, top)
    M = np.eye(4)
    M[:3, 3] = [1.5, 0.0, 0.0]
    save_def(tmp_path / "c.def", M)
    rings = np.where(P[:, 1] > 6.0, 3, 1)
    save_rings(tmp_path / "r.txt", rings)
    out = tmp_path / "o.ply"
    code, _, err = _deform(capsys, CLOUD, "--handles", tmp_path / "c.sel", "--rings-file",
                           tmp_path / "r.txt", "-o", out, "-q")
    assert code == 0, err
    h = np.concatenate([fixed, top])
    order = np.argsort(h)
    T = np.concatenate([P[fixed], P[top] + [1.5, 0.0, 0.0]])
    want = Deformer(cloud, h[order], rings=rings).solve(T[order]).vertices
    got = read_ply(out.read_bytes(), str(out)).elements["vertex"].data
    V = np.stack([got["x"], got["y"], got["z"]], axis=1)
    assert np.abs(V - want).max() < 1e-9 * cloud.bounding_box_diagonal
    assert (got["rings"] == rings).all()
    assert np.abs(V[top] - P[top] - [1.5, 0, 0]).max() < 1e-9  # the handles moved


def test_info_reports_on_the_graph_asked_for(tmp_path, capsys):
    """``info --neighbours/--radius`` describes the graph ``deform`` would solve on: two
    clusters apart are two parts at k = 2 (each point's two nearest are in its own
    cluster) and one part with a radius that spans the gap (counted by brute force)."""
    P = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5], [6, 5, 5], [5, 6, 5.0]])
    path = tmp_path / "two.xyz"
    np.savetxt(path, P)
    for argv, graph, parts, edges in (
            (["-k", "2"], "kNN, k = 2", 2, 6),
            (["--radius", "9"], "radius 9", 1,
             int((np.linalg.norm(P[:, None] - P[None], axis=2) < 9).sum() - 6) // 2)):
        capsys.readouterr()
        assert main(["info", str(path), "--json", *argv]) == 0
        facts = json.loads(capsys.readouterr().out)
        assert (facts["graph"], facts["components"], facts["edges"]) == (graph, parts, edges)
    capsys.readouterr()
    assert main(["info", str(ROOT / "examples" / "cactus.off"), "--neighbours", "4"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "this file is a triangle mesh" in err


def test_a_clouds_dry_runs_count_points_and_a_meshs_vertices(tmp_path, capsys):
    """What a dry run prints counts a cloud's points as points (the counts themselves
    checked against the handle file read by the library), a mesh's as vertices."""
    groups = ROOT / "examples" / "cactus-groups.json"
    hs = load_handles(HANDLES, load_points(CLOUD))
    code, out, err = _deform(capsys, CLOUD, "-H", HANDLES, "--groups", groups, "-o",
                             tmp_path / "o.ply", "--dry-run")
    assert code == 0, err
    assert "(2000 points, box" in out and f"handles: {len(hs.indices)} points in 3" in out
    assert f"pot: {len(hs.groups[0].indices)} points, fixed" in out
    assert "rigid part (" in out and " vertices" not in out
    capsys.readouterr()
    assert main(["compare", str(CLOUD), "-H", str(HANDLES), "-o", str(tmp_path / "c"),
                 "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("point cloud: ") and " vertices" not in out and " points" in out
    mesh = ROOT / "examples" / "cactus.off"
    code, out, err = _deform(capsys, mesh, "-H", HANDLES, "-o", tmp_path / "m.ply",
                             "--dry-run")
    assert code == 0 and "(2162 vertices, box" in out and " points" not in out


def test_the_editor_counts_a_clouds_selection_in_points():
    from arapkit.editor.panels import next_step, selected_text
    from arapkit.editor.state import EditorState

    st = EditorState(load_points(CLOUD))
    st.selection = np.arange(5)
    assert selected_text(5, st.mesh) == "Selected: **5** points"
    assert next_step(st).startswith("**Next:** 5 points selected:")
