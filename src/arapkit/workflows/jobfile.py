"""Job lists: the JSON form of one deformation job, JSON Lines files of them, job hashes.

A job is one ``arapkit deform`` written as a JSON object (see :data:`JOB_KEYS`). Every
field is checked by the rule the library applies to the same parameter
(:mod:`arapkit.validate`, the deformer's init names, the method table), and a field left
out takes the library's own default (:data:`arapkit.workflows.jobs.JOB_DEFAULTS`), so a job
solves exactly as ``arapkit deform`` or :class:`arapkit.Deformer` would.

Examples
--------
>>> job = normalise_job({"mesh": "/m.off", "handles": "/h.json", "output": "a.ply", "tol": 0})
>>> job["tol"], job["max_iter"], job_spec(job).init
(0.0, 1000, 'identity')
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from .. import validate
from ..arap.domains import all_weight_kinds
from ..errors import InputError
from ..mesh.cloud import counted, element_nouns
from ..methods.deformer import INITS, check_method
from ..methods.registry import method, methods
from ..validate import iteration_cap, read_input, ring_size, tolerance
from .jobs import (
    ENERGIES,
    JOB_DEFAULTS,
    DeformJob,
    describe_groups,
    error_message,
    load_job_inputs,
)

__all__ = ["JOB_KEYS", "dry_run", "job_hash", "job_spec", "load_jobs", "normalise_job",
           "write_jobs"]

#: Keys a job object may have (``mesh``, ``handles`` and ``output`` are required).
JOB_KEYS = ("mesh", "handles", "transform", "rings", "rings_file", "weights", "energy",
            "sr_alpha", "nodes", "smooth_lambda", "weld", "tol", "max_iter", "init",
            "accelerate", "output", "neighbours", "radius", "groups")
#: every optional key of :data:`JOB_KEYS` and its default
_DEFAULTS = {k: JOB_DEFAULTS[k] for k in JOB_KEYS if k in JOB_DEFAULTS}


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _path(value: Any, key: str, base: Path, where: str) -> str:
    if not isinstance(value, str) or not value:
        raise InputError(f"{where}: '{key}' must be a file path (a non-empty string)")
    p = Path(value).expanduser()
    return str(p if p.is_absolute() else base / p)


def _check_method(job: dict, where: str) -> None:
    """The method name and its own options, by the rule the library and deform use."""
    if not isinstance(job["energy"], str):
        raise InputError(f"{where}: 'energy' must be a string, got {json.dumps(job['energy'])}")
    if job["energy"] not in ENERGIES:
        raise InputError(f"{where}: energy {job['energy']} is not available in this build "
                         f"(available: {', '.join(ENERGIES)})")
    try:
        check_method(job["energy"], job["sr_alpha"], job["nodes"],
                     smooth_lambda=job["smooth_lambda"])
    except InputError as e:
        raise InputError(f"{where}: {e}") from None
    if job.get("groups") is not None and not method(job["energy"]).groups:
        takes = ", ".join(m.name for m in methods("batch") if m.groups)
        raise InputError(f"{where}: 'groups': energy {job['energy']} takes no vertex groups "
                         f"(these methods do: {takes})")


def _check_weld(value: Any, where: str) -> float | None:
    """``weld``: false/absent (no welding), true (the default tolerance) or a tolerance."""
    if value is None or value is False:
        return None
    if value is True:
        from ..mesh.welding import WELD_TOL

        value = WELD_TOL
    if not _is_number(value) or not 0 <= value < 1:
        raise InputError(f"{where}: 'weld' must be true or a tolerance in [0, 1) (relative "
                         f"to the bounding-box diagonal), got {json.dumps(value)}")
    return float(value)


def _check_graph(job: dict, where: str) -> None:
    """``neighbours`` / ``radius``: a point cloud's graph (not both)."""
    from ..mesh.neighbours import MAX_NEIGHBOURS

    if job["neighbours"] is not None and job["radius"] is not None:
        raise InputError(f"{where}: give 'neighbours' or 'radius', not both")
    if job["neighbours"] is not None:
        job["neighbours"] = validate.integer(job["neighbours"], f"{where}: 'neighbours'",
                                             lo=1, hi=MAX_NEIGHBOURS)
    if job["radius"] is not None:
        job["radius"] = validate.number(job["radius"], f"{where}: 'radius'", lo=0.0,
                                        lo_open=True)


def _check_output(out: Any, where: str, job_mesh: str) -> None:
    """``output``: a mesh (or, for a point cloud, a cloud) file name inside the output
    folder."""
    from ..io.clouds import check_shape_output

    if not isinstance(out, str) or not out:
        raise InputError(f"{where}: 'output' must be a file name inside the output folder")
    parts = Path(out).parts
    if Path(out).is_absolute() or ".." in parts or out.endswith(("/", os.sep)):
        raise InputError(f"{where}: 'output' {out!r} must be a file name inside the output "
                         "folder (no absolute path, no '..')")
    try:
        check_shape_output(out, job_mesh)
    except InputError as e:
        raise InputError(f"{where}: {e}") from None


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
    >>> normalise_job({"mesh": "/m.off", "handles": "/h.json", "output": "a.ply", "rings": 101})
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: job: 'rings': must be at most 100, got 101
    """
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
    if not isinstance(job["handles"], (list, dict)):  # inline groups: checked by the task
        job["handles"] = _path(job["handles"], "handles", base, where)
    for key in ("transform", "rings_file"):
        if job[key] is not None:
            job[key] = _path(job[key], key, base, where)
    if job["groups"] is not None and not isinstance(job["groups"], (list, dict)):
        job["groups"] = _path(job["groups"], "groups", base, where)  # inline: as handles
    if "rings" in obj and "rings_file" in obj:
        raise InputError(f"{where}: give 'rings' or 'rings_file', not both")
    # the rules of the library's own parameters (arapkit.validate), with the job's location
    job["rings"] = ring_size(job["rings"], f"{where}: 'rings'")
    # null: the shape's own default (cotan-clamped on a mesh, gaussian on a point cloud)
    if job["weights"] is not None and job["weights"] not in all_weight_kinds():
        raise InputError(f"{where}: 'weights' must be one of {', '.join(all_weight_kinds())}, "
                         f"got {json.dumps(job['weights'])}")
    _check_method(job, where)
    job["weld"] = _check_weld(job["weld"], where)
    job["tol"] = tolerance(job["tol"], f"{where}: 'tol'")
    job["max_iter"] = iteration_cap(job["max_iter"], f"{where}: 'max_iter'")
    if job["init"] not in INITS:
        raise InputError(f"{where}: 'init' must be {' or '.join(INITS)}, "
                         f"got {json.dumps(job['init'])}")
    if job["accelerate"] is not None and not isinstance(job["accelerate"], bool):
        raise InputError(f"{where}: 'accelerate' must be true or false")
    _check_graph(job, where)
    _check_output(job["output"], where, job["mesh"])
    # a job without groups has no "groups" key: its hash (and a resumed run) stays as it was
    return {k: job[k] for k in JOB_KEYS if k != "groups" or job[k] is not None}


def job_spec(job: dict) -> DeformJob:
    """The library's :class:`~arapkit.workflows.jobs.DeformJob` of a checked job (without
    ``output``)."""
    return DeformJob(**{k: job[k] for k in JOB_KEYS if k != "output" and k in job})


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


def dry_run(path: str | os.PathLike) -> list[str]:
    """Resolve every job's mesh and handles, solve nothing: one line per job and group.

    A job whose inputs cannot be read gets a ``failed: MESSAGE`` line (the others go on),
    as it would in a real run. Needs no Dask.
    """
    lines = []
    for i, job in enumerate(load_jobs(path), 1):
        try:
            inputs = load_job_inputs(job_spec(job))
        except (InputError, OSError) as exc:
            lines.append(f"job {i} -> {job['output']}: failed: {error_message(exc)}")
            continue
        hs = inputs.handles
        cloud = inputs.mesh.faces is None
        lines.append(f"job {i} -> {job['output']}: {job['mesh']} "
                     f"({counted(inputs.mesh.n_vertices, points=cloud)}), "
                     f"{len(hs.indices)} handle {element_nouns(cloud)[1]} in "
                     f"{len(hs.groups)} group(s)")
        lines += [f"  {line}" for line in describe_groups(inputs.mesh.vertices, hs,
                                                          points=cloud)]
        if inputs.groups is not None:
            lines.append(f"  vertex groups: {inputs.groups.summary(points=cloud)}")
    return lines
