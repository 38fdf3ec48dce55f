"""The ``arapkit`` command line, run as a subprocess (deform, demo, info, errors).

Every deformation check compares against numbers computed independently here: handle
vertices must equal their rest position moved by the transform written in the test, fixed
vertices must not move, and results must match the Python API.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from arapkit.io import read_ply_vertex_properties, save_def, save_mesh, save_rings, save_sel
from arapkit.mesh.shapes import bar, bar_bend, bar_two_materials

ROOT = Path(__file__).resolve().parents[1]
MESHES = ROOT.parent / "shared" / "data" / "meshes"
needs_data = pytest.mark.skipif(
    not MESHES.is_dir(), reason=f"real meshes not found at {MESHES} (../shared/data/meshes)"
)


def arapkit(*args, cwd=None) -> subprocess.CompletedProcess:
    """Run ``python -m arapkit.cli ARGS`` and capture its output."""
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    return subprocess.run(
        [sys.executable, "-m", "arapkit.cli", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=600,
    )


def error_line(proc: subprocess.CompletedProcess) -> str:
    """The one-line error message; asserts there is exactly one and no traceback."""
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("arapkit: error: ")]
    assert len(lines) == 1, proc.stderr
    return lines[0]


def read_vertices(path: Path) -> np.ndarray:
    p = read_ply_vertex_properties(path)
    return np.stack([p["x"], p["y"], p["z"]], axis=1)


def not_blank(path: Path) -> bool:
    img = mpimg.imread(path)[..., :3]
    return img.shape[0] > 100 and img.shape[1] > 100 and float(img.std()) > 0.05


@pytest.fixture(scope="module")
def bar_file(tmp_path_factory) -> tuple[Path, np.ndarray, np.ndarray]:
    """The built-in 1,154-vertex bar written to an OFF file."""
    mesh = bar()
    path = tmp_path_factory.mktemp("bar") / "bar.off"
    save_mesh(path, mesh.vertices, mesh.faces)
    return path, np.array(mesh.vertices), np.array(mesh.faces)


def caps(V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.flatnonzero(V[:, 0] < 1e-9), np.flatnonzero(V[:, 0] > 7 - 1e-9)


# --------------------------------------------------------------------------- help, version

def test_python_dash_m_arapkit_is_the_same_door(tmp_path, bar_file):
    """``python -m arapkit`` runs the command line: same version, same deform output, same
    one-line errors as the ``arapkit`` script (whose module is ``arapkit.cli``)."""
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}

    def dash_m(*args):
        return subprocess.run([sys.executable, "-m", "arapkit", *map(str, args)],
                              capture_output=True, text=True, env=env, timeout=600)

    assert dash_m("--version").stdout == arapkit("--version").stdout
    mesh_path, V, _ = bar_file
    base, tip = caps(V)
    spec = [{"indices": base.tolist()}, {"indices": tip.tolist(), "translate": [0, 0, 0.5]}]
    (tmp_path / "h.json").write_text(json.dumps(spec))
    outs = {}
    for name, run in (("m", dash_m), ("cli", arapkit)):
        out = tmp_path / f"{name}.ply"
        proc = run("deform", mesh_path, "--handles", tmp_path / "h.json", "-o", out, "-q")
        assert proc.returncode == 0, proc.stderr
        outs[name] = read_vertices(out)
    np.testing.assert_array_equal(outs["m"], outs["cli"])
    bad = dash_m("info", tmp_path / "missing.off")
    assert bad.returncode == 2
    assert error_line(bad) == error_line(arapkit("info", tmp_path / "missing.off"))



def test_version_and_help_with_examples():
    v = arapkit("--version")
    assert v.returncode == 0 and v.stdout.strip() == "arapkit 0.1.0"
    top = arapkit("--help")
    assert top.returncode == 0
    for cmd in ("deform", "demo", "info"):
        assert cmd in top.stdout
        h = arapkit(cmd, "--help")
        assert h.returncode == 0 and "examples:" in h.stdout and f"arapkit {cmd}" in h.stdout
    none = arapkit()
    assert none.returncode == 2 and "usage" in none.stderr


def test_version_has_one_source():
    """``arapkit.__version__``, ``--version`` and reports all read the package metadata."""
    from importlib.metadata import version

    import arapkit as package

    assert package.__version__ == version("arapkit")
    assert arapkit("--version").stdout.strip() == f"arapkit {package.__version__}"


# --------------------------------------------------------------------------- deform


def test_deform_json_with_every_selection_kind(tmp_path, bar_file):
    mesh_path, V, _ = bar_file
    base, tip = caps(V)
    sphere_c, sphere_r = np.array([3.5, 0.2, 0.2]), 0.15
    near_p, k = np.array([5.0, -0.2, -0.2]), 3
    in_sphere = [i for i, v in enumerate(V) if np.sum((v - sphere_c) ** 2) <= sphere_r**2]
    d = np.linalg.norm(V - near_p, axis=1)
    nearest = sorted(sorted(range(len(V)), key=lambda i: (d[i], i))[:k])
    handles = [
        {"name": "base", "box": {"min": [-1, -1, -1], "max": [0.01, 1, 1]}, "fixed": True},
        {
            "name": "tip",
            "indices": tip.tolist(),
            "rotate": {"axis": [0, 1, 0], "degrees": 90, "center": [7, 0, 0]},
            "translate": [-1, 0, 1],
        },
        {
            "name": "mid",
            "sphere": {"center": sphere_c.tolist(), "radius": sphere_r},
            "translate": [0, 0.5, 0],
        },
        {
            "name": "near",
            "nearest": {"point": near_p.tolist(), "k": k},
            "targets": (V[nearest] + [0, -0.25, 0]).tolist(),
        },
    ]
    (tmp_path / "h.json").write_text(json.dumps(handles))
    out, rep, fig = tmp_path / "out.ply", tmp_path / "report.json", tmp_path / "fig.png"
    proc = arapkit(
        "deform",
        mesh_path,
        "--handles",
        tmp_path / "h.json",
        "--rings",
        2,
        "--max-iter",
        300,
        "-o",
        out,
        "--report",
        rep,
        "--figure",
        fig,
    )
    assert proc.returncode == 0, proc.stderr
    P = read_vertices(out)

    # fixed: untouched, bit for bit
    np.testing.assert_array_equal(P[base], V[base])
    # rotating 90 degrees about +y through (7,0,0) sends (7, y, z) to (7 + z, y, 0)
    want_tip = np.stack([7 + V[tip, 2] - 1, V[tip, 1], np.ones(len(tip))], axis=1)
    np.testing.assert_allclose(P[tip], want_tip, atol=1e-12)
    # the corner vertex, its 4 edge neighbours at 0.1 and 4 diagonal ones at 0.141
    assert len(in_sphere) == 9
    np.testing.assert_array_equal(P[in_sphere], V[in_sphere] + [0, 0.5, 0])
    np.testing.assert_array_equal(P[nearest], V[nearest] + [0, -0.25, 0])
    # and the free part really deformed
    free = np.setdiff1d(np.arange(len(V)), np.r_[base, tip, in_sphere, nearest])
    assert np.linalg.norm(P[free] - V[free], axis=1).max() > 0.5

    report = json.loads(rep.read_text())
    res = report["result"]
    hist = np.array(res["energy_history"])
    assert res["iterations"] == len(hist) and 1 < len(hist) <= 300
    assert res["energy"] == pytest.approx(hist[-1])
    assert np.all(np.diff(hist) <= 1e-9 * hist[:-1])  # global/local never increases energy
    if res["converged"]:
        assert (hist[-2] - hist[-1]) / hist[-2] < 1e-3
    assert report["parameters"] == {
        "rings": 2,
        "weights": "cotan-clamped",  # the default
        "tol": 1e-3,
        "max_iter": 300,
        "init": "identity",
        "accelerate": False,
    }
    assert [g["name"] for g in report["handles"]["groups"]] == ["base", "tip", "mid", "near"]
    assert report["handles"]["count"] == len(base) + len(tip) + 9 + 3
    assert res["max_handle_error"] < 1e-12
    for key in (
        "neighbourhood_ms",
        "factorisation_ms",
        "global_ms_per_iter",
        "local_ms_per_iter",
        "total_s",
    ):
        assert report["timings"][key] >= 0
    # stdout: results only, matching the report
    summary = dict(line.split(": ", 1) for line in proc.stdout.splitlines())
    assert int(summary["iterations"]) == res["iterations"] and summary["output"] == str(out)
    props = read_ply_vertex_properties(out)
    assert props["rings"].tolist() == [2] * len(V)
    assert props["energy"].shape == (len(V),) and np.all(props["energy"] >= -1e-12)
    assert not_blank(fig)


def test_sel_def_pair_matches_equivalent_json(tmp_path, bar_file):
    mesh_path, V, _ = bar_file
    base, tip = caps(V)
    save_sel(tmp_path / "bar.sel", len(V), base, tip)
    M = np.array([[0.0, 0, -1, 7], [0, 1, 0, 0], [1, 0, 0, -7 + 2], [0, 0, 0, 1]])
    save_def(tmp_path / "bend.def", M)
    a = arapkit(
        "deform",
        mesh_path,
        "--handles",
        tmp_path / "bar.sel",
        "--transform",
        tmp_path / "bend.def",
        "-r",
        4,
        "-o",
        tmp_path / "sel.ply",
        "--quiet",
    )
    assert a.returncode == 0, a.stderr
    Pa = read_vertices(tmp_path / "sel.ply")
    want = (np.c_[V[tip], np.ones(len(tip))] @ M.T)[:, :3]
    np.testing.assert_allclose(Pa[tip], want, atol=1e-12)
    np.testing.assert_array_equal(Pa[base], V[base])  # status 0 stays where it is

    spec = [
        {"name": "fixed", "indices": base.tolist()},
        {"name": "handle", "indices": tip.tolist(), "targets": want.tolist()},
    ]
    (tmp_path / "same.json").write_text(json.dumps(spec))
    b = arapkit(
        "deform",
        mesh_path,
        "--handles",
        tmp_path / "same.json",
        "-r",
        4,
        "-o",
        tmp_path / "json.off",
        "--report",
        "-",
        "--quiet",
    )
    assert b.returncode == 0, b.stderr
    report = json.loads(b.stdout)  # stdout holds nothing but the JSON report
    assert report["outputs"]["mesh"] == str(tmp_path / "json.off")
    Pb = np.loadtxt(tmp_path / "json.off", skiprows=2, max_rows=len(V))
    np.testing.assert_allclose(Pb, Pa, atol=1e-9)


def test_rigidity_file_matches_python_api(tmp_path, bar_file):
    from arapkit import Deformer, Mesh

    mesh_path, V, F = bar_file
    mesh = Mesh(V, F)
    rings = bar_two_materials(mesh, soft=2, hard=6)
    save_rings(tmp_path / "r.txt", rings)
    handles, targets = bar_bend(mesh, 90)
    spec = [{"indices": handles.tolist(), "targets": targets.tolist()}]
    (tmp_path / "h.json").write_text(json.dumps(spec))
    proc = arapkit(
        "deform",
        mesh_path,
        "--handles",
        tmp_path / "h.json",
        "--rings-file",
        tmp_path / "r.txt",
        "-o",
        tmp_path / "out.ply",
        "--report",
        tmp_path / "rep.json",
        "-q",
    )
    assert proc.returncode == 0, proc.stderr
    ref = Deformer(mesh, handles, rings=rings).solve(targets)
    props = read_ply_vertex_properties(tmp_path / "out.ply")
    np.testing.assert_allclose(read_vertices(tmp_path / "out.ply"), ref.vertices, atol=1e-9)
    np.testing.assert_allclose(props["energy"], ref.vertex_energy, rtol=1e-6, atol=1e-12)
    assert props["rings"].tolist() == rings.tolist()
    rep = json.loads((tmp_path / "rep.json").read_text())
    assert rep["parameters"]["rings"]["counts"] == {
        "2": int((rings == 2).sum()),
        "6": int((rings == 6).sum()),
    }
    assert rep["result"]["iterations"] == ref.iterations


def test_force_allows_overwriting_the_input(tmp_path, bar_file):
    mesh_path, V, F = bar_file
    target = tmp_path / "bar.off"
    target.write_bytes(mesh_path.read_bytes())
    base, tip = caps(V)
    spec = [{"indices": base.tolist()}, {"indices": tip.tolist(), "translate": [0, 0, 0.5]}]
    (tmp_path / "h.json").write_text(json.dumps(spec))
    before = target.read_bytes()
    refused = arapkit("deform", target, "--handles", tmp_path / "h.json", "-o", target, "-q")
    assert refused.returncode == 2 and "would overwrite an input file" in error_line(refused)
    assert target.read_bytes() == before
    forced = arapkit(
        "deform",
        target,
        "--handles",
        tmp_path / "h.json",
        "-o",
        target,
        "-q",
        "--force",
        "--max-iter",
        5,
    )
    assert forced.returncode == 0, forced.stderr
    P = np.loadtxt(target, skiprows=2, max_rows=len(V))
    np.testing.assert_array_equal(P[tip], V[tip] + [0, 0, 0.5])


# --------------------------------------------------------------------------- bad input


def _bad_inputs(tmp: Path, mesh_path: Path, V: np.ndarray):
    """(name, argv, file named in the message, message fragment) for each bad input."""
    good = tmp / "good.json"
    good.write_text(json.dumps([{"indices": [0, 1]}, {"indices": [1150], "translate": [0, 0, 1]}]))
    text = mesh_path.read_text()
    (tmp / "truncated.off").write_text(text[: len(text) // 3])
    (tmp / "range.json").write_text(json.dumps([{"name": "tip", "indices": [0, 5000]}]))
    (tmp / "unknown.json").write_text(json.dumps([{"name": "tip", "indices": [0], "move": 1}]))
    (tmp / "overlap.json").write_text(
        json.dumps(
            [
                {"name": "a", "indices": [0, 1]},
                {"name": "b", "sphere": {"center": V[1].tolist(), "radius": 1e-6}},
            ]
        )
    )
    (tmp / "short.txt").write_text("2\n" * (len(V) - 1))
    (tmp / "bad.def").write_text("1 0 0\n")
    save_sel(tmp / "a.sel", len(V), [0], [1153])
    out = tmp / "out.ply"
    return [
        (
            "truncated mesh",
            ["deform", tmp / "truncated.off", "--handles", good, "-o", out],
            "truncated.off",
            "truncated",
        ),
        (
            "index out of range",
            ["deform", mesh_path, "--handles", tmp / "range.json", "-o", out],
            "range.json",
            "group 1 ('tip'): vertex index 5000 out of range (mesh has 1154",
        ),
        (
            "unknown key",
            ["deform", mesh_path, "--handles", tmp / "unknown.json", "-o", out],
            "unknown.json",
            "unknown key 'move'",
        ),
        (
            "overlap",
            ["deform", mesh_path, "--handles", tmp / "overlap.json", "-o", out],
            "overlap.json",
            "group 2 ('b'): overlaps group 'a'",
        ),
        (
            "rings wrong length",
            ["deform", mesh_path, "--handles", good, "--rings-file", tmp / "short.txt", "-o", out],
            "short.txt",
            "1153 rigidity values for a mesh of 1154 vertices",
        ),
        (
            "missing output folder",
            ["deform", mesh_path, "--handles", good, "-o", tmp / "nowhere" / "out.ply"],
            "out.ply",
            "output folder",
        ),
        (
            "bad output format",
            ["deform", mesh_path, "--handles", good, "-o", tmp / "out.xyz2"],
            "out.xyz2",
            # the input's name could hold a mesh or a point cloud: both lists are given
            "unsupported output format",
        ),
        (
            "bad def",
            [
                "deform",
                mesh_path,
                "--handles",
                tmp / "a.sel",
                "--transform",
                tmp / "bad.def",
                "-o",
                out,
            ],
            "bad.def",
            "expected 16 finite numbers",
        ),
        (
            "missing mesh",
            ["deform", tmp / "nope.off", "--handles", good, "-o", out],
            "nope.off",
            "no such file",
        ),
        (
            "missing figure folder",
            [
                "deform",
                mesh_path,
                "--handles",
                good,
                "-o",
                out,
                "--figure",
                tmp / "nowhere" / "f.png",
            ],
            "f.png",
            "folder",
        ),
        ("info on truncated", ["info", tmp / "truncated.off"], "truncated.off", "truncated"),
        (
            "demo folder without parent",
            ["demo", "--out", tmp / "no" / "demo"],
            "demo",
            "parent folder",
        ),
    ]


def test_bad_inputs_exit_2_with_one_line(tmp_path, bar_file):
    mesh_path, V, _ = bar_file
    for name, argv, fname, fragment in _bad_inputs(tmp_path, mesh_path, V):
        proc = arapkit(*argv)
        assert proc.returncode == 2, (name, proc.returncode, proc.stderr)
        line = error_line(proc)
        assert fname in line and fragment in line, (name, line)
        assert proc.stdout == "", name
        assert not (tmp_path / "out.ply").exists(), name


def test_usage_errors_exit_2(bar_file):
    mesh_path, _, _ = bar_file
    proc = arapkit("deform", mesh_path, "-o", "x.ply")  # --handles missing
    assert proc.returncode == 2 and "--handles" in proc.stderr
    proc = arapkit("deform", mesh_path, "--handles", "h.json", "-o", "x.ply", "--rings", 0)
    assert proc.returncode == 2 and "must be at least 1" in proc.stderr
    proc = arapkit(
        "deform", mesh_path, "--handles", "h", "-o", "x.ply", "--rings", 2, "--rings-file", "r.txt"
    )
    assert proc.returncode == 2 and "not allowed with" in proc.stderr


# --------------------------------------------------------------------------- info


@pytest.mark.parametrize("argv, line", [
    # an option from another tool: the subcommand names it and the one it most likely meant
    (["deform", "{mesh}", "-H", "h.json", "--method", "rring"],
     "arapkit: error: arapkit deform: unrecognized arguments: --method rring; "
     "did you mean --energy? (see arapkit deform --help)"),
    (["deform", "{mesh}", "-H", "h.json", "--max-iters=5", "--iters", "4"],
     "arapkit: error: arapkit deform: unrecognized arguments: --max-iters=5 --iters 4; "
     "did you mean --max-iter for --max-iters, --max-iter for --iters? "
     "(see arapkit deform --help)"),
    (["info", "{mesh}", "--zzz"],
     "arapkit: error: arapkit info: unrecognized arguments: --zzz (see arapkit info --help)"),
    # the top level: its name opens the line once
    (["--bogus"], "arapkit: error: unrecognized arguments: --bogus (see arapkit --help)"),
])
def test_unrecognized_arguments_name_the_subcommand(bar_file, argv, line):
    mesh_path, _, _ = bar_file
    proc = arapkit(*[a.format(mesh=mesh_path) for a in argv])
    assert proc.returncode == 2 and error_line(proc) == line
    assert proc.stdout == ""


def test_info_on_builtin_bar(bar_file):
    mesh_path, V, F = bar_file
    proc = arapkit("info", mesh_path, "--json")
    assert proc.returncode == 0, proc.stderr
    facts = json.loads(proc.stdout)
    # a closed box of 70 x 4 x 4 cells: V = 2 + 4 * (70*4 + 70*4 + 4*4) / 2 ... counted directly
    assert facts["vertices"] == len(V) == 1154 and facts["faces"] == len(F) == 2304
    assert facts["edges"] == len(V) + len(F) - 2  # Euler: V - E + F = 2 for a sphere
    assert facts["components"] == 1 and facts["boundary_loops"] == 0
    assert facts["degenerate_faces_dropped"] == 0
    text = arapkit("info", mesh_path)
    assert "what arapkit deform would do:" in text.stdout and "no problems found" in text.stdout


def _independent_topology(path: Path) -> dict:
    """Components and boundary loops counted with trimesh + scipy (not arapkit)."""
    import trimesh

    t = trimesh.load(path, process=False, force="mesh")
    n = len(t.vertices)
    e = np.sort(np.asarray(t.edges), axis=1)
    adj = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    n_comp = connected_components(adj, directed=False)[0]
    uniq, counts = np.unique(e, axis=0, return_counts=True)
    b = uniq[counts == 1]
    if len(b) == 0:
        loops = 0
    else:
        verts, inv = np.unique(b.ravel(), return_inverse=True)
        inv = inv.reshape(-1, 2)
        g = sp.coo_matrix((np.ones(len(b)), (inv[:, 0], inv[:, 1])), shape=(len(verts),) * 2)
        loops = connected_components(g, directed=False)[0]
    return {
        "vertices": n,
        "faces": len(t.faces),
        "components": n_comp,
        "boundary_loops": loops,
        "nonmanifold_edges": int(np.count_nonzero(counts > 2)),
    }


@needs_data
@pytest.mark.parametrize("name", ["cylinder.off", "plane.off", "npm_snowden_lo.obj"])
def test_info_on_real_meshes(name):
    proc = arapkit("info", MESHES / name, "--json")
    assert proc.returncode == 0, proc.stderr
    facts = json.loads(proc.stdout)
    want = _independent_topology(MESHES / name)
    for key, value in want.items():
        assert facts[key] == value, (name, key)
    if name == "npm_snowden_lo.obj":  # the data README's numbers for this bad-input case
        assert (facts["vertices"], facts["nonmanifold_edges"]) == (18743, 88)
        assert any("non-manifold" in a for a in facts["advice"])
        assert any("moves rigidly with the nearest part" in a for a in facts["advice"])


@needs_data
def test_deform_real_mesh_with_figure(tmp_path):
    """Twist the open cylinder: one end fixed, the other rotated about the tube axis."""
    import trimesh

    V = np.asarray(trimesh.load(MESHES / "cylinder.off", process=False).vertices)
    lo, hi = V[:, 0].min(), V[:, 0].max()
    spec = [
        {"name": "left", "box": {"min": [lo - 1, -9, -9], "max": [lo + 0.05, 9, 9]}},
        {
            "name": "right",
            "box": {"min": [hi - 0.05, -9, -9], "max": [hi + 1, 9, 9]},
            "rotate": {"axis": [1, 0, 0], "degrees": 30, "center": [hi, 0, 0]},
        },
    ]
    (tmp_path / "twist.json").write_text(json.dumps(spec))
    proc = arapkit(
        "deform",
        MESHES / "cylinder.off",
        "--handles",
        tmp_path / "twist.json",
        "-r",
        3,
        "--max-iter",
        40,
        "-o",
        tmp_path / "twist.ply",
        "--figure",
        tmp_path / "twist.png",
        "--weights",
        "cotan-clamped",
    )
    assert proc.returncode == 0, proc.stderr
    P = read_vertices(tmp_path / "twist.ply")
    left = np.flatnonzero(V[:, 0] <= lo + 0.05)
    right = np.flatnonzero(V[:, 0] >= hi - 0.05)
    np.testing.assert_array_equal(P[left], V[left])
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    want = np.stack(
        [V[right, 0], c * V[right, 1] - s * V[right, 2], s * V[right, 1] + c * V[right, 2]], axis=1
    )
    np.testing.assert_allclose(P[right], want, atol=1e-12)
    assert not_blank(tmp_path / "twist.png")


# --------------------------------------------------------------------------- demo


def test_demo_reproduces_table_and_figures(tmp_path):
    out = tmp_path / "demo"
    proc = arapkit("demo", "--out", out, "--quiet")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    header = next(i for i, ln in enumerate(lines) if ln.split()[:1] == ["r"])
    rows = [ln.split() for ln in lines[header + 1 : header + 7]]
    assert [r[0] for r in rows] == ["1", "2", "4", "6", "10", "2/6"]
    iterations = [int(r[5]) for r in rows[:5]]
    # the paper's Table 1 / Fig. 5: larger r converges in fewer iterations
    assert all(a > b for a, b in zip(iterations, iterations[1:])), iterations
    report = json.loads((out / "demo-report.json").read_text())
    assert [row["iterations"] for row in report["table"][:5]] == iterations
    assert all(row["converged"] for row in report["table"])
    for name in report["figures"]:
        assert not_blank(out / name), name
    assert {
        "fig3_bar_bend.png",
        "fig4_energy_curves.png",
        "fig5_iterations.png",
        "fig8_two_materials.png",
    } <= set(report["figures"])
    # the two-material mesh carries its rigidity map: the soft middle third is r = 2
    rest = read_vertices(out / "bar_rest.ply")
    x = rest[:, 0]
    rings = read_ply_vertex_properties(out / "bar_two_materials.ply")["rings"]
    soft = (x > 7 / 3) & (x < 14 / 3)
    assert np.all(rings[soft] == 2) and np.all(rings[~soft] == 6)
    # bent 180 degrees: the x = 0 cap stays, the x = 7 cap lands back on the plane x = 0
    P = read_vertices(out / "bar_r6.ply")
    np.testing.assert_array_equal(P[x < 1e-9], rest[x < 1e-9])
    assert np.abs(P[x > 7 - 1e-9, 0]).max() < 1e-9


# --------------------------------------------------------------------------- dispatch


def _fake_command(name: str, exc: BaseException | None):
    import types

    mod = types.ModuleType(name)

    def add_parser(sub):
        return sub.add_parser(name.rsplit(".", 1)[-1])

    def run(args):
        if exc is not None:
            raise exc
        print("ran")
        return 0

    mod.add_parser, mod.run = add_parser, run
    return mod


def test_dispatch_error_handling_in_process(monkeypatch, capsys):
    import arapkit.cli as cli
    from arapkit.errors import InputError

    cases = {
        "fake_ok": (None, 0),
        "fake_input": (InputError("x.json: bad\nthing"), 2),
        "fake_missing": (FileNotFoundError(2, "No such file", "gone.off"), 2),
        "fake_bug": (RuntimeError("boom"), 1),
    }
    table = []
    for name, (exc, _) in cases.items():
        monkeypatch.setitem(sys.modules, f"fake.{name}", _fake_command(f"fake.{name}", exc))
        table.append((name, f"fake.{name}"))
    monkeypatch.setattr(cli, "COMMANDS", table)
    for name, (_, code) in cases.items():
        assert cli.main([name]) == code, name
        err = capsys.readouterr().err
        if code == 2:
            assert err.count("\n") == 1 and err.startswith("arapkit: error: ")
        if name == "fake_input":
            assert err == "arapkit: error: x.json: bad thing\n"
        if name == "fake_missing":
            assert "gone.off: file not found" in err
        if name == "fake_bug":
            assert "Traceback" in err and "internal error (RuntimeError: boom)" in err
    assert cli.main(["learnish"]) == 2  # not registered: argparse usage error
    # a command module that is missing is a packaging bug and must not be hidden
    monkeypatch.setattr(cli, "COMMANDS", [("x", "arapkit.cli.no_such_module")])
    with pytest.raises(ModuleNotFoundError):
        cli.build_parser()


@needs_data
def test_indefinite_system_keeps_stdout_clean(tmp_path):
    """A scan whose cotangent system is indefinite: exit 2, one error line, nothing on stdout.

    CHOLMOD prints its own warning with printf before cholespy raises; it must not reach
    stdout (which carries results only) nor add a second line on stderr.
    """
    h = tmp_path / "h.json"
    h.write_text(json.dumps([
        {"name": "feet", "box": {"min": [-10, -4, -10], "max": [10, -3.5, 10]}},
        {"name": "head", "nearest": {"point": [0, 4, 0], "k": 30}, "translate": [0.5, 0, 0]},
    ]))
    mesh = MESHES / "npm_snowden_lo.obj"
    proc = arapkit("deform", mesh, "--handles", h, "--rings", 2, "--weights", "cotan",
                   "-o", tmp_path / "o.ply", "--quiet")
    assert proc.returncode == 2
    assert proc.stdout == ""
    # the remedy is worded for the command line, not as a Python keyword
    line = error_line(proc)
    assert "not positive definite" in line and "use --weights cotan-clamped" in line, line
    assert "CHOLMOD" not in proc.stderr
    # the remedy it names works
    ok = arapkit("deform", mesh, "--handles", h, "--rings", 2, "--weights", "cotan-clamped",
                 "-o", tmp_path / "o.ply", "--quiet")
    assert ok.returncode == 0, ok.stderr
    assert (tmp_path / "o.ply").exists()


def test_accelerate_flag_reaches_the_solver(tmp_path, bar_file):
    """--accelerate gives a monotone history and about the plain result's energy."""
    mesh_path, V, _ = bar_file
    base, tip = caps(V)
    h = tmp_path / "h.json"
    h.write_text(json.dumps([{"name": "base", "indices": base.tolist()},
                             {"name": "tip", "indices": tip.tolist(), "translate": [0, 0, 2]}]))
    reports = {}
    for flag in ([], ["--accelerate"]):
        rep = tmp_path / f"r{len(flag)}.json"
        proc = arapkit("deform", mesh_path, "--handles", h, "--rings", 2, "--tol", 1e-6,
                       "-o", tmp_path / f"o{len(flag)}.ply", "--report", rep, "--quiet", *flag)
        assert proc.returncode == 0, proc.stderr
        reports[bool(flag)] = json.loads(rep.read_text())
    acc = reports[True]
    assert acc["parameters"]["accelerate"] is True
    assert "accel_rejected" in acc["timings"]  # the accelerated loop ran
    H = np.array(acc["result"]["energy_history"])
    assert np.all(np.diff(H) <= 1e-10 * H[0])
    plain = reports[False]["result"]["energy"]
    assert acc["result"]["energy"] == pytest.approx(plain, rel=1e-3)


def test_edit_takes_deform_short_options():
    """A line written for ``deform`` (-H, -r, -G) opens the same files in ``edit``."""
    from arapkit.cli import build_parser

    parser = build_parser()
    short = parser.parse_args(["edit", "m.off", "-H", "h.json", "-r", "3", "-G", "g.json"])
    long = parser.parse_args(["edit", "m.off", "--handles", "h.json", "--rings", "3",
                              "--groups", "g.json"])
    assert (short.handles, short.rings, short.groups) == ("h.json", 3, "g.json")
    assert (long.handles, long.rings, long.groups) == ("h.json", 3, "g.json")
    deform = parser.parse_args(["deform", "m.off", "-H", "h.json", "-r", "3", "-G", "g.json"])
    assert (deform.handles, deform.rings, deform.groups) == ("h.json", 3, "g.json")
