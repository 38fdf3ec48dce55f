"""``arapkit simulate``: its outputs against the library, and its refusals (one line, exit 2)."""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from arapkit import cli, load_mesh
from arapkit.io.frames import load_frames
from arapkit.methods.dynamics import simulate

ROOT = Path(__file__).resolve().parents[1]
BAR = ROOT / "examples" / "bar.off"


def run_main(*args) -> tuple[int, str, str]:
    """The command line in-process: (status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = cli.main([str(a) for a in args])
    return rc, out.getvalue(), err.getvalue()


def test_defaults_write_frames_the_library_reproduces(tmp_path):
    """The door as a user types it (a subprocess): a free bar falls under gravity along
    the guessed up axis (-z), and the frames are the library's."""
    out = tmp_path / "fall.npz"
    proc = subprocess.run([sys.executable, "-m", "arapkit.cli", "simulate", str(BAR),
                           "--frames", "6", "-o", str(out)], capture_output=True, text=True,
                          timeout=600, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert proc.returncode == 0, proc.stderr
    assert "gravity [0, 0, -9.81] m/s^2, down the guessed up axis +z" in proc.stderr
    assert "frames: 6" in proc.stdout and "converged steps: 5 of 5" in proc.stdout
    V, F, t = load_frames(out)
    m = load_mesh(BAR)
    assert V.shape == (6, m.n_vertices, 3) and np.array_equal(F, m.faces)
    assert np.allclose(t, np.arange(6) / 60)
    ref = simulate(m, 6, gravity=[0, 0, -9.81])
    assert np.abs(V - ref.vertices).max() < 1e-12
    assert V[-1, :, 2].mean() < m.vertices[:, 2].mean() - 0.01  # it fell


def test_handles_ramp_to_their_pose_and_a_sequence_and_figure_are_written(tmp_path):
    pytest.importorskip("matplotlib", reason="--figure needs the plots extra")
    handles = ROOT / "examples" / "bar-bend.json"
    rc, stdout, err = run_main("simulate", BAR, "-H", handles, "--frames", "4", "--ramp",
                               "0.05", "--gravity", "0", "0", "0", "-o", tmp_path / "b.obj",
                               "--figure", tmp_path / "film.png", "-q")
    assert rc == 0, err
    files = sorted(p.name for p in tmp_path.glob("b_*.obj"))
    assert files == ["b_0000.obj", "b_0001.obj", "b_0002.obj", "b_0003.obj"]
    m = load_mesh(BAR)
    from arapkit import load_handles

    hs = load_handles(handles, m.vertices)
    last = load_mesh(tmp_path / "b_0003.obj").vertices
    assert np.abs(last[hs.indices] - hs.targets).max() < 1e-6  # the pose, reached at 0.05 s
    first = load_mesh(tmp_path / "b_0000.obj").vertices
    assert np.abs(first - m.vertices).max() < 1e-6
    assert (tmp_path / "film.png").read_bytes()[:4] == b"\x89PNG"
    assert "handles: 50" in stdout


@pytest.mark.parametrize(("args", "match"), [
    (["--dt", "0"], "--dt: must be greater than 0"),
    (["--dt", "-0.01"], "--dt: must be greater than 0"),
    (["--frames", "0"], "--frames/-n: must be at least 1"),
    (["--gravity", "0", "nan", "0"], "--gravity: expected a finite number, got nan"),
    (["--stiffness", "-5"], "--stiffness/-k: must be greater than 0"),
    (["--damping", "-1"], "--damping: must be at least 0"),
    (["--energy", "sr-arap"], "--energy sr-arap: dynamics needs"),
    (["--energy", "nope"], "unknown method 'nope'"),
])
def test_bad_options_are_one_line_exit_2(tmp_path, args, match):
    rc, _, err = run_main("simulate", BAR, "-o", tmp_path / "x.npz", *args)
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("arapkit: error: ") and match in lines[0], err
    assert not (tmp_path / "x.npz").exists()


def test_a_handles_file_out_of_range_is_one_line_exit_2(tmp_path):
    bad = tmp_path / "h.json"
    bad.write_text(json.dumps([{"name": "pin", "indices": [0, 99999]}]))
    rc, _, err = run_main("simulate", BAR, "-H", bad, "-o", tmp_path / "x.npz")
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and str(bad) in lines[0] and "99999" in lines[0], err


def test_outputs_are_checked_before_the_work(tmp_path):
    rc, _, err = run_main("simulate", BAR, "-o", tmp_path / "x.txt")
    assert rc == 2 and "unsupported mesh format '.txt'" in err
    rc, _, err = run_main("simulate", BAR, "-o", tmp_path / "no" / "x.npz")
    assert rc == 2 and "output folder" in err
    rc, _, err = run_main("simulate", BAR, "-o", tmp_path / "x.npz", "--figure",
                          tmp_path / "f.gif")
    assert rc == 2 and "unsupported figure format" in err
