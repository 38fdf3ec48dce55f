"""``arapkit batch`` and distributed ``learn`` on Dask.

Most tests share one in-process cluster (two workers of one thread, ``processes=False``);
one starts a real ``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1. Batch
outputs are compared byte for byte with ``arapkit deform`` run in this process with the
numba thread count the batch report records, and the deformations themselves are checked
against the handle targets written here.
"""

from __future__ import annotations

import csv
import importlib.util
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numba
import numpy as np
import pytest
from conftest import data_path

from arapkit.cli import main
from arapkit.io import (
    parse_handles,
    read_ply_vertex_properties,
    save_def,
    save_mesh,
    save_rings,
    save_sel,
)
from arapkit.mesh.shapes import bar

HAVE_DASK = importlib.util.find_spec("distributed") is not None
needs_dask = pytest.mark.skipif(not HAVE_DASK, reason="dask/distributed not installed "
                                "(pip install 'arapkit[batch]')")
ROOT = Path(__file__).resolve().parents[1]
COLUMNS = ["output", "status", "error", "iterations", "energy", "seconds", "worker"]

BEND = [
    {"name": "left", "box": {"min": [-1, -1, -1], "max": [0.01, 1, 1]}},
    {"name": "right", "box": {"min": [6.99, -1, -1], "max": [8, 1, 1]},
     "rotate": {"axis": [0, 0, 1], "degrees": 60, "center": [7, 0, 0]},
     "translate": [-0.5, 1.0, 0]},
]


@pytest.fixture(scope="module")
def cluster():
    """An in-process Dask cluster: two workers with one thread each."""
    if not HAVE_DASK:
        pytest.skip("dask/distributed not installed")
    import logging

    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                      dashboard_address=None, silence_logs=logging.ERROR) as lc, Client(lc) as c:
        yield c


@pytest.fixture
def data(tmp_path):
    """A bar mesh with handle files of every kind, a corrupt mesh and a job file."""
    m = bar(segments=(35, 3, 3))
    save_mesh(tmp_path / "bar.off", m.vertices, m.faces)
    (tmp_path / "bend.json").write_text(json.dumps(BEND))
    save_sel(tmp_path / "bar.sel", m.n_vertices, np.flatnonzero(m.vertices[:, 0] < 1e-9),
             np.flatnonzero(m.vertices[:, 0] > 7 - 1e-9))
    lift = np.eye(4)
    lift[:3, 3] = [0, 0.8, 0.3]
    save_def(tmp_path / "bar.def", lift)
    save_rings(tmp_path / "r.txt", np.where(m.vertices[:, 0] < 3.5, 1, 4))
    (tmp_path / "broken.off").write_text("OFF\n4 2 0\n0 0 0\n1 0 0\n")
    jobs = [
        {"mesh": "bar.off", "handles": "bend.json", "rings": 3, "output": "json3.ply"},
        {"mesh": "bar.off", "handles": "bar.sel", "transform": "bar.def", "output": "sel.off",
         "tol": 1e-4, "init": "laplacian"},
        {"mesh": "bar.off", "handles": "bend.json", "rings_file": "r.txt", "output": "map.ply"},
        {"mesh": "bar.off", "handles": BEND, "rings": 2, "max_iter": 5, "output": "inline.obj"},
    ]
    write_lines(tmp_path / "jobs.jsonl", jobs)
    return tmp_path, m, jobs


def write_lines(path: Path, jobs: list) -> None:
    path.write_text("".join((j if isinstance(j, str) else json.dumps(j)) + "\n" for j in jobs))


def summary(outdir: Path) -> list[dict]:
    with open(outdir / "summary.csv", newline="") as f:
        reader = csv.DictReader(f)
        assert reader.fieldnames == COLUMNS
        return list(reader)


def deform_args(folder: Path, job: dict, out: Path) -> list[str]:
    """The ``arapkit deform`` arguments of a job (inline handles saved to a file)."""
    handles = job["handles"]
    if not isinstance(handles, str):
        (folder / "inline.json").write_text(json.dumps(handles))
        handles = "inline.json"
    args = ["deform", str(folder / job["mesh"]), "--handles", str(folder / handles)]
    for key, flag in (("transform", "--transform"), ("rings_file", "--rings-file")):
        if key in job:
            args += [flag, str(folder / job[key])]
    for key in ("rings", "tol", "max_iter", "init"):
        if key in job:
            args += ["--" + key.replace("_", "-"), str(job[key])]
    return [*args, "-o", str(out), "-q"]


def ply_vertices(path: Path) -> np.ndarray:
    p = read_ply_vertex_properties(path)
    return np.stack([p["x"], p["y"], p["z"]], axis=1)


# --------------------------------------------------------------------------- batch


@needs_dask
def test_outputs_equal_single_deform_runs(data, cluster, capsys):
    folder, mesh, jobs = data
    out = folder / "out"
    assert main(["batch", str(folder / "jobs.jsonl"), "-o", str(out),
                 "--scheduler", cluster.scheduler.address]) == 0
    rows = summary(out)
    assert [r["output"] for r in rows] == [j["output"] for j in jobs]
    assert [r["status"] for r in rows] == ["ok"] * 4
    workers = set(cluster.scheduler_info()["workers"])
    assert {r["worker"] for r in rows} <= workers
    saved = numba.get_num_threads()
    try:
        for job, row in zip(jobs, rows):
            report = json.loads((out / (job["output"] + ".json")).read_text())
            threads = report["batch"]["numba_threads"]
            # two one-thread workers on this host share its cores
            assert threads == max(1, len(os.sched_getaffinity(0)) // 2)
            assert report["result"]["iterations"] == int(row["iterations"])
            assert report["result"]["energy"] == float(row["energy"])
            numba.set_num_threads(threads)
            single = folder / ("single-" + job["output"])
            assert main(deform_args(folder, job, single)) == 0
            assert (out / job["output"]).read_bytes() == single.read_bytes(), job["output"]
    finally:
        numba.set_num_threads(saved)
    # the deformation itself: the .sel job's handle vertices moved by the .def matrix
    sel = np.loadtxt(out / "sel.off", skiprows=2, max_rows=mesh.n_vertices)
    right = mesh.vertices[:, 0] > 7 - 1e-9
    left = mesh.vertices[:, 0] < 1e-9
    np.testing.assert_allclose(sel[right], mesh.vertices[right] + [0, 0.8, 0.3], atol=1e-9)
    np.testing.assert_allclose(sel[left], mesh.vertices[left], atol=1e-9)
    hs = parse_handles(BEND, mesh.vertices)
    V = ply_vertices(out / "json3.ply")
    np.testing.assert_allclose(V[hs.indices], hs.targets, atol=1e-5)
    assert "jobs: 4 (ok 4, skipped 0, failed 0)" in capsys.readouterr().out


@needs_dask
def test_bad_jobs_fail_alone_with_their_messages(data, cluster, capsys):
    folder, mesh, jobs = data
    bad = [
        *jobs[:2],
        {"mesh": "broken.off", "handles": "bend.json", "output": "broken.ply"},
        {"mesh": "nowhere.off", "handles": "bend.json", "output": "missing.ply"},
        {"mesh": "bar.off", "handles": [{"indices": [0, 10**6]}], "output": "range.ply"},
    ]
    write_lines(folder / "bad.jsonl", bad)
    out = folder / "out"
    assert main(["batch", str(folder / "bad.jsonl"), "-o", str(out),
                 "--scheduler", cluster.scheduler.address]) == 3
    rows = {r["output"]: r for r in summary(out)}
    assert [rows[j["output"]]["status"] for j in bad] == ["ok", "ok", "failed", "failed",
                                                           "failed"]
    assert rows["broken.ply"]["error"].startswith(f"{folder / 'broken.off'}: ")
    assert "truncated" in rows["broken.ply"]["error"]
    assert rows["missing.ply"]["error"].startswith(f"{folder / 'nowhere.off'}: ")
    assert "vertex index 1000000 out of range" in rows["range.ply"]["error"]
    for name in ("broken.ply", "missing.ply", "range.ply"):
        assert "\n" not in rows[name]["error"] and not (out / name).exists()
        assert rows[name]["iterations"] == "" and rows[name]["worker"].startswith("inproc://")
    assert (out / "json3.ply").is_file() and (out / "sel.off.json").is_file()
    assert "failed 3" in capsys.readouterr().out


@needs_dask
def test_rerun_skips_and_no_resume_redoes(data, cluster):
    folder, mesh, jobs = data
    out = folder / "out"
    args = ["batch", str(folder / "jobs.jsonl"), "-o", str(out), "--scheduler",
            cluster.scheduler.address, "-q"]
    assert main(args) == 0
    first = {r["output"]: r for r in summary(out)}
    stamps = {j["output"]: (out / j["output"]).stat().st_mtime_ns for j in jobs}
    assert main(args) == 0
    second = summary(out)
    assert [r["status"] for r in second] == ["skipped"] * 4
    for r in second:  # the skipped rows carry the earlier results
        assert r["iterations"] == first[r["output"]]["iterations"]
        assert r["energy"] == first[r["output"]]["energy"]
    assert stamps == {j["output"]: (out / j["output"]).stat().st_mtime_ns for j in jobs}
    # a changed input file or a changed parameter reruns only the jobs concerned
    time.sleep(0.01)
    (folder / "r.txt").write_text((folder / "r.txt").read_text())
    jobs[0] = {**jobs[0], "rings": 2}
    write_lines(folder / "jobs.jsonl", jobs)
    assert main(args) == 0
    assert [r["status"] for r in summary(out)] == ["ok", "skipped", "ok", "skipped"]
    assert main([*args, "--no-resume"]) == 0
    assert [r["status"] for r in summary(out)] == ["ok"] * 4
    # a missing report (or output) means the job is redone
    (out / "sel.off.json").unlink()
    assert main(args) == 0
    assert [r["status"] for r in summary(out)] == ["skipped", "ok", "skipped", "skipped"]


@needs_dask
@pytest.mark.parametrize(
    "line, message",
    [
        ('{"mesh": "bar.off", "handles": "bend.json", "output": "x.ply", "ring": 2}',
         ":3: unknown key 'ring'"),
        ('{"mesh": "bar.off", "handles": "bend.json", "output": "x.ply"', ":3: not valid JSON"),
        ('["bar.off"]', ":3: a job must be a JSON object"),
        ('{"mesh": "bar.off", "output": "x.ply"}', ":3: missing key 'handles'"),
        ('{"mesh": "bar.off", "handles": "bend.json", "output": "json3.ply"}',
         ":3: output 'json3.ply' is already written by line 1"),
        ('{"mesh": "bar.off", "handles": "bend.json", "output": "../x.ply"}',
         ":3: 'output' '../x.ply' must be a file name inside the output folder"),
        # (.xyz is a point cloud's: a .off may hold one, so that waits for the file; a
        # format neither a mesh nor a cloud is written in is refused at once)
        ('{"mesh": "bar.off", "handles": "bend.json", "output": "x.abc"}',
         ":3: x.abc: unsupported output format"),
        ('{"mesh": "bar.off", "handles": "bend.json", "output": "x.ply", "rings": 0}',
         ":3: 'rings': must be at least 1, got 0"),
        ('{"mesh": "bar.off", "handles": "bend.json", "output": "x.ply", "energy": "sr"}',
         ":3: energy sr is not available in this build"),
        ('{"mesh": "bar.off", "handles": "bend.json", "output": "x.ply", "rings": 2, '
         '"rings_file": "r.txt"}', ":3: give 'rings' or 'rings_file', not both"),
        ('{"mesh": "bar.off", "handles": "bend.json", "output": "x.ply", "tol": -1}',
         ":3: 'tol': must be at least 0, got -1"),
    ],
)
def test_malformed_job_file_exit_2_writes_nothing(data, capsys, line, message):
    folder, mesh, jobs = data
    lines = [json.dumps(jobs[0]), "", line, json.dumps(jobs[1])]
    write_lines(folder / "jobs.jsonl", lines)
    out = folder / "out"
    # no cluster is needed: the file is checked before one is started or reached
    assert main(["batch", str(folder / "jobs.jsonl"), "-o", str(out),
                 "--scheduler", "tcp://127.0.0.1:1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"arapkit: error: {folder / 'jobs.jsonl'}:3: ")
    assert message in err[0]
    assert not out.exists()


def test_batch_without_dask_says_how_to_install(data, monkeypatch, capsys):
    folder, _, _ = data
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails as if absent
    assert main(["batch", str(folder / "jobs.jsonl"), "-o", str(folder / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("arapkit: error: arapkit batch needs dask and distributed: "
                   "pip install 'arapkit[batch]'")
    assert not (folder / "out").exists()


@needs_dask
def test_library_run_returns_summary_rows(data, cluster, monkeypatch):
    from arapkit.workflows import batch

    folder, mesh, jobs = data
    monkeypatch.chdir(folder)  # job paths given as objects are relative to the current folder
    rows = batch.run(jobs[:2], folder / "lib", cluster)
    if not isinstance(rows, list):
        rows = rows.to_dict("records")
    assert [set(r) for r in rows] == [set(COLUMNS)] * 2
    assert [r["status"] for r in rows] == ["ok", "ok"]
    assert isinstance(rows[0]["iterations"], int) and rows[0]["energy"] > 0
    report = json.loads((folder / "lib" / "json3.ply.json").read_text())
    assert report["batch"]["job"]["mesh"] == str(folder / "bar.off")
    assert report["command"][:3] == ["arapkit", "deform", str(folder / "bar.off")]


def test_jobs_follow_the_library_rules_and_defaults(tmp_path, capsys):
    """A job field takes the rule and the default of the library parameter it sets."""
    from arapkit import Deformer, InputError
    from arapkit.mesh.shapes import bar_bend
    from arapkit.methods.deformer import INITS
    from arapkit.validate import MAX_ITER_LIMIT, MAX_RINGS
    from arapkit.workflows.batch import job_spec, normalise_job

    base = {"mesh": "/m.off", "handles": "/h.json", "output": "a.ply"}
    m = bar(segments=(7, 1, 1))
    h, _ = bar_bend(m, 30)
    # tol = 0 (run to max_iter) is a valid tolerance for both
    assert normalise_job({**base, "tol": 0})["tol"] == 0.0
    assert Deformer(m, h, tol=0).tol == 0.0
    # r and max_iter above the library's caps: refused by the job, deform and the API alike
    for key, flag, value in (("rings", "--rings", MAX_RINGS + 1),
                             ("max_iter", "--max-iter", MAX_ITER_LIMIT + 1)):
        rule = f"must be at most {value - 1}, got {value}"
        with pytest.raises(InputError) as job_error:
            normalise_job({**base, key: value})
        assert str(job_error.value) == f"job: '{key}': {rule}"
        assert main(["deform", "/m.off", "-H", "/h.json", "-o", str(tmp_path / "o.ply"),
                     flag, str(value)]) == 2
        assert rule in capsys.readouterr().err
        # the API names the same limit (per vertex for a rigidity map)
        api_rule = f"r must be 1..{MAX_RINGS}" if key == "rings" else rule
        with pytest.raises(InputError, match=api_rule.replace(".", r"\.")):
            Deformer(m, h, **{key: value})
    with pytest.raises(InputError, match=f"'init' must be {' or '.join(INITS)}"):
        normalise_job({**base, "init": "random"})
    # a job that leaves everything out solves with the Deformer's own defaults
    spec = job_spec(normalise_job(base))
    deformer = Deformer(m, h)
    assert (spec.tol, spec.max_iter, spec.init, spec.energy, spec.accelerate) == (
        deformer.tol, deformer.max_iter, deformer.init, deformer.energy, deformer.accelerate)
    # weights None: the shape's own default, which the Deformer resolves (cotan-clamped here)
    assert spec.weights is None and Deformer(m, h, weights=spec.weights).weights_kind == \
        deformer.weights_kind == "cotan-clamped"
    assert spec.rings == int(deformer.rings[0])


def test_job_hash_follows_parameters_and_input_files(tmp_path):
    from arapkit.workflows.batch import job_hash, normalise_job

    m = bar(segments=(7, 1, 1))
    save_mesh(tmp_path / "m.off", m.vertices, m.faces)
    save_sel(tmp_path / "m.sel", m.n_vertices, [0], [m.n_vertices - 1])
    save_def(tmp_path / "m.def", np.eye(4))
    job = normalise_job({"mesh": "m.off", "handles": "m.sel", "output": "o.ply"}, tmp_path)
    assert job["mesh"] == str(tmp_path / "m.off") and "weights" in job
    h0 = job_hash(job)
    assert job_hash(dict(job)) == h0
    assert job_hash({**job, "tol": 1e-4}) != h0
    assert job_hash({**job, "output": "p.ply"}) != h0
    # the .def read beside the .sel counts as an input although the job does not name it
    lift = np.eye(4)
    lift[1, 3] = 0.5
    save_def(tmp_path / "m.def", lift)
    assert job_hash(job) != h0


# --------------------------------------------------------------------------- augmentation


@needs_dask
def test_augment_is_reproducible_and_runs(data, cluster):
    from arapkit.workflows.batch import augment_jobs

    folder, mesh, _ = data
    a = augment_jobs([folder / "bar.off"], 3, seed=7)
    assert a == augment_jobs([folder / "bar.off"], 3, seed=7)
    assert a != augment_jobs([folder / "bar.off"], 3, seed=8)
    k = max(3, mesh.n_vertices // 50)
    for job in a:
        hs = parse_handles(job["handles"], mesh.vertices)  # valid and disjoint groups
        fixed, moved = hs.groups
        assert len(fixed.indices) == len(moved.indices) <= k
        assert 1 <= job["rings"] <= 3
        # the moved group is among the 10% of vertices farthest from the fixed one's point
        p = np.asarray(job["handles"][0]["nearest"]["point"])
        q = np.asarray(job["handles"][1]["nearest"]["point"])
        d = np.linalg.norm(mesh.vertices - p, axis=1)
        assert np.linalg.norm(q - p) >= np.quantile(d, 0.89) - 1e-5
    out = folder / "aug"
    assert main(["batch", "--augment", "3", "--seed", "7", str(folder / "bar.off"), "-o",
                 str(out), "--scheduler", cluster.scheduler.address, "-q"]) == 0
    written = [json.loads(ln) for ln in (out / "jobs.jsonl").read_text().splitlines()]
    assert written == a
    rows = summary(out)
    assert [r["status"] for r in rows] == ["ok"] * 3
    for job in a:  # every output reaches its own handle targets
        hs = parse_handles(job["handles"], mesh.vertices)
        V = ply_vertices(out / job["output"])
        np.testing.assert_allclose(V[hs.indices], hs.targets, atol=1e-4)
    # the written job list reruns as a plain batch: everything is up to date
    assert main(["batch", str(out / "jobs.jsonl"), "-o", str(out), "--scheduler",
                 cluster.scheduler.address, "-q"]) == 0
    assert [r["status"] for r in summary(out)] == ["skipped"] * 3


# --------------------------------------------------------------------------- learning


def _twist(V: np.ndarray, turns: float) -> np.ndarray:
    """Twist about the x axis by an angle growing along x: a smooth non-rigid motion."""
    a = turns * V[:, 0] / 7.0
    c, s = np.cos(a), np.sin(a)
    return np.stack([V[:, 0], c * V[:, 1] - s * V[:, 2], s * V[:, 1] + c * V[:, 2]], axis=1)


def _sequences(mesh):
    V = mesh.vertices
    seq_a = [V, _twist(V, 0.6), V * [1.0, 1.0, 1.3]]
    wave = np.zeros_like(V)
    wave[:, 1] = 0.2 * np.sin(V[:, 0])
    seq_b = [_twist(V, -1.0), V * [1.2, 0.9, 1.0] + wave]
    seq_c = [_twist(V, 2.0)]
    return seq_a, seq_b, seq_c


@needs_dask
def test_learn_sequences_on_dask_equal_one_process(cluster):
    from arapkit.learn.fit import learn_rings, learn_rings_sequences
    from arapkit.workflows.batch import dask_map

    mesh = bar(segments=(35, 3, 3))
    seq_a, seq_b, seq_c = _sequences(mesh)
    seqs = [seq_a[1:], seq_b, seq_c]  # seq_a[0] is the reference
    local = learn_rings_sequences(mesh, seqs, r_max=4, omega="auto")
    dist = learn_rings_sequences(mesh, seqs, r_max=4, omega="auto", map=dask_map(cluster))
    np.testing.assert_array_equal(dist.energies, local.energies)
    np.testing.assert_array_equal(dist.rings, local.rings)
    assert dist.omega == local.omega and dist.n_examples == 5
    # one process over all examples at once: the same table up to the order of the sums
    one = learn_rings(mesh, [P for s in seqs for P in s], r_max=4, omega="auto")
    np.testing.assert_allclose(dist.energies, one.energies, rtol=1e-12, atol=1e-300)
    np.testing.assert_array_equal(dist.rings, one.rings)
    assert len(np.unique(one.rings)) > 1  # a map that says something
    # the mean is by example count: a per-sequence brute force mean agrees
    from arapkit.learn.fit import ring_energies

    tables = [ring_energies(mesh, s, 1, 4)[0] for s in seqs]
    brute = sum(len(s) * t for s, t in zip(seqs, tables)) / 5
    np.testing.assert_allclose(dist.energies, brute, rtol=1e-12)


@needs_dask
def test_learn_panda_walk_split_in_sequences(cluster):
    """The real 61-frame walk as three sequences on the cluster: the one-process map."""
    from arapkit import Mesh
    from arapkit.learn.fit import learn_rings, learn_rings_sequences
    from arapkit.workflows.batch import dask_map

    with np.load(data_path("sequences", "panda_walk_seq.npz")) as d:
        V, F = d["V"].astype(np.float64), d["F"]
    ref = Mesh(V[0], F)
    seqs = [V[1:21], V[21:41], V[41:]]
    dist = learn_rings_sequences(ref, seqs, omega="auto", map=dask_map(cluster))
    one = learn_rings(ref, V[1:], omega="auto")
    assert dist.n_examples == one.n_examples == 60
    np.testing.assert_allclose(dist.energies, one.energies, rtol=1e-11, atol=1e-15)
    assert dist.omega == pytest.approx(one.omega, rel=1e-12)
    np.testing.assert_array_equal(dist.rings, one.rings)
    assert len(np.unique(one.rings)) >= 4  # the walk's map spreads over r (README: 1..6)


@needs_dask
def test_learn_cli_several_npz_with_scheduler(tmp_path, cluster, capsys):
    mesh = bar(segments=(35, 3, 3))
    seq_a, seq_b, seq_c = _sequences(mesh)
    for name, seq in (("a", seq_a), ("b", seq_b), ("c", seq_c)):
        np.savez(tmp_path / f"{name}.npz", V=np.stack(seq), F=mesh.faces)
    np.savez(tmp_path / "all.npz", V=np.stack(seq_a + seq_b + seq_c), F=mesh.faces)
    dist, local, one = tmp_path / "dist.txt", tmp_path / "local.txt", tmp_path / "one.txt"
    files = [str(tmp_path / f"{n}.npz") for n in "abc"]

    def learn(inputs, out, *extra):
        args = ["learn", *inputs, "-o", str(out), "--r-max", "4", "--energies",
                str(out) + ".npy", *extra]
        assert main(args) == 0, capsys.readouterr().err

    learn(files, dist, "--scheduler", cluster.scheduler.address)
    learn(files, local)
    learn([str(tmp_path / "all.npz")], one)
    assert dist.read_text() == local.read_text() == one.read_text()
    E_dist, E_local = np.load(str(dist) + ".npy"), np.load(str(local) + ".npy")
    np.testing.assert_array_equal(E_dist, E_local)
    np.testing.assert_allclose(E_dist, np.load(str(one) + ".npy"), rtol=1e-12)
    assert "5 examples" in capsys.readouterr().out
    # sequences must share the reference's connectivity
    np.savez(tmp_path / "d.npz", V=np.stack(seq_c), F=mesh.faces[:, [0, 2, 1]])
    assert main(["learn", files[0], str(tmp_path / "d.npz"), "-o", str(tmp_path / "x.txt")]) == 2
    assert "d.npz: faces differ from" in capsys.readouterr().err


# --------------------------------------------------------------------------- real cluster


def _start(args: list[str], log: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT / "src"), *filter(None, [os.environ.get("PYTHONPATH")])])}
    with open(log, "wb") as f:
        return subprocess.Popen([sys.executable, "-m", "dask", *args], stdout=f,
                                stderr=subprocess.STDOUT, env=env, cwd=log.parent)


@needs_dask
def test_default_local_cluster_of_processes(data):
    """Without --scheduler the command starts (and stops) its own cluster of processes."""
    folder, _, jobs = data
    out = folder / "out"
    proc = subprocess.run(
        [sys.executable, "-m", "arapkit.cli", "batch", str(folder / "jobs.jsonl"), "-o",
         str(out), "--workers", "2"],
        capture_output=True, text=True, timeout=300,
        env={**os.environ, "PYTHONPATH": str(ROOT / "src")})
    assert proc.returncode == 0, proc.stderr
    rows = summary(out)
    assert [r["status"] for r in rows] == ["ok"] * 4
    used = {r["worker"] for r in rows}
    assert 1 <= len(used) <= 2 and all(w.startswith("tcp://127.0.0.1:") for w in used)
    assert proc.stdout.splitlines()[0] == "jobs: 4 (ok 4, skipped 0, failed 0)"


@needs_dask
def test_scheduler_and_two_worker_processes(data):
    """A scheduler and two workers on 127.0.0.1, then ``arapkit batch --scheduler``."""
    from distributed import Client

    folder, mesh, jobs = data
    more = [{**jobs[0], "rings": r, "output": f"r{r}.ply"} for r in (1, 2, 4, 5)]
    write_lines(folder / "jobs.jsonl", jobs + more)
    sched_file = folder / "scheduler.json"
    procs = [_start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                     "--scheduler-file", str(sched_file)], folder / "scheduler.log")]
    try:
        deadline = time.monotonic() + 120
        while not sched_file.exists():
            assert time.monotonic() < deadline, (folder / "scheduler.log").read_text()
            assert procs[0].poll() is None, (folder / "scheduler.log").read_text()
            time.sleep(0.2)
        for i in range(2):
            procs.append(_start(["worker", "--scheduler-file", str(sched_file), "--nthreads",
                                 "1", "--host", "127.0.0.1", "--no-dashboard", "--name",
                                 f"w{i}"], folder / f"worker{i}.log"))
        address = json.loads(sched_file.read_text())["address"]
        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=120)
            workers = set(client.scheduler_info()["workers"])
        assert len(workers) == 2 and all(w.startswith("tcp://127.0.0.1:") for w in workers)
        out = folder / "out"
        proc = subprocess.run(
            [sys.executable, "-m", "arapkit.cli", "batch", str(folder / "jobs.jsonl"), "-o",
             str(out), "--scheduler", address],
            capture_output=True, text=True, timeout=300,
            env={**os.environ, "PYTHONPATH": str(ROOT / "src")})
        assert proc.returncode == 0, proc.stderr
        rows = summary(out)
        assert [r["status"] for r in rows] == ["ok"] * 8
        # every job ran on the cluster, and both workers took part
        assert {r["worker"] for r in rows} == workers
        # not a terminal: one plain progress line per job
        assert len([ln for ln in proc.stderr.splitlines() if "jobs/min" in ln]) == 8
        for job in jobs + more:
            report = json.loads((out / (job["output"] + ".json")).read_text())
            assert report["batch"]["worker"] in workers
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=20)


def test_dry_run_counts_groups_without_dask_or_output(data, capsys, monkeypatch):
    """--dry-run resolves each job's handles (counts taken here from the box selections and
    the .sel file), reports an unreadable job as failed and writes nothing; Dask is not
    needed."""
    from arapkit.workflows import batch

    folder, mesh, jobs = data
    jobs = [*jobs[:2], {"mesh": "broken.off", "handles": "bend.json", "output": "broken.ply"}]
    write_lines(folder / "dry.jsonl", jobs)
    monkeypatch.setattr(batch, "require_dask", lambda: pytest.fail("dry run needs no Dask"))
    out = folder / "dry-out"
    assert main(["batch", str(folder / "dry.jsonl"), "-o", str(out), "--dry-run"]) == 0
    text = capsys.readouterr().out
    V = mesh.vertices
    for g in BEND:
        lo, hi = np.array(g["box"]["min"]), np.array(g["box"]["max"])
        count = int(np.all((V >= lo) & (V <= hi), axis=1).sum())
        assert f"{g['name']}: {count} vertices" in text
    fixed = int((V[:, 0] < 1e-9).sum())
    moved = int((V[:, 0] > 7 - 1e-9).sum())
    assert f"{fixed + moved} handle vertices" in text
    assert "job 3 -> broken.ply: failed: " in text and "truncated" in text
    assert not out.exists()


@needs_dask
def test_unwritable_output_folder_is_refused_before_any_job(data, locked, capsys, monkeypatch):
    """An output folder that cannot take files is found before a cluster starts or a job
    runs, and the message names the user's path (issue: outputs checked first)."""
    from arapkit.workflows import batch

    folder, _, _ = data
    monkeypatch.setattr(batch, "_local_cluster",
                        lambda *a, **k: pytest.fail("a cluster was started"))
    assert main(["batch", str(folder / "jobs.jsonl"), "-o", str(locked), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{locked / 'summary.csv'}: cannot write" in err[0]
    assert main(["batch", str(folder / "jobs.jsonl"), "-o", str(locked / "sub"), "-q"]) == 2
    assert f"{locked / 'sub'}: cannot create the output folder" in capsys.readouterr().err


def test_a_job_run_in_the_callers_thread_gives_its_thread_count_back(tmp_path):
    """run_job limits numba's threads for its own solve only (the count is per thread)."""
    import numba

    from arapkit.io import save_mesh
    from arapkit.workflows.batch import normalise_job, run_job

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one numba thread: nothing to limit")
    m = bar(segments=(20, 2, 2))
    save_mesh(tmp_path / "bar.off", m.vertices, m.faces)
    (tmp_path / "h.json").write_text(json.dumps([
        {"box": {"min": [-1, -1, -1], "max": [0.01, 1, 1]}},
        {"box": {"min": [6.99, -1, -1], "max": [8, 1, 1]}, "translate": [0, 0, 1]}]))
    job = normalise_job({"mesh": "bar.off", "handles": "h.json", "output": "o.ply"}, tmp_path)
    before = numba.get_num_threads()
    row = run_job(job, tmp_path / "out", threads=1)
    assert row["status"] == "ok", row["error"]
    report = json.loads((tmp_path / "out" / "o.ply.json").read_text())
    assert report["batch"]["numba_threads"] == 1
    assert numba.get_num_threads() == before
