"""Many deformation jobs on a Dask cluster: a local one by default, or any existing one.

A job is one ``arapkit deform`` written as a JSON object (see :data:`JOB_KEYS`); a job list
is a JSON Lines file, one job per line. :func:`run` sends every job to the cluster as one
task; each task writes the deformed mesh and its JSON report (the ``deform`` report plus a
``batch`` section) atomically and returns one row of the summary. One bad job never stops
the others: its row says ``failed`` with the one-line message ``deform`` would print.

Every task runs the same library code as ``arapkit deform`` (:mod:`arapkit.workflows.jobs`) with the
solver limited to ``cores // (tasks running on that host)`` numba threads, so N workers do
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
import hashlib
import io
import json
import math
import os
import sys
import time
import zlib
from collections.abc import Callable, Iterable, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError, worded_for
from ..mesh.model import bounding_box_diagonal
from ..mesh.weights import DEFAULT_WEIGHTS, WEIGHT_KINDS
from ..methods.deformer import check_method
from ..validate import read_input
from .jobs import DEFAULT_ENERGY, ENERGIES, DeformJob

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
    "require_dask",
    "run",
    "run_job",
    "write_jobs",
]

#: Keys a job object may have (``mesh``, ``handles`` and ``output`` are required).
JOB_KEYS = ("mesh", "handles", "transform", "rings", "rings_file", "weights", "energy",
            "sr_alpha", "nodes", "weld", "tol", "max_iter", "init", "accelerate", "output")
#: Columns of ``summary.csv``, in order.
SUMMARY_COLUMNS = ("output", "status", "error", "iterations", "energy", "seconds", "worker")
INSTALL_HINT = "arapkit batch needs dask and distributed: pip install 'arapkit[batch]'"
_INITS = ("identity", "laplacian")
_DEFAULTS: dict[str, Any] = {"transform": None, "rings": 1, "rings_file": None,
                             "weights": DEFAULT_WEIGHTS, "energy": DEFAULT_ENERGY, "tol": 1e-3,
                             "max_iter": 1000, "init": "identity", "accelerate": False,
                             "sr_alpha": None, "nodes": None, "weld": None}


def require_dask() -> None:
    """Raise :class:`InputError` with :data:`INSTALL_HINT` when Dask is not installed."""
    try:
        import dask  # noqa: F401
        import distributed  # noqa: F401
    except ImportError:
        raise InputError(INSTALL_HINT) from None


# --------------------------------------------------------------------------- job lists


def _is_int(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _path(value: Any, key: str, base: Path, where: str) -> str:
    if not isinstance(value, str) or not value:
        raise InputError(f"{where}: '{key}' must be a file path (a non-empty string)")
    p = Path(value).expanduser()
    return str(p if p.is_absolute() else base / p)


def normalise_job(obj: Any, base: str | os.PathLike = ".", where: str = "job") -> dict:
    """Check one job object and fill in its defaults; input paths become absolute.

    Parameters
    ----------
    obj : dict
        The job, with keys from :data:`JOB_KEYS`.
    base : path
        Folder that relative input paths are relative to (the job file's).
    where : str
        Prefix of error messages (``jobs.jsonl:3``).

    Returns
    -------
    dict
        Every key of :data:`JOB_KEYS`; ``output`` stays relative to the output folder.

    Raises
    ------
    InputError
        Unknown or missing keys, wrong types, values out of range.

    Examples
    --------
    >>> job = normalise_job({"mesh": "/m.off", "handles": "/h.json", "output": "a.ply"})
    >>> job["rings"], job["tol"], job["output"]
    (1, 0.001, 'a.ply')
    >>> normalise_job({"mesh": "/m.off", "handles": "/h.json", "output": "a.ply", "r": 2})
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: job: unknown key 'r' (known: mesh, handles, transform, ...)
    """
    from ..io import mesh_format

    if not isinstance(obj, dict):
        raise InputError(f"{where}: a job must be a JSON object, got {type(obj).__name__}")
    unknown = [k for k in obj if k not in JOB_KEYS]
    if unknown:
        raise InputError(f"{where}: unknown key {unknown[0]!r} (known: {', '.join(JOB_KEYS)})")
    for key in ("mesh", "handles", "output"):
        if key not in obj:
            raise InputError(f"{where}: missing key '{key}'")
    base = Path(base)
    job = {**_DEFAULTS, **obj}
    job["mesh"] = _path(job["mesh"], "mesh", base, where)
    if isinstance(job["handles"], (list, dict)):
        pass  # inline handle groups, checked against the mesh by the task
    else:
        job["handles"] = _path(job["handles"], "handles", base, where)
    for key in ("transform", "rings_file"):
        if job[key] is not None:
            job[key] = _path(job[key], key, base, where)
    if "rings" in obj and "rings_file" in obj:
        raise InputError(f"{where}: give 'rings' or 'rings_file', not both")
    if not _is_int(job["rings"]) or job["rings"] < 1:
        raise InputError(f"{where}: 'rings' must be an integer >= 1, "
                         f"got {json.dumps(job['rings'])}")
    if job["weights"] not in WEIGHT_KINDS:
        raise InputError(f"{where}: 'weights' must be one of {', '.join(WEIGHT_KINDS)}, "
                         f"got {json.dumps(job['weights'])}")
    if not isinstance(job["energy"], str):
        raise InputError(f"{where}: 'energy' must be a string, got {json.dumps(job['energy'])}")
    if job["energy"] not in ENERGIES:
        raise InputError(f"{where}: energy {job['energy']} is not available in this build "
                         f"(available: {', '.join(ENERGIES)})")
    try:  # the method's own options, by the rule the library and deform use
        check_method(job["energy"], job["sr_alpha"], job["nodes"])
    except InputError as e:
        raise InputError(f"{where}: {e}") from None
    if job["weld"] is False:
        job["weld"] = None
    if job["weld"] is not None:
        if job["weld"] is True:
            from ..mesh.welding import WELD_TOL

            job["weld"] = WELD_TOL
        if not _is_number(job["weld"]) or not 0 <= job["weld"] < 1:
            raise InputError(f"{where}: 'weld' must be true or a tolerance in [0, 1) (relative "
                             f"to the bounding-box diagonal), got {json.dumps(job['weld'])}")
        job["weld"] = float(job["weld"])
    if not _is_number(job["tol"]) or job["tol"] <= 0:
        raise InputError(f"{where}: 'tol' must be a positive number, got {json.dumps(job['tol'])}")
    job["tol"] = float(job["tol"])
    if not _is_int(job["max_iter"]) or job["max_iter"] < 1:
        raise InputError(f"{where}: 'max_iter' must be an integer >= 1, "
                         f"got {json.dumps(job['max_iter'])}")
    if job["init"] not in _INITS:
        raise InputError(f"{where}: 'init' must be identity or laplacian, "
                         f"got {json.dumps(job['init'])}")
    if not isinstance(job["accelerate"], bool):
        raise InputError(f"{where}: 'accelerate' must be true or false")
    out = job["output"]
    if not isinstance(out, str) or not out:
        raise InputError(f"{where}: 'output' must be a file name inside the output folder")
    parts = Path(out).parts
    if Path(out).is_absolute() or ".." in parts or out.endswith(("/", os.sep)):
        raise InputError(f"{where}: 'output' {out!r} must be a file name inside the output "
                         "folder (no absolute path, no '..')")
    try:
        mesh_format(out)
    except InputError as e:
        raise InputError(f"{where}: {e}") from None
    return {k: job[k] for k in JOB_KEYS}


def job_spec(job: dict) -> DeformJob:
    """The library's :class:`~arapkit.workflows.jobs.DeformJob` of a checked job (without
    ``output``)."""
    return DeformJob(**{k: job[k] for k in JOB_KEYS if k != "output"})


def dry_run(path: str | os.PathLike) -> list[str]:
    """Resolve every job's mesh and handles, solve nothing: one line per job and group.

    A job whose inputs cannot be read gets a ``failed: MESSAGE`` line (the others go on),
    as it would in a real run. Needs no Dask.
    """
    from ..cli.deform import describe_groups
    from .jobs import load_job_inputs

    lines = []
    for i, job in enumerate(load_jobs(path), 1):
        try:
            inputs = load_job_inputs(job_spec(job))
        except (InputError, OSError) as exc:
            lines.append(f"job {i} -> {job['output']}: failed: {_one_line(exc)}")
            continue
        hs = inputs.handles
        lines.append(f"job {i} -> {job['output']}: {job['mesh']} ({inputs.mesh.n_vertices} "
                     f"vertices), {len(hs.indices)} handle vertices in {len(hs.groups)} "
                     "group(s)")
        lines += [f"  {line}" for line in describe_groups(inputs.mesh.vertices, hs)]
    return lines


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


def load_jobs(path: str | os.PathLike) -> list[dict]:
    """Read and check a JSON Lines job file (blank lines are ignored).

    Raises
    ------
    InputError
        ``FILE:LINE: ...`` for the first malformed line, duplicate output, or unreadable file.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "jobs.jsonl"
    >>> _ = p.write_text('{"mesh": "a.off", "handles": "h.json", "output": "a.ply"}\\n{oops\\n')
    >>> load_jobs(p)
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: ...jobs.jsonl:2: not valid JSON (Expecting property name \
enclosed in double quotes at column 2)
    """
    path = Path(path)
    try:
        text = read_input(path, "job files").decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file") from None
    base = path.resolve().parent
    jobs, seen = [], {}
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        where = f"{path}:{number}"
        try:
            obj = json.loads(line)
        except json.JSONDecodeError as e:
            raise InputError(f"{where}: not valid JSON ({e.msg} at column {e.colno})") from None
        job = normalise_job(obj, base, where)
        key = os.path.normpath(job["output"])
        if key in seen:
            raise InputError(f"{where}: output {job['output']!r} is already written by line "
                             f"{seen[key]}")
        seen[key] = number
        jobs.append(job)
    if not jobs:
        raise InputError(f"{path}: holds no jobs")
    return jobs


def write_jobs(path: str | os.PathLike, jobs: Iterable[dict]) -> None:
    """Write jobs as JSON Lines, atomically."""
    from ..io import atomic_write, to_jsonable

    atomic_write(path, "".join(json.dumps(to_jsonable(j)) + "\n" for j in jobs))


def _file_stamp(path: str) -> list:
    try:
        st = os.stat(path)
    except OSError:
        return [path, None, None]
    return [path, st.st_size, st.st_mtime_ns]


def job_hash(job: dict) -> str:
    """SHA-256 of a normalised job and of the size and mtime of each of its input files.

    Examples
    --------
    >>> a = normalise_job({"mesh": "/no/m.off", "handles": "/no/h.json", "output": "a.ply"})
    >>> job_hash(a) == job_hash(dict(a)), job_hash(a) == job_hash({**a, "rings": 2})
    (True, False)
    """
    files = job_spec(job).input_files()
    blob = json.dumps({"job": job, "files": [_file_stamp(f) for f in files]}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


# --------------------------------------------------------------------------- one task


def _one_line(exc: BaseException) -> str:
    """The message ``arapkit deform`` would print for ``exc`` (see :func:`arapkit.cli.main`)."""
    if isinstance(exc, InputError):
        msg = worded_for(exc.args[0] if exc.args else exc, "cli")
    elif isinstance(exc, FileNotFoundError):
        msg = f"{exc.filename}: file not found"
    elif isinstance(exc, IsADirectoryError):
        msg = f"{exc.filename}: is a folder, expected a file"
    elif isinstance(exc, PermissionError):
        msg = f"{exc.filename}: permission denied"
    else:
        msg = f"internal error ({type(exc).__name__}: {exc}); please report this"
    return " ".join(msg.split())


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
    cmd += ["--weights", job["weights"], "--energy", job["energy"], "--tol", repr(job["tol"]),
            "--max-iter", str(job["max_iter"]), "--init", job["init"]]
    # the method's own options and welding, as given (deform fills in the same defaults)
    for key, flag in (("sr_alpha", "--sr-alpha"), ("nodes", "--nodes"), ("weld", "--weld")):
        if job[key] is not None:
            cmd.append(f"{flag}={job[key]}")
    if job["accelerate"]:
        cmd.append("--accelerate")
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


def _limit_threads(threads: int) -> int:
    import numba

    threads = max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS))
    # per calling thread in numba, so in-process workers do not disturb each other
    numba.set_num_threads(threads)
    return threads


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
    if isinstance(threads, dict):
        threads = _threads_for(threads)
    output = Path(outdir) / job["output"]
    try:
        digest = job_hash(job)
        old = _previous(output, digest) if resume else None
        if old is not None:
            res = old["result"]
            return _row(job, "skipped", "", res["iterations"], res["energy"],
                        time.perf_counter() - t0, worker)
        threads = _limit_threads(threads)
        spec = job_spec(job)
        for f in spec.input_files():
            if Path(f).resolve() == output.resolve():
                raise InputError(f"{output}: output would overwrite an input file")
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
        return _row(job, "failed", _one_line(e), seconds=time.perf_counter() - t0,
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
                    row = _row(todo[index[fut.key]], "failed", _one_line(e))
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
    _limit_threads(_threads_for(slots))
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


# --------------------------------------------------------------------------- augmentation


def _disjoint_groups(V: np.ndarray, a: int, b: int, k: int) -> int:
    """Largest k' <= k whose k'-nearest sets around vertices a and b do not overlap."""
    da = np.linalg.norm(V - V[a], axis=1)
    db = np.linalg.norm(V - V[b], axis=1)
    while k > 1:
        sa = set(np.argpartition(da, k - 1)[:k].tolist())
        sb = set(np.argpartition(db, k - 1)[:k].tolist())
        if not sa & sb:
            break
        k //= 2
    return k


def _r(x, digits: int = 6) -> list[float] | float:
    return [round(float(v), digits) for v in x] if np.ndim(x) else round(float(x), digits)


def augment_jobs(meshes: Sequence[str | os.PathLike], n: int, seed: int = 0,
                 max_rings: int = 3) -> list[dict]:
    """``n`` random deformation jobs per mesh, reproducible from ``seed``.

    Each job fixes the vertices nearest a random vertex ``a`` and moves those nearest a
    vertex ``b`` drawn from the 10% of vertices farthest from ``a``: a rotation about a
    random axis through ``b`` by up to 45 degrees, then a translation of up to 20% of the
    bounding-box diagonal. Groups have ``max(3, n_vertices // 50)`` vertices (fewer if the
    two would overlap); r is drawn from ``1..max_rings``. A mesh's jobs depend only on
    ``seed``, its file name and the sample number, not on the other meshes.

    Returns
    -------
    list of dict
        Jobs with inline handle groups and outputs ``STEM-0000.ply`` ...

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from arapkit.io import save_mesh
    >>> from arapkit.mesh.shapes import bar
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "bar.off"
    >>> m = bar(); _ = save_mesh(p, m.vertices, m.faces)
    >>> jobs = augment_jobs([p], 2, seed=1)
    >>> [j["output"] for j in jobs], jobs == augment_jobs([p], 2, seed=1)
    (['bar-0000.ply', 'bar-0001.ply'], True)
    """
    from ..cli.common import load_mesh_checked

    if not _is_int(n) or n < 1:
        raise InputError(f"--augment must be an integer >= 1, got {n}")
    jobs, stems = [], set()
    for path in meshes:
        path = os.path.abspath(os.fspath(path))
        name = os.path.basename(path)
        stem = name.split(".")[0] or "mesh"
        while stem in stems:  # two meshes named alike in different folders
            stem += "_"
        stems.add(stem)
        V = load_mesh_checked(path).vertices
        nv = len(V)
        if nv < 2:
            raise InputError(f"{path}: needs at least two vertices to place handles")
        diag = bounding_box_diagonal(V)
        rng = np.random.default_rng([int(seed), zlib.crc32(name.encode())])
        for s in range(n):
            a = int(rng.integers(nv))
            dist = np.linalg.norm(V - V[a], axis=1)
            far = np.argsort(dist, kind="stable")[-max(1, nv // 10):]
            b = int(rng.choice(far))
            k = _disjoint_groups(V, a, b, min(max(3, nv // 50), nv // 2 or 1))
            axis = rng.normal(size=3)
            axis /= np.linalg.norm(axis)
            degrees = rng.uniform(-45.0, 45.0)
            move = rng.normal(size=3)
            move *= rng.uniform(0.0, 0.2) * diag / np.linalg.norm(move)
            rings = int(rng.integers(1, max_rings + 1))
            handles = [
                {"name": "fixed", "nearest": {"point": _r(V[a]), "k": k}},
                {"name": "moved", "nearest": {"point": _r(V[b]), "k": k},
                 "rotate": {"axis": _r(axis), "degrees": _r(degrees, 3), "center": _r(V[b])},
                 "translate": _r(move)},
            ]
            jobs.append({"mesh": path, "handles": handles, "rings": rings,
                         "output": f"{stem}-{s:04d}.ply"})
    return jobs
