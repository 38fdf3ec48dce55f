"""A light core install: arapkit without its extras, and the one line a door prints for one.

Each test runs Python in a subprocess in which the extra's modules cannot be imported
(``sys.modules[name] = None`` makes ``import name`` raise ImportError, as if not installed),
so the test process's own imports do not hide a missing guard.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"
GUI = ("matplotlib", "viser")


def _env() -> dict[str, str]:
    # this checkout's sources, whatever arapkit the interpreter may have installed
    path = os.pathsep.join(p for p in (str(ROOT / "src"), os.environ.get("PYTHONPATH")) if p)
    return {**os.environ, "PYTHONPATH": path}


def python_without(blocked, code: str, cwd=None) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter where the modules ``blocked`` are not importable."""
    guard = f"import sys\nfor _m in {tuple(blocked)!r}:\n    sys.modules[_m] = None\n"
    return subprocess.run([sys.executable, "-c", guard + code], capture_output=True, text=True,
                          cwd=cwd, env=_env(), timeout=600)


def cli_without(blocked, *args, cwd=None) -> subprocess.CompletedProcess:
    """``arapkit ARGS`` where the modules ``blocked`` are not importable."""
    code = f"from arapkit.cli import main\nsys.exit(main({[str(a) for a in args]!r}))\n"
    return python_without(blocked, code, cwd)


def test_import_arapkit_needs_no_gui_or_plotting_stack():
    code = (
        "import arapkit, arapkit.cli, arapkit.plots.colors\n"
        "arapkit.cli.build_parser()\n"
        "from arapkit.mesh.shapes import bar, bar_bend\n"
        "m = bar(); h, t = bar_bend(m, 90)\n"
        "print(arapkit.Deformer(m, h).solve(t).converged)\n"
    )
    proc = python_without(GUI, code)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "True"


def test_deform_runs_on_the_examples_without_the_extras(tmp_path):
    out = tmp_path / "bent.off"
    proc = cli_without(GUI, "deform", EX / "bar.off", "--handles", EX / "bar.sel",
                       "--transform", EX / "bar.def", "-o", out, "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert out.is_file() and "converged: yes" in proc.stdout


def test_ply_with_custom_properties_needs_no_plyfile(tmp_path):
    """PLY in and out with the core alone: plyfile (GPL) is not imported, a property stays."""
    from ply_oracle import parse_ply

    from arapkit.io import load_mesh, save_mesh

    bar = load_mesh(EX / "bar.off")
    quality = np.linspace(0, 1, bar.n_vertices)
    save_mesh(tmp_path / "bar.ply", bar.vertices, bar.faces, {"quality": quality})
    out = tmp_path / "bent.ply"
    proc = cli_without((*GUI, "plyfile"), "deform", tmp_path / "bar.ply", "--handles",
                       EX / "bar.sel", "--transform", EX / "bar.def", "-o", out, "--quiet")
    assert proc.returncode == 0, proc.stderr
    vert = parse_ply(out.read_bytes())["elements"]["vertex"]
    assert vert["quality"] == quality.tolist()


def _plots_line(what: str) -> str:
    return f"arapkit: error: {what} needs the plots extra: pip install 'arapkit[plots]'\n"


_EDITOR_LINE = ("arapkit: error: arapkit edit needs the editor extra: "
                "pip install 'arapkit[editor]'\n")


@pytest.mark.parametrize("blocked", [("viser",), ("matplotlib",)])
def test_edit_without_the_editor_extra_names_it(blocked):
    proc = cli_without(blocked, "edit", EX / "bar.off", "--port", "1")
    assert (proc.returncode, proc.stderr, proc.stdout) == (2, _EDITOR_LINE, "")


@pytest.mark.parametrize(
    "args, what",
    [
        (["deform", EX / "bar.off", "-H", EX / "bar.sel", "-o", "{tmp}/o.off",
          "--figure", "{tmp}/f.png"], "arapkit deform --figure"),
        (["deform", EX / "cactus.off", "-H", EX / "cactus.json", "--dry-run",
          "--figure", "{tmp}/f.png"], "arapkit deform --figure"),
        (["learn", EX / "finger-bend.npz", "-o", "{tmp}/r.txt", "--figure", "{tmp}/f.png"],
         "arapkit learn --figure"),
        (["compare", EX / "bar.off", "-H", EX / "bar.sel", "-o", "{tmp}/cmp"],
         "arapkit compare"),
        (["demo", "--out", "{tmp}/demo"], "arapkit demo"),
        (["fit", EX / "finger.off", EX / "finger-scan.xyz", "-o", "{tmp}/out.ply",
          "--figure", "{tmp}/f.png"], "arapkit fit --figure"),
    ],
    ids=["deform", "deform-dry-run", "learn", "compare", "demo", "fit"],
)
def test_figures_without_the_plots_extra_name_it(tmp_path, args, what):
    args = [str(a).format(tmp=tmp_path) for a in args]
    proc = cli_without(("matplotlib",), *args)
    assert (proc.returncode, proc.stderr) == (2, _plots_line(what))
    assert list(tmp_path.iterdir()) == []  # said before anything was solved or written


def test_importing_the_figures_without_matplotlib_names_the_extra():
    code = (
        "from arapkit.errors import InputError\n"
        "try:\n"
        "    import arapkit.plots.figures\n"
        "except ImportError as e:\n"
        "    print(isinstance(e, InputError), e)\n"
    )
    proc = python_without(("matplotlib",), code)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "True arapkit.plots needs the plots extra: pip install 'arapkit[plots]'\n"


def test_cloud_laplacian_weights_without_the_clouds_extra_name_it():
    code = (
        "import numpy as np, arapkit\n"
        "c = arapkit.PointCloud(np.random.default_rng(0).random((30, 3)))\n"
        "print(arapkit.Deformer(c, [0]).weights_kind)\n"  # the default needs nothing
        "try:\n"
        "    arapkit.Deformer(c, [0], weights='laplacian')\n"
        "except ImportError as e:\n"
        "    print(isinstance(e, arapkit.InputError), e)\n"
    )
    proc = python_without(("robust_laplacian",), code)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == ("gaussian\nTrue weights='laplacian' needs the clouds extra: "
                           "pip install 'arapkit[clouds]'\n")


def _pyproject() -> dict:
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def _names(requirements: list[str]) -> set[str]:
    return {r.split("[")[0].split(">")[0].split("=")[0].split("<")[0].strip()
            for r in requirements}


def test_core_dependencies_carry_no_gui_or_plotting_stack():
    project = _pyproject()
    core = _names(project["dependencies"])
    assert core == {"numpy", "scipy", "numba", "cholespy", "trimesh", "tqdm",
                    "fast-simplification", "qdldl"}
    extras = project["optional-dependencies"]
    assert "matplotlib" in _names(extras["plots"])
    assert {"viser", "matplotlib"} <= _names(extras["editor"])
    # all: every extra but torch (.ci/run adds it) and the test tools
    assert extras["all"] == ["arapkit[plots,editor,batch,volume,clouds,image]"]
    assert set(extras) == {"plots", "editor", "batch", "torch", "volume", "clouds", "image",
                           "all", "test"}
    assert _names(extras["clouds"]) == {"robust-laplacian"}
    assert {"pillow", "scikit-image", "shapely", "PythonCDT"} <= _names(extras["image"])


def test_make_installs_every_extra_and_checks_the_layers_before_pytest():
    make = (ROOT / "Makefile").read_text()
    assert '$(BIN)/pip install --quiet -e ".[all,test]"' in make
    recipe = make.split("\ntest:", 1)[1].split("\n\n", 1)[0].splitlines()[1:]
    assert [line.split()[0] for line in recipe] == [
        "$(BIN)/ruff", "$(BIN)/lint-imports", "$(BIN)/python"]


_IMAGE_LINE = ("arapkit: error: arapkit warp needs the image extra: "
               "pip install 'arapkit[image]'\n")


@pytest.mark.parametrize("blocked", [("PIL",), ("skimage",), ("shapely",), ("pythoncdt",)])
def test_warp_without_the_image_extra_names_it(tmp_path, blocked):
    proc = cli_without(blocked, "warp", EX / "puppet.png", "--pins", EX / "puppet-pins.json",
                       "-o", tmp_path / "o.png")
    assert (proc.returncode, proc.stderr, proc.stdout) == (2, _IMAGE_LINE, "")
    assert not (tmp_path / "o.png").exists()
