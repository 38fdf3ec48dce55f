"""The r-ring build's cost: estimated before building, refused when it would not fit,
built without transient copies, with progress and cancellation (issue 47, part 1).

The estimate is checked against the real build's counts; the refusal with a limit forced
small through ``ARAPKIT_RING_MEMORY_MB`` (never by exhausting the machine); the peak with
tracemalloc, which sees numpy's allocations.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from arapkit import Deformer, InputError, load_mesh
from arapkit.arap import ringcost
from arapkit.arap.problem import ARAPProblem
from arapkit.arap.ringcost import (
    RING_MEMORY_VARIABLE,
    check_ring_memory,
    estimate_ring_cost,
    memory_share,
)
from arapkit.arap.rings import BuildCancelled, build_neighbourhoods, ring_progress
from arapkit.errors import worded_for
from arapkit.mesh.shapes import bar, bar_bend
from arapkit.mesh.weights import edge_weights

ROOT = Path(__file__).resolve().parents[1]
MESHES = ROOT.parent / "shared" / "data" / "meshes"
needs_data = pytest.mark.skipif(
    not MESHES.is_dir(), reason=f"real meshes not found at {MESHES} (../shared/data/meshes)")


def sizes(nb) -> tuple[int, int]:
    return int(nb.disk_ptr[-1]), int(nb.edge_ptr[-1])


def structure_bytes(nb) -> int:
    return sum(a.nbytes for a in (nb.rings, nb.edge_ptr, nb.edge_idx, nb.edge_layer,
                                  nb.disk_ptr, nb.disk_idx, nb.disk_coef, nb.edge_count))


# ------------------------------------------------------------------ the estimate
def test_small_mesh_is_counted_exactly():
    m = bar(segments=(8, 2, 2))  # fewer vertices than the sample: every one is searched
    assert m.n_vertices < ringcost.SAMPLES
    for r in (1, 3, 7):
        nb = build_neighbourhoods(m, edge_weights(m), r)
        c = estimate_ring_cost(m.n_vertices, m.edges, r)
        assert c.exact
        assert (c.disk_entries, c.edge_entries) == sizes(nb)
        assert c.bytes == pytest.approx(structure_bytes(nb), rel=0.01)


@needs_data
@pytest.mark.parametrize("name, r", [("cow.off", 4), ("cow.off", 12), ("homer.off", 8),
                                     ("bunny00.off", 3)])
def test_sampled_estimate_bounds_the_real_build(name, r):
    m = load_mesh(MESHES / name)
    c = estimate_ring_cost(m.n_vertices, m.edges, r)
    assert not c.exact
    disk, edges = sizes(build_neighbourhoods(m, edge_weights(m), r))
    # the mean plus two standard errors: above the truth, and not far
    for est, true in ((c.disk_entries, disk), (c.edge_entries, edges)):
        assert true <= est <= 1.12 * true, (name, r, est, true)


def test_per_vertex_map_is_sampled_per_value():
    """A small stiff region is never missed: each value of r has its own sample."""
    m = bar(segments=(60, 4, 4))
    rings = np.ones(m.n_vertices, dtype=np.int32)
    stiff = np.flatnonzero(m.vertices[:, 0] > 6.6)  # a few dozen vertices at one end
    rings[stiff] = 12
    assert 0 < len(stiff) < 0.1 * m.n_vertices
    c = estimate_ring_cost(m.n_vertices, m.edges, rings)
    disk, edges = sizes(build_neighbourhoods(m, edge_weights(m), rings))
    assert disk <= c.disk_entries <= 1.12 * disk
    assert edges <= c.edge_entries <= 1.12 * edges


def test_time_and_size_grow_with_r():
    m = bar()
    costs = [estimate_ring_cost(m.n_vertices, m.edges, r) for r in (1, 4, 16)]
    assert all(a.seconds < b.seconds and a.bytes < b.bytes for a, b in zip(costs, costs[1:]))


# ------------------------------------------------------------------ peak memory
@needs_data
def test_build_holds_no_transient_copy():
    """Peak numpy memory of a build within 1.15x its structure (the int64 copy of the edge
    ids that ``np.bincount`` made alone took 1.6x)."""
    m = load_mesh(MESHES / "cow.off")
    w = edge_weights(m)
    build_neighbourhoods(m, w, 1)  # compile outside the measure
    tracemalloc.start()
    try:
        nb = build_neighbourhoods(m, w, 12)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak <= 1.15 * structure_bytes(nb), peak / structure_bytes(nb)


# ------------------------------------------------------------------ refusal
@pytest.fixture
def small_limit(monkeypatch):
    monkeypatch.setenv(RING_MEMORY_VARIABLE, "40")
    return 40 * 2**20


def test_refusal_names_r_size_estimate_and_largest_r(small_limit):
    m = bar()
    h, _ = bar_bend(m, 90)
    with pytest.raises(InputError) as e:
        Deformer(m, h, rings=60)
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(f"{m.name}: r = 60 on 1,154 vertices needs about ")
    assert "MiB for its r-ring neighbourhoods" in msg and "40 MiB allowed by " in msg
    lo = int(msg.split("the largest r that fits is ")[1].split()[0])
    assert 1 <= lo < 60
    assert msg.endswith(f"(rings={lo})")
    assert worded_for(e.value.args[0], "cli").endswith(f"(--rings {lo})")
    assert worded_for(e.value.args[0], "editor").endswith(
        f"(Global r {lo} in the Rigidity panel)")
    # the advice is right: r = lo is built, r = lo + 1 is not
    nb = Deformer(m, h, rings=lo).problem.energy.nbh
    assert structure_bytes(nb) <= small_limit
    with pytest.raises(InputError, match="the largest r that fits is"):
        Deformer(m, h, rings=lo + 1)


def test_refusal_of_a_map_and_of_every_library_door(small_limit):
    m = bar()
    h, t = bar_bend(m, 90)
    rings = np.full(m.n_vertices, 80, dtype=np.int32)
    rings[:100] = 1
    with pytest.raises(InputError, match=r"r up to 80 \(a per-vertex map, 1\.\.80\).*capped "
                                         r"at r = \d+ the map fits"):
        ARAPProblem.from_mesh(m, h, rings=rings)
    d = Deformer(m, h, rings=2)
    before = d.solve(t).vertices
    with pytest.raises(InputError, match="r = 70 on 1,154 vertices"):
        d.set_rings(70)
    # refused before anything changed: the deformer still solves its own map
    assert d.rings.max() == 2
    assert np.allclose(d.solve(t).vertices, before)
    with pytest.raises(InputError, match="r = 70"):
        d.problem.with_rings(70)


@needs_data
def test_coarse_to_fine_refuses_the_full_mesh_rings_up_front(small_limit):
    """The proxy's rings would fit; the full mesh's, built later in the background, would
    not: refused at construction, naming the full mesh."""
    m = load_mesh(MESHES / "cow.off")
    h = np.arange(20)
    with pytest.raises(InputError, match=f"r = 20 on {m.n_vertices:,} vertices"):
        Deformer(m, h, rings=20, multires=True, proxy_vertices=400)

    d = Deformer(m, h, rings=2, multires=True, proxy_vertices=400)
    with pytest.raises(InputError, match=f"r = 20 on {m.n_vertices:,} vertices"):
        d.set_rings(20)  # refused now, not when the full mesh is built for the next solve
    assert d.rings.max() == 2 and d.proxy.rings.max() <= 2


def test_a_limit_with_room_builds(monkeypatch):
    monkeypatch.setenv(RING_MEMORY_VARIABLE, "100000")
    m = bar()
    assert check_ring_memory(m.n_vertices, m.edges, 60, "bar").bytes > 0


def test_jobs_sharing_a_host_share_its_memory(monkeypatch):
    monkeypatch.delenv(RING_MEMORY_VARIABLE, raising=False)
    monkeypatch.setattr(ringcost, "_meminfo_available", lambda: 400 * 2**20)
    monkeypatch.setattr(ringcost, "_cgroup_room", lambda: None)
    m = bar()
    check_ring_memory(m.n_vertices, m.edges, 60, "bar")  # about 60 MiB: fits in 400
    with memory_share(8), pytest.raises(InputError, match="of memory available to each of 8 "
                                                          "jobs on this host"):
        check_ring_memory(m.n_vertices, m.edges, 60, "bar")


def test_container_limit_is_read(monkeypatch):
    monkeypatch.delenv(RING_MEMORY_VARIABLE, raising=False)
    monkeypatch.setattr(ringcost, "_meminfo_available", lambda: 64 * 2**30)
    monkeypatch.setattr(ringcost, "_cgroup_room", lambda: 3 * 2**20)
    assert ringcost.available_memory() == (3 * 2**20, "memory available")


# ------------------------------------------------------------------ progress, cancel
@pytest.fixture
def slow_estimate(monkeypatch):
    """Make every build look long, so that it runs in pieces and reports progress."""
    monkeypatch.setattr(ringcost, "SECONDS_PER_EDGE_ENTRY", 1e-3)


def test_progress_runs_from_0_to_1(slow_estimate):
    m = bar()
    seen = []
    with ring_progress(lambda f, cost: seen.append((f, cost.seconds))):
        nb = build_neighbourhoods(m, edge_weights(m), 4)
    fractions = [f for f, _ in seen]
    assert fractions[0] == 0.0 and fractions[-1] == pytest.approx(1.0)
    assert len(fractions) >= 5 and np.all(np.diff(fractions) >= 0)
    assert seen[0][1] >= 1.0
    # pieces or not, the structure is the same
    ref = build_neighbourhoods(m, edge_weights(m), 4)
    for a in ("edge_ptr", "edge_idx", "edge_layer", "disk_ptr", "disk_idx", "edge_count"):
        assert np.array_equal(getattr(nb, a), getattr(ref, a)), a
    assert np.allclose(nb.disk_coef, ref.disk_coef, rtol=0, atol=1e-12)


def test_cancel_stops_the_build_and_keeps_the_deformer(slow_estimate):
    m = bar()
    h, t = bar_bend(m, 90)
    d = Deformer(m, h, rings=2)
    before = d.solve(t).vertices
    calls = []
    with ring_progress(lambda f, cost: calls.append(f) or f > 0.3), \
            pytest.raises(BuildCancelled):
        d.set_rings(6)
    assert 0.3 < calls[-1] < 1.0
    assert d.rings.max() == 2
    assert np.allclose(d.solve(t).vertices, before)


def test_progress_is_per_thread(slow_estimate):
    """A callback set in one thread does not see builds in another (the editor's worker)."""
    import threading

    m = bar()
    seen = []
    with ring_progress(lambda f, cost: seen.append(f)):
        th = threading.Thread(target=build_neighbourhoods, args=(m, edge_weights(m), 3))
        th.start()
        th.join()
    assert seen == []


# ------------------------------------------------------------------ the command line
def cli(*args, env=None):
    return subprocess.run([sys.executable, "-m", "arapkit.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONWARNINGS": "ignore", **(env or {})})


def test_cli_deform_refuses_in_one_line(tmp_path):
    ex = ROOT / "examples"
    p = cli("deform", ex / "bar.off", "--handles", ex / "bar-bend.json", "--rings", 60,
            "-o", tmp_path / "out.ply", env={RING_MEMORY_VARIABLE: "40"})
    assert p.returncode == 2, p.stderr
    assert "Traceback" not in p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("arapkit: error: bar.off: r = 60 on 1,154 vertices needs about ")
    assert "the largest r that fits is" in lines[0] and lines[0].endswith(")")
    assert "(--rings " in lines[0]
    assert not (tmp_path / "out.ply").exists()


def test_cli_learn_and_compare_refuse(tmp_path):
    m = bar()
    np.savez(tmp_path / "seq.npz", V=np.stack([m.vertices, m.vertices * [1, 1.1, 1]]),
             F=m.faces)
    p = cli("learn", tmp_path / "seq.npz", "--r-max", 60, "-o", tmp_path / "r.txt",
            env={RING_MEMORY_VARIABLE: "40"})
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    assert "r = 60 on 1,154 vertices needs about" in p.stderr
    ex = ROOT / "examples"
    p = cli("compare", ex / "bar.off", "--handles", ex / "bar-bend.json", "--rings", 60,
            "--out", tmp_path / "cmp", env={RING_MEMORY_VARIABLE: "40"})
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    assert "r = 60 on 1,154 vertices needs about" in p.stderr and "(--rings " in p.stderr


def test_cli_says_what_a_long_build_costs(tmp_path, monkeypatch, capsys):
    """Off a terminal the bar is a line: the estimate first, then the solve."""
    from arapkit.cli import main

    monkeypatch.setattr(ringcost, "SECONDS_PER_EDGE_ENTRY", 1e-3)
    ex = ROOT / "examples"
    assert main(["deform", str(ex / "bar.off"), "--handles", str(ex / "bar-bend.json"),
                 "--rings", "3", "-o", str(tmp_path / "out.ply")]) == 0
    err = capsys.readouterr().err
    assert "arapkit: building the r-ring neighbourhoods (about " in err
    assert "estimated)" in err


def test_batch_job_fails_alone_with_the_message(tmp_path, monkeypatch):
    from arapkit.workflows.batch import normalise_job, run_job

    monkeypatch.setenv(RING_MEMORY_VARIABLE, "40")
    ex = ROOT / "examples"
    job = normalise_job({"mesh": str(ex / "bar.off"), "handles": str(ex / "bar-bend.json"),
                         "rings": 60, "output": "bar60.ply"})
    row = run_job(job, tmp_path)
    assert row["status"] == "failed"
    assert "r = 60 on 1,154 vertices needs about" in row["error"]
    assert "(--rings " in row["error"]
    ok = run_job({**job, "rings": 2, "output": "bar2.ply"}, tmp_path)
    assert ok["status"] == "ok", ok
