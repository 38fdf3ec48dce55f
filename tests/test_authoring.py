"""Writing handle files and reading the output: info's box and up axis, --dry-run,
--view/--up, plain progress lines, the public API and one-line errors."""

from __future__ import annotations

import io
import json
import re
import subprocess
import sys
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

import arapkit
from arapkit.cli.common import Progress
from arapkit.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"


def arapkit_cli(*args, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "arapkit.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=600)


# ------------------------------------------------------------------ info


def test_info_prints_box_and_up_axis():
    proc = arapkit_cli("info", EX / "cactus.off", "--json")
    assert proc.returncode == 0, proc.stderr
    facts = json.loads(proc.stdout)
    V = arapkit.load_mesh(EX / "cactus.off").vertices
    np.testing.assert_allclose(facts["bounding_box_min"], V.min(0), rtol=0, atol=0)
    np.testing.assert_allclose(facts["bounding_box_max"], V.max(0), rtol=0, atol=0)
    np.testing.assert_allclose(facts["extents"], np.ptp(V, axis=0), rtol=1e-15)
    assert facts["up_axis_guess"] == "+y" and 0.9 <= facts["up_axis_confidence"] <= 1.0
    text = arapkit_cli("info", EX / "finger.off").stdout
    assert re.search(r"^up axis guess:\s+\+z$", text, re.M)
    assert re.search(r"^bounding box min:\s+\[", text, re.M)


# ------------------------------------------------------------------ --dry-run


def test_dry_run_prints_groups_and_draws_them(tmp_path):
    fig = tmp_path / "groups.png"
    proc = arapkit_cli("deform", EX / "cactus.off", "--handles", EX / "cactus.json",
                       "--dry-run", "--figure", fig)
    assert proc.returncode == 0, proc.stderr
    V = arapkit.load_mesh(EX / "cactus.off").vertices
    # independent counts: vertices inside each box of cactus.json
    groups = json.loads((EX / "cactus.json").read_text())["groups"]
    for g in groups:
        lo, hi = np.array(g["box"]["min"]), np.array(g["box"]["max"])
        n = int(np.all((V >= lo) & (V <= hi), axis=1).sum())
        kind = "fixed" if "rotate" not in g else "moved"
        assert re.search(rf"^  {g['name']}: {n} vertices, {kind}", proc.stdout, re.M), proc.stdout
    assert "nothing solved" in proc.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["groups.png"]  # no mesh written
    img = mpimg.imread(fig)[..., :3]
    # each group's colour (tab10: blue, orange, green) is on the picture
    import matplotlib.pyplot as plt

    for k in range(3):
        c = np.array(plt.get_cmap("tab10").colors[k])
        shaded = img / np.maximum(img.max(axis=-1, keepdims=True), 1e-9)
        assert np.any(np.all(np.abs(shaded - c / c.max()) < 0.06, axis=-1)), f"group {k}"


def test_dry_run_moved_group_reports_displacement(tmp_path):
    proc = arapkit_cli("deform", EX / "bar.off", "--handles", EX / "handles/explicit-targets.json",
                       "--dry-run")
    assert proc.returncode == 0, proc.stderr
    V = arapkit.load_mesh(EX / "bar.off").vertices
    spec = json.loads((EX / "handles/explicit-targets.json").read_text())["groups"][1]
    d = np.array(spec["targets"]) - V[spec["indices"]]
    mean = ", ".join(f"{x:.4g}" for x in d.mean(0) + 0.0)
    big = np.linalg.norm(d, axis=1).max()
    assert f"right corners: 4 vertices, moved: mean displacement [{mean}], largest {big:.4g}" \
        in proc.stdout


def test_output_required_without_dry_run(tmp_path):
    proc = arapkit_cli("deform", EX / "bar.off", "--handles", EX / "bar-bend.json")
    assert proc.returncode == 2
    assert proc.stderr.strip() == (
        "arapkit: error: -o/--output OUT is required (only --dry-run writes no mesh)"
    )


# ------------------------------------------------------------------ --view / --up


def test_view_and_up_options_on_every_drawing_command(tmp_path):
    from arapkit.cli import build_parser

    p = build_parser()
    for argv in (["deform", "m.off", "-H", "h.json", "-o", "o.ply"], ["learn", "a.npz", "-o", "r"],
                 ["demo"]):
        a = p.parse_args([*argv, "--view", "iso", "--up=-y"])
        assert (a.view, a.up) == ("iso", "-y")
        assert p.parse_args([*argv, "--up", "z"]).up == "+z"
    bad = arapkit_cli("demo", "--up", "w", "--out", tmp_path / "d")
    assert bad.returncode == 2 and "expected one of +x" in bad.stderr


def test_deform_figure_with_side_view(tmp_path):
    proc = arapkit_cli("deform", EX / "finger.off", "--handles", EX / "handles/rotate-limb.json",
                       "-o", tmp_path / "f.ply", "--figure", tmp_path / "f.png", "--view",
                       "side", "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert mpimg.imread(tmp_path / "f.png")[..., :3].std() > 0.05


# ------------------------------------------------------------------ progress and wording


class _Pipe(io.StringIO):
    def isatty(self) -> bool:
        return False


def test_progress_without_a_terminal_is_plain_lines(monkeypatch):
    err = _Pipe()
    monkeypatch.setattr(sys, "stderr", err)
    with Progress(delay=0.0, interval=0.0, desc="r = 2") as p:
        for it, e in enumerate([4.0, 2.0, 1.0], start=1):
            p(it, e, None)
    lines = err.getvalue().splitlines()
    assert "\r" not in err.getvalue() and len(lines) == 3
    # the first iteration has nothing to compare with: its line says so by leaving it out
    assert lines[0] == "arapkit: r = 2: iteration 1, energy 4"
    assert lines[1] == "arapkit: r = 2: iteration 2, energy 2, rel. decrease 5.00e-01"


def test_deform_log_has_no_carriage_returns(tmp_path):
    # a solve long enough for progress output (tol tiny, many iterations), stderr a pipe
    proc = arapkit_cli("deform", EX / "cactus.off", "--handles", EX / "cactus.json",
                       "--rings", "4", "--tol", "1e-12", "--max-iter", "300",
                       "-o", tmp_path / "c.ply")
    assert proc.returncode == 0, proc.stderr
    assert "\r" not in proc.stderr


def test_learn_says_one_example(tmp_path):
    data = np.load(EX / "finger-bend.npz")
    np.savez(tmp_path / "two.npz", V=data["V"][:2], F=data["F"])
    proc = arapkit_cli("learn", tmp_path / "two.npz", "-o", tmp_path / "r.txt")
    assert proc.returncode == 0, proc.stderr
    assert "from 1 example;" in proc.stdout and "examples" not in proc.stdout.split(";")[0]


def test_edit_help_has_examples():
    out = arapkit_cli("edit", "--help").stdout
    assert "examples:" in out and "arapkit edit examples/cactus.off" in out


# ------------------------------------------------------------------ API surface


def test_all_lists_importable_public_names():
    assert "os" not in dir(arapkit) and "_os" not in dir(arapkit)
    for name in arapkit.__all__:
        assert hasattr(arapkit, name), name
        assert not name.startswith("_") or name == "__version__"
    mods = {n for n in arapkit.__all__ if type(getattr(arapkit, n)).__name__ == "module"}
    assert not mods


def test_names_the_readme_uses_are_importable_from_arapkit():
    # the README and the user pages that took its reference sections
    pages = ["README.md", "docs/solver.md", "docs/handles.md", "docs/cli.md", "docs/io.md",
             "docs/learning.md", "docs/editor.md", "docs/interactive.md", "docs/weights.md"]
    text = "\n".join((ROOT / p).read_text() for p in pages)
    used = set(re.findall(r"\barapkit\.([a-z_][A-Za-z_]+)\(", text))
    used |= {"save_mesh", "load_handles", "load_rings", "save_rings"}  # named by the issue
    missing = [n for n in sorted(used) if not hasattr(arapkit, n)]
    assert not missing


def test_kernel_value_errors_are_input_errors():
    from arapkit.arap.rotations import fit_rotations

    with pytest.raises(InputError, match=r"shape \(n, 3, 3\), got \(2, 3\)"):
        fit_rotations(np.ones((2, 3)))
    with pytest.raises(InputError, match="S must be numbers"):
        fit_rotations([[["a"] * 3] * 3])
    V = np.zeros((4, 3))
    with pytest.raises(InputError, match=r"k must be an integer in 1\.\.4, got 5"):
        arapkit.select_nearest(V, [0, 0, 0], 5)
    with pytest.raises(InputError, match="point must be 3 finite numbers"):
        arapkit.select_nearest(V, [0, np.inf, 0], 1)


def test_handle_files_accept_comments():
    V = np.eye(3)
    hs = arapkit.parse_handles({"comment": "top", "groups": [
        {"name": "a", "comment": "why", "indices": [0]}]}, V)
    assert hs.indices.tolist() == [0]
    with pytest.raises(InputError, match="unknown top-level key 'comments'"):
        arapkit.parse_handles({"comments": "x", "groups": []}, V)


def test_shipped_examples_are_what_the_script_makes(tmp_path):
    """examples/make_examples.py reproduces the shipped files (so they can be regenerated)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_examples", EX / "make_examples.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(tmp_path)
    made = sorted(p.name for p in tmp_path.iterdir())
    assert made == ["bar-rings.txt", "bar.def", "bar.off", "bar.sel", "cactus-points.ply",
                    "cactus.off", "finger-bend.npz", "finger-landmarks.json", "finger-scan.xyz",
                    "finger.off"]
    for name in made:
        if name.endswith(".npz"):
            a, b = np.load(tmp_path / name), np.load(EX / name)
            assert all(np.array_equal(a[k], b[k]) for k in ("V", "F"))
        else:
            assert (tmp_path / name).read_bytes() == (EX / name).read_bytes(), name
    total = sum(p.stat().st_size for p in EX.rglob("*") if p.is_file())
    # small enough to ship in the repository (600 KB since the examples hold a point cloud,
    # cactus-points.ply, 56 KB, beside the fit's scan)
    assert total < 600_000
