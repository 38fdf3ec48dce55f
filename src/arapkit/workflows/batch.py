"""Many deformation jobs on a Dask cluster: a local one by default, or any existing one.

A job is one ``arapkit deform`` written as a JSON object, a job list a JSON Lines file
(:mod:`arapkit.workflows.jobfile`: the schema, its checks and defaults; random jobs for
data sets come from :mod:`arapkit.workflows.augment`). :func:`run` sends every job to the
cluster as one task; each task writes the deformed mesh and its JSON report (the
``deform`` report plus a ``batch`` section) atomically and returns one row of the summary.
One bad job never stops the others: its row says ``failed`` with the one-line message
``deform`` would print.

Every task runs the same library code as ``arapkit deform`` (:mod:`arapkit.workflows.jobs`)
with the solver limited to ``cores // (tasks running on that host)`` numba threads, so N workers do
not oversubscribe a machine. The output equals that of ``arapkit deform`` run with the same
number of threads (``NUMBA_NUM_THREADS``, recorded in the report): the solver sums per
chunk of vertices and the chunking follows the thread count.

Resume: a task whose output and report already exist, with the report's ``job_hash``
equal to the hash of the job's normalised parameters and of its input files' sizes and
modification times, is ``skipped``.

Examples
--------
>>> import tempfile, pathlib, json
>>> from arapkit.io import save_mesh
>>> from arapkit.mesh.shapes import bar
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> m = bar()
>>> _ = save_mesh(d / "bar.off", m.vertices, m.faces)
>>> handles = [{"box": {"min": [-1, -1, -1], "max": [0.01, 1, 1]}},
...            {"box": {"min": [6.99, -1, -1], "max": [8, 1, 1]}, "translate": [0, 1, 0]}]
>>> jobs = [{"mesh": str(d / "bar.off"), "handles": handles, "rings": r,
...          "output": f"bar{r}.ply"} for r in (1, 3)]
>>> rows = run(jobs, d / "out", client=False)  # doctest: +SKIP
>>> [row["status"] for row in rows]  # doctest: +SKIP
['ok', 'ok']
"""

from __future__ import annotations

import csv
import io
import json
import os
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from typing import Any

from ..arap.ringcost import memory_share
from ..errors import InputError

# the job schema and augmentation live beside this module; their names stay importable here
from .augment import augment_jobs
from .jobfile import (
    JOB_KEYS,
    dry_run,
    job_hash,
    job_spec,
    load_jobs,
    normalise_job,
    write_jobs,
)
from .jobs import error_message

__all__ = [
    "INSTALL_HINT",
    "JOB_KEYS",
    "SUMMARY_COLUMNS",
    "augment_jobs",
    "dask_map",
    "dry_run",
    "job_spec",
    "job_hash",
    "load_jobs",
    "normalise_job",
    "report_path",
    "require_dask",
    "run",
    "run_job",
    "write_jobs",
    "write_summary",
]

#: Columns of ``summary.csv``, in order.
SUMMARY_COLUMNS = ("output", "status", "error", "iterations", "energy", "seconds", "worker")
INSTALL_HINT = "arapkit batch needs dask and distributed: pip install 'arapkit[batch]'"


def require_dask() -> None:
    """Raise :class:`InputError` with :data:`INSTALL_HINT` when Dask is not installed."""
    try:
        import dask  # noqa: F401
        import distributed  # noqa: F401
    except ImportError:
        raise InputError(INSTALL_HINT) from None


# --------------------------------------------------------------------------- one task


def _check_outdir(outdir: Path) -> None:
    """Create OUTDIR and prove it writable before any cluster starts or job runs."""
    from ..io import check_output_path

    if outdir.exists() and not outdir.is_dir():
        raise InputError(f"{outdir}: output folder is a file")
    try:
        outdir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"{outdir}: cannot create the output folder "
                         f"({e.strerror or type(e).__name__})") from None
    check_output_path(outdir / "summary.csv", what="batch output")


def _worker_address() -> str:
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return "local"


def _deform_command(job: dict, output: str) -> list[str]:
    """The ``arapkit deform`` command line equivalent to ``job``."""
    # inline handles: the report's input.handles, saved as a .json file
    handles = job["handles"] if isinstance(job["handles"], str) else "HANDLES.json"
    cmd = ["arapkit", "deform", job["mesh"], "--handles", handles]
    if job["transform"]:
        cmd += ["--transform", job["transform"]]
    if job["rings_file"]:
        cmd += ["--rings-file", job["rings_file"]]
    else:
        cmd += ["--rings", str(job["rings"])]
    if job["weights"] is not None:  # None: the shape's default, as deform's
        cmd += ["--weights", job["weights"]]
    cmd += ["--energy", job["energy"], "--tol", repr(job["tol"]),
            "--max-iter", str(job["max_iter"]), "--init", job["init"]]
    # the method's own options and welding, as given (deform fills in the same defaults)
    for key, flag in (("sr_alpha", "--sr-alpha"), ("nodes", "--nodes"),
                      ("smooth_lambda", "--smooth-lambda"), ("weld", "--weld"),
                      ("neighbours", "--neighbours"), ("radius", "--radius")):
        if job[key] is not None:
            cmd.append(f"{flag}={job[key]}")
    if job["accelerate"] is not None:  # None: the method's choice, as deform's default
        cmd.append("--accelerate" if job["accelerate"] else "--no-accelerate")
    if job.get("groups") is not None:  # inline groups: the report's vertex_groups
        cmd += ["--groups", job["groups"] if isinstance(job["groups"], str) else "GROUPS.json"]
    return [*cmd, "-o", output]


def report_path(output: str | os.PathLike) -> Path:
    """Where a job's report goes: beside its output, ``NAME.EXT.json``."""
    return Path(f"{os.fspath(output)}.json")


def _previous(output: Path, digest: str) -> dict | None:
    """The report of an earlier identical run whose output still exists, else None."""
    rp = report_path(output)
    if not (output.is_file() and rp.is_file()):
        return None
    try:
        report = json.loads(rp.read_text(encoding="utf-8"))
        return report if report["batch"]["job_hash"] == digest else None
    except (OSError, ValueError, KeyError, TypeError):
        return None


@contextmanager
def _limit_threads(threads: int) -> Iterator[int]:
    """Run with at most ``threads`` numba threads, then give the caller its own count back.

    The count is per calling thread in numba, so in-process workers do not disturb each
    other; restoring it matters as much: a batch run in the caller's thread used to leave it
    on one thread, and the solver's sums (chunked by thread count) then differed in the last
    bits from the same solve elsewhere.
    """
    import numba

    saved = numba.get_num_threads()
    threads = max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(threads)
    try:
        yield threads
    finally:
        numba.set_num_threads(saved)


def _row(job: dict, status: str, error: str = "", iterations: Any = "", energy: Any = "",
         seconds: float = 0.0, worker: str = "") -> dict:
    return {"output": job["output"], "status": status, "error": error,
            "iterations": iterations, "energy": energy, "seconds": round(seconds, 3),
            "worker": worker}


def run_job(job: dict, outdir: str | os.PathLike, threads: int | dict = 1,
            resume: bool = True) -> dict:
    """Run one normalised job (the Dask task); never raises for a bad job.

    Parameters
    ----------
    job : dict
        From :func:`normalise_job`.
    outdir : path
        Output folder (``job["output"]`` is relative to it).
    threads : int or dict
        Numba threads for the solver, or ``{host: tasks on that host}`` from which the
        task takes ``cores // tasks``.
    resume : bool
        Skip the job when an identical earlier run left its output and report.

    Returns
    -------
    dict
        One summary row (keys :data:`SUMMARY_COLUMNS`).
    """
    from ..io import write_json
    from .jobs import job_report, prepare_job, save_result

    t0 = time.perf_counter()
    worker = _worker_address()
    sharing = 1  # jobs that run beside this one on its host share its memory
    if isinstance(threads, dict):
        sharing = max(1, threads.get(_host(worker), 1))
        threads = _threads_for(threads)
    output = Path(outdir) / job["output"]
    try:
        digest = job_hash(job)
        old = _previous(output, digest) if resume else None
        if old is not None:
            res = old["result"]
            return _row(job, "skipped", "", res["iterations"], res["energy"],
                        time.perf_counter() - t0, worker)
        spec = job_spec(job)
        for f in spec.input_files():
            if Path(f).resolve() == output.resolve():
                raise InputError(f"{output}: output would overwrite an input file")
        with _limit_threads(threads) as threads, memory_share(sharing):
            prepared = prepare_job(spec)
            res = prepared.solve()
        output.parent.mkdir(parents=True, exist_ok=True)
        warnings = save_result(output, prepared, res)
        wall = time.perf_counter() - t0
        report = job_report(spec, prepared, res, wall,
                            command=_deform_command(job, str(output)),
                            outputs={"mesh": str(output), "report": str(report_path(output))})
        report["batch"] = {"job": job, "job_hash": digest, "worker": worker,
                           "numba_threads": threads, "notes": prepared.notes,
                           "warnings": warnings}
        write_json(report_path(output), report)
        return _row(job, "ok", "", res.iterations, float(res.energy), wall, worker)
    except Exception as e:  # one bad job must not stop the others
        return _row(job, "failed", error_message(e), seconds=time.perf_counter() - t0,
                    worker=worker)


# --------------------------------------------------------------------------- many tasks


def _host(address: str) -> str:
    """Host part of a Dask address: tcp://10.0.0.5:8786 and inproc://10.0.0.5/12/3 -> 10.0.0.5."""
    rest = address.split("://", 1)[-1].split("/", 1)[0]
    return rest.rsplit(":", 1)[0] if rest.count(":") == 1 else rest


def _host_slots(client) -> dict[str, int]:
    """Tasks that can run at once on each host of the cluster."""
    slots: dict[str, int] = {}
    for addr, info in client.scheduler_info()["workers"].items():
        host = _host(addr)
        slots[host] = slots.get(host, 0) + int(info.get("nthreads", 1))
    return slots


class _Progress:
    """Jobs done / failed / rate on stderr: a tqdm bar on a terminal, plain lines otherwise."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.enabled, self.total, self.done, self.failed = enabled, total, 0, 0
        self.t0 = time.perf_counter()
        self.tty = enabled and sys.stderr.isatty()
        self.bar = None
        if self.tty:
            from tqdm import tqdm

            self.bar = tqdm(total=total, file=sys.stderr, unit="job", desc="batch",
                            dynamic_ncols=True)

    def update(self, row: dict) -> None:
        self.done += 1
        self.failed += row["status"] == "failed"
        if self.bar is not None:
            self.bar.set_postfix_str(f"failed {self.failed}", refresh=False)
            self.bar.update(1)
        elif self.enabled:
            rate = 60 * self.done / max(time.perf_counter() - self.t0, 1e-9)
            err = f": {row['error']}" if row["error"] else ""
            print(f"arapkit: [{self.done}/{self.total}] {row['status']} {row['output']} "
                  f"({row['seconds']:.2f} s, {row['worker']}){err}; failed {self.failed}, "
                  f"{rate:.1f} jobs/min", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def write_summary(path: str | os.PathLike, rows: Sequence[dict]) -> None:
    """``summary.csv`` with :data:`SUMMARY_COLUMNS`, atomically."""
    from ..io import atomic_write

    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=SUMMARY_COLUMNS, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: row[k] for k in SUMMARY_COLUMNS})
    atomic_write(path, buf.getvalue())


def _as_table(rows: list[dict]):
    try:
        import pandas as pd
    except ImportError:
        return rows
    return pd.DataFrame(rows, columns=list(SUMMARY_COLUMNS))


def _local_cluster(workers: int | None):
    import logging

    from distributed import Client, LocalCluster

    n = max(1, int(workers or _cores()))
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                           dashboard_address=None, silence_logs=logging.ERROR)
    return cluster, Client(cluster)


def run(
    jobs: str | os.PathLike | Sequence[dict],
    outdir: str | os.PathLike,
    client=None,
    *,
    workers: int | None = None,
    resume: bool = True,
    progress: bool = False,
    on_row: Callable[[dict], None] | None = None,
):
    """Run deformation jobs on a Dask cluster and write ``OUTDIR/summary.csv``.

    Parameters
    ----------
    jobs : path or sequence of dict
        A JSON Lines job file (relative paths are relative to it) or job objects (relative
        paths are relative to the current folder). All are checked before any work.
    outdir : path
        Output folder, created if needed.
    client : distributed.Client, optional
        The cluster to use. Without one a local cluster of ``workers`` processes (default:
        the core count) is started and stopped here.
    workers : int, optional
        Size of the local cluster (ignored with ``client``).
    resume : bool
        Skip jobs whose output and report from an identical run exist.
    progress : bool
        Progress on stderr.
    on_row : callable, optional
        Called with each summary row as its job finishes.

    Returns
    -------
    list of dict, or pandas.DataFrame when pandas is installed
        One row per job in job order, keys :data:`SUMMARY_COLUMNS`.

    Raises
    ------
    InputError
        A malformed job list (nothing is written then), or Dask missing.
    """
    require_dask()
    if isinstance(jobs, (str, os.PathLike)):
        todo = load_jobs(jobs)
    else:
        todo = [normalise_job(j, Path.cwd(), f"job {i}") for i, j in enumerate(jobs)]
        outs = [os.path.normpath(j["output"]) for j in todo]
        if len(set(outs)) != len(outs):
            raise InputError("jobs: two jobs write the same output")
    outdir = Path(outdir)
    _check_outdir(outdir)
    from distributed import as_completed

    own = client is None
    cluster = None
    if own:
        cluster, client = _local_cluster(workers)
    try:
        outdir.mkdir(parents=True, exist_ok=True)
        slots = _host_slots(client)
        futures = [client.submit(run_job, job, str(outdir.resolve()), slots, resume, pure=False)
                   for job in todo]
        index = {f.key: i for i, f in enumerate(futures)}
        rows: list[dict | None] = [None] * len(todo)
        bar = _Progress(len(todo), progress)
        try:
            for fut in as_completed(futures):
                try:
                    row = fut.result()
                except Exception as e:  # the task itself died (worker lost ...)
                    row = _row(todo[index[fut.key]], "failed", error_message(e))
                rows[index[fut.key]] = row
                bar.update(row)
                if on_row is not None:
                    on_row(row)
        finally:
            bar.close()
        done = [r for r in rows if r is not None]
        write_summary(outdir / "summary.csv", done)
    finally:
        if own:
            client.close()
            cluster.close()
    return _as_table(done)


def _cores() -> int:
    """Cores this process may use (its CPU affinity where the platform has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # macOS, Windows
        return os.cpu_count() or 1


def _threads_for(slots: dict[str, int]) -> int:
    """Numba threads for a task on this worker: the host's cores over its worker threads."""
    return max(1, _cores() // max(1, slots.get(_host(_worker_address()), 1)))


def _limited_call(func: Callable, slots: dict[str, int], item: Any) -> Any:
    with _limit_threads(_threads_for(slots)):
        return func(item)


def dask_map(client) -> Callable:
    """``map(func, items)`` running one task per item on ``client``'s cluster, in order.

    For :func:`arapkit.learn.fit.learn_rings_sequences` (one energy table per sequence). Each
    task limits numba to the host's cores over its worker threads, as batch jobs do.

    Examples
    --------
    >>> from distributed import Client  # doctest: +SKIP
    >>> with Client(processes=False) as c:  # doctest: +SKIP
    ...     list(dask_map(c)(abs, [-1, 2]))
    [1, 2]
    """

    def _map(func: Callable, items: Iterable) -> list:
        task = partial(_limited_call, func, _host_slots(client))
        return client.gather(client.map(task, list(items), pure=False))

    return _map
