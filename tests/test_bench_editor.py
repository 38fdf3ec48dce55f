"""The editor bench's memory watch: it must not cost what it measures."""

import importlib.util
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_editor.py"


def _bench():
    spec = importlib.util.spec_from_file_location("bench_editor", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_watch_reads_pss_only_when_the_resident_sizes_rise(monkeypatch):
    """smaps_rollup (33 ms a read at 1.75M vertices) is read on a rise of the resident
    sizes by PSS_STEP_KIB, not every 100 ms, and the peak Pss is still the largest read."""
    be = _bench()
    w = be.Watch()
    w.close()  # sampled by hand below
    rss = {"self": 0, "7": 0}
    pss = {"self": 0, "7": 0}
    reads = []

    def proc_kib(pid, file, field):
        if file == "smaps_rollup":
            reads.append(pid)
            return pss[pid]
        return rss[pid] if field == "VmRSS" else 0

    monkeypatch.setattr(be, "_proc_kib", proc_kib)
    monkeypatch.setattr(be, "_children", lambda: ["7"])
    step = be.PSS_STEP_KIB
    trace = [  # (rss self, rss child, pss self, pss child), a sample each
        (10 * step, 2 * step, 9 * step, 2 * step),   # first sample: read
        (10 * step, 2 * step, 9 * step, 2 * step),   # steady: no read
        (10 * step + 10, 2 * step, 9 * step, 2 * step),  # a small rise: no read
        (11 * step, 3 * step, 10 * step, 3 * step),  # up by 2 steps: read, new peak
        (8 * step, 2 * step, 7 * step, 2 * step),    # down: no read
        (11 * step, 3 * step, 10 * step, 3 * step),  # back up, not past the last read
    ]
    for a, b, c, d in trace:
        rss["self"], rss["7"], pss["self"], pss["7"] = a, b, c, d
        w._sample()
    assert len(reads) == 4  # two reads of two processes
    assert w.pss_reads == 2
    assert w.total_peak == 13 * step
