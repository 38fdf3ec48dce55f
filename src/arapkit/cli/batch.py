"""``arapkit batch``: run many deformation jobs on a Dask cluster (local or existing).

Examples
--------
::

    arapkit batch jobs.jsonl -o results --workers 2
    arapkit batch jobs.jsonl -o results --scheduler tcp://10.0.0.5:8786
    arapkit batch --augment 20 --seed 1 meshes/ -o dataset
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from arapkit.cli.common import add_example_epilog, positive_int
from arapkit.errors import InputError

__all__ = ["add_parser", "run"]

EXAMPLES = [
    "arapkit batch jobs.jsonl -o results",
    "arapkit batch jobs.jsonl -o results --workers 2 --no-resume",
    "arapkit batch jobs.jsonl -o /shared/results --scheduler tcp://10.0.0.5:8786",
    "arapkit batch --augment 20 --seed 1 meshes/ -o dataset",
]


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``batch`` with its options."""
    p = subparsers.add_parser(
        "batch",
        help="run many deformation jobs (JSON Lines) on a local or existing Dask cluster",
        description="Run the deformation jobs of JOBS (JSON Lines, one 'arapkit deform' per "
        "line; keys in docs/batch.md) on a Dask cluster. Each job writes its mesh and a JSON "
        "report into OUTDIR; OUTDIR/summary.csv lists every job. Exit status 0 when every job "
        "is ok or skipped, 3 when any failed, 2 for a malformed job file. With --augment N, "
        "the inputs are meshes (files, folders or globs) and N random jobs per mesh are "
        "written to OUTDIR/jobs.jsonl and run. Needs dask and distributed "
        "(pip install 'arapkit[batch]').",
        **add_example_epilog(EXAMPLES),
    )
    p.add_argument("inputs", nargs="+", metavar="JOBS",
                   help="JSON Lines job file; with --augment: meshes, folders or globs")
    p.add_argument("-o", "--outdir", required=True, metavar="OUTDIR",
                   help="folder for outputs, reports and summary.csv (created if needed)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on this existing Dask cluster (tcp://HOST:PORT); paths must be "
                   "valid on its workers")
    p.add_argument("--workers", type=positive_int, metavar="N",
                   help="processes of the local cluster (default: the core count)")
    p.add_argument("--no-resume", dest="resume", action="store_false",
                   help="redo every job, also those whose output and report are up to date")
    p.add_argument("--augment", type=positive_int, metavar="N",
                   help="generate N random handle placements and moves per input mesh")
    p.add_argument("--seed", type=int, default=0, metavar="S",
                   help="random seed of --augment (default 0)")
    p.add_argument("--dry-run", action="store_true",
                   help="no solve (and no Dask needed): check the job file and print, per job, "
                   "each handle group's vertex count and motion")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")
    return p


def _jobs(args: argparse.Namespace):
    """The job file to run: the one given, or the one --augment writes into OUTDIR."""
    from arapkit.workflows.batch import augment_jobs, write_jobs

    if args.augment is None:
        if len(args.inputs) != 1:
            raise InputError(f"give one job file (got {len(args.inputs)}); meshes are inputs "
                             "only with --augment N")
        return args.inputs[0]
    from arapkit.workflows.learning import expand_frames

    meshes = expand_frames(args.inputs)
    bad = [m for m in meshes if m.lower().endswith((".jsonl", ".json", ".npz"))]
    if bad:
        raise InputError(f"{bad[0]}: --augment takes meshes, not job or data files")
    jobs = augment_jobs(meshes, args.augment, args.seed)
    outdir = Path(args.outdir)
    if outdir.exists() and not outdir.is_dir():
        raise InputError(f"{outdir}: output folder is a file")
    outdir.mkdir(parents=True, exist_ok=True)
    path = outdir / "jobs.jsonl"
    write_jobs(path, jobs)
    if not args.quiet:
        print(f"arapkit: wrote {len(jobs)} jobs to {path} (seed {args.seed})", file=sys.stderr)
    return path


def run(args: argparse.Namespace) -> int:
    """Execute ``arapkit batch``; returns 0 (all ok or skipped) or 3 (some failed)."""
    from arapkit.workflows import batch

    if args.dry_run:
        for line in batch.dry_run(_jobs(args)):
            print(line)
        return 0
    batch.require_dask()
    if args.scheduler and args.workers:
        raise InputError("--workers sizes the local cluster; it cannot be used with --scheduler")
    jobs = _jobs(args)
    # check the job file before connecting: a malformed one writes nothing
    batch.load_jobs(jobs)
    client = None
    if args.scheduler:
        from distributed import Client

        try:
            client = Client(args.scheduler, timeout=30)
        except (OSError, TimeoutError, ValueError) as e:
            raise InputError(f"{args.scheduler}: cannot reach the Dask scheduler "
                             f"({type(e).__name__}: {e})") from None
    try:
        rows = batch.run(jobs, args.outdir, client, workers=args.workers, resume=args.resume,
                         progress=not args.quiet)
    finally:
        if client is not None:
            client.close()
    if not isinstance(rows, list):  # a DataFrame
        rows = rows.to_dict("records")
    counts = {s: sum(r["status"] == s for r in rows) for s in ("ok", "skipped", "failed")}
    print(f"jobs: {len(rows)} (ok {counts['ok']}, skipped {counts['skipped']}, "
          f"failed {counts['failed']})")
    print(f"summary: {os.path.join(args.outdir, 'summary.csv')}")
    return 3 if counts["failed"] else 0
