"""A factor held by a child process (arapkit.arap.childfactor): the same numbers as the
factor made here, the same errors, the GIL left free, and no child or file left behind."""

from __future__ import annotations

import gc
import os
import threading
import time

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

import arapkit.arap.childfactor as childfactor
from arapkit import InputError
from arapkit.arap.childfactor import ChildCholesky, factors_in_child
from arapkit.arap.constraints import CholeskyFactor
from arapkit.mesh.shapes import bar, bar_bend
from arapkit.methods.multires import MultiresDeformer


def _grid_laplacian(k: int, shift: float = 1e-2) -> sp.csr_matrix:
    """A k x k grid's graph Laplacian plus ``shift`` I: symmetric positive definite."""
    n = k * k
    A = sp.diags([-1.0, -1.0, 4.0, -1.0, -1.0], [-k, -1, 0, 1, k], shape=(n, n))
    return sp.csr_matrix(A + shift * sp.eye(n))


def test_a_child_factor_solves_as_the_factor_made_here():
    """Same cholespy, same matrix: bitwise the same solutions for a vector, three columns
    and then five (the shared buffer grows), and both agree with SciPy's own solve."""
    A = _grid_laplacian(40)
    rng = np.random.default_rng(3)
    here = CholeskyFactor(A, "grid")
    with factors_in_child(10):
        child = CholeskyFactor(A, "grid")
    assert isinstance(child._solver, ChildCholesky)
    assert child._solver.pid != os.getpid()
    for B in (rng.standard_normal(A.shape[0]), rng.standard_normal((A.shape[0], 3)),
              rng.standard_normal((A.shape[0], 5)), rng.standard_normal((A.shape[0], 1))):
        x = child.solve(B)
        assert x.shape == B.shape
        assert np.array_equal(x, here.solve(B))
        ref = spsolve(sp.csc_matrix(A), B)
        assert np.abs(x - ref.reshape(B.shape)).max() < 1e-10 * np.abs(ref).max()
    out = np.empty((A.shape[0], 3))
    B = rng.standard_normal((A.shape[0], 3))
    assert child.solve(B, out) is out and np.array_equal(out, here.solve(B))
    child._solver.close()


def test_only_large_factors_and_only_where_asked_go_to_a_child():
    A = _grid_laplacian(12)  # 144 rows
    assert not isinstance(CholeskyFactor(A, "grid")._solver, ChildCholesky)
    with factors_in_child(145):
        assert not isinstance(CholeskyFactor(A, "grid")._solver, ChildCholesky)
    with factors_in_child(144):
        f = CholeskyFactor(A, "grid")
        assert isinstance(f._solver, ChildCholesky)
        f._solver.close()


def test_a_matrix_that_is_not_positive_definite_fails_alike_in_a_child():
    A = _grid_laplacian(10, shift=-1.0)  # shifted below zero: indefinite
    with pytest.raises(InputError) as here:
        CholeskyFactor(A, "grid")
    with factors_in_child(10), pytest.raises(InputError) as child:
        CholeskyFactor(A, "grid")
    assert str(child.value) == str(here.value)
    assert "not positive definite" in str(child.value)


def test_where_no_child_can_start_the_factor_is_made_here(monkeypatch):
    A = _grid_laplacian(20)
    B = np.random.default_rng(0).standard_normal((A.shape[0], 3))
    monkeypatch.setattr(childfactor.sys, "executable", None)  # an embedded interpreter
    with factors_in_child(10):
        f = CholeskyFactor(A, "grid")
    assert not isinstance(f._solver, ChildCholesky)
    assert np.array_equal(f.solve(B), CholeskyFactor(A, "grid").solve(B))


def test_the_child_ends_with_its_factor_and_leaves_no_files():
    with factors_in_child(10):
        f = CholeskyFactor(_grid_laplacian(20), "grid")
    proc, folder = f._solver._proc, f._solver._folder
    f.solve(np.ones(400))
    assert proc.poll() is None and os.path.isdir(folder)
    del f
    gc.collect()
    assert proc.wait(timeout=10) == 0
    assert not os.path.exists(folder)


def test_building_a_child_factor_leaves_this_process_running():
    """cholespy holds the GIL for a whole factorisation: made here on another thread, a
    200x200 grid's factor stops this thread for all of it. In a child, this thread runs
    for most of the build."""
    A = _grid_laplacian(200)
    done = {}

    def build():
        with factors_in_child(10):
            done["f"] = CholeskyFactor(A, "grid")

    thread = threading.Thread(target=build)
    ran = 0.0
    t0 = time.perf_counter()
    thread.start()
    while thread.is_alive():
        t = time.perf_counter()
        time.sleep(0.002)
        ran += min(time.perf_counter() - t, 0.05)  # a tick stopped by the GIL counts 50 ms
    elapsed = time.perf_counter() - t0
    thread.join()
    assert isinstance(done["f"]._solver, ChildCholesky)
    assert ran > 0.5 * elapsed, (ran, elapsed)
    done["f"]._solver.close()


def test_a_background_build_puts_the_full_factor_in_a_child(monkeypatch):
    """MultiresDeformer builds its full problem beside the preview in a child; the solve
    from it equals the one whose factor was made here."""
    import arapkit.methods.multires.levels as levels

    monkeypatch.setattr(levels, "can_overlap", lambda: True)
    monkeypatch.setattr(childfactor, "CHILD_MIN_ROWS", 100)
    mesh = bar(segments=(120, 12, 12))
    h, t = bar_bend(mesh, 60)
    beside = MultiresDeformer(mesh, h, proxy_vertices=400, background=True)
    assert beside.wait_ready(120)
    factor = beside.full.problem.elimination.factor
    assert isinstance(factor._solver, ChildCholesky)
    here = MultiresDeformer(mesh, h, proxy_vertices=400)
    assert not isinstance(here.full.problem.elimination.factor._solver, ChildCholesky)
    a, b = beside.solve(t), here.solve(t)
    assert a.iterations == b.iterations
    assert np.abs(a.vertices - b.vertices).max() < 1e-12 * mesh.bounding_box_diagonal


def test_children_import_what_is_on_this_process_path_only(tmp_path, monkeypatch):
    """An embedded interpreter (Blender) puts an extension's wheels on sys.path at run time:
    both kinds of child (a factor, a decimation) must import from there too: a package in a
    folder on this process's sys.path alone must be found by each child."""
    import subprocess
    import sys

    import arapkit.methods.multires.decimator as decimator
    from arapkit.arap.childfactor import child_env

    marker = tmp_path / "sitepkg"
    (marker / "arapkit_probe_pkg").mkdir(parents=True)
    (marker / "arapkit_probe_pkg" / "__init__.py").write_text("WHERE = 'extension'\n")
    monkeypatch.syspath_prepend(str(marker))
    probe = [sys.executable, "-c", "import arapkit_probe_pkg; print(arapkit_probe_pkg.WHERE)"]
    plain = subprocess.run(probe, capture_output=True, text=True,
                           env={k: v for k, v in child_env().items() if k != "PYTHONPATH"})
    assert plain.returncode != 0  # without the path the probe is not found: the test bites
    got = subprocess.run(probe, capture_output=True, text=True, env=child_env())
    assert got.stdout.strip() == "extension"
    # both launchers pass that environment
    seen = []
    real_run, real_popen = subprocess.run, subprocess.Popen
    monkeypatch.setattr(decimator.subprocess, "run",
                        lambda *a, **k: seen.append(k.get("env")) or real_run(*a, **k))
    mesh = bar(segments=(20, 4, 4))
    V, F = decimator._decimator_input(mesh, decimator._frame(mesh), 100)
    decimator._run_child(V, F, 100)
    monkeypatch.setattr(childfactor.subprocess, "Popen",
                        lambda *a, **k: seen.append(k.get("env")) or real_popen(*a, **k))
    A = sp.coo_matrix(np.array([[4.0, 1.0], [1.0, 3.0]]))
    ChildCholesky(2, A.row.astype(np.int32), A.col.astype(np.int32), A.data).close()
    assert len(seen) == 2
    assert all(str(marker) in env["PYTHONPATH"].split(os.pathsep) for env in seen)
