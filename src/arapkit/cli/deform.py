"""``arapkit deform``: deform one mesh with handles and a (possibly varying) rigidity r.

Examples
--------
::

    arapkit deform bar.off --handles bend.json --rings 4 -o bent.ply --figure bent.png
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from arapkit.cli.common import (
    Progress,
    add_example_epilog,
    iteration_cap,
    load_mesh_checked,
    note,
    ring_size,
    rings_summary,
    tolerance,
)
from arapkit.errors import InputError
from arapkit.weights import DEFAULT_WEIGHTS, WEIGHT_KINDS

__all__ = ["add_parser", "run"]

EXAMPLES = [
    "arapkit deform cow.off --handles cow.json -o cow-bent.ply",
    "arapkit deform bar.off --handles bar.json --rings 6 -o bar6.ply --figure bar6.png",
    "arapkit deform bar.off --handles bar.sel --transform bar.def --rings-file r.txt -o out.off",
    "arapkit deform bar.off --handles bar.json -o out.ply --report - --quiet | jq .result",
]
_FIGURE_FORMATS = ("png", "pdf", "svg", "jpg", "jpeg")


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``deform`` with its options."""
    p = subparsers.add_parser(
        "deform",
        help="deform a mesh so that its handles reach their targets",
        description="Deform MESH with r-ring ARAP so that the handle vertices reach their "
        "targets. Results (a short summary, or the JSON report with --report -) go to "
        "stdout; progress and notes go to stderr.",
        **add_example_epilog(EXAMPLES),
    )
    p.add_argument("mesh", metavar="MESH", help="input mesh (OFF, OBJ, PLY, STL; may be .gz)")
    p.add_argument(
        "--handles",
        "-H",
        required=True,
        metavar="FILE",
        help="handle groups (.json, schema in README) or a per-vertex status file (.sel)",
    )
    p.add_argument(
        "--transform",
        "-T",
        metavar="FILE",
        help="4x4 matrix (.def) moving the status-2 vertices of a .sel file "
        "(default: the .def next to the .sel)",
    )
    rig = p.add_mutually_exclusive_group()
    rig.add_argument(
        "--rings",
        "-r",
        type=ring_size,
        default=1,
        metavar="N",
        help="ring size r for every vertex; 1 is standard ARAP, larger is stiffer (default 1)",
    )
    rig.add_argument(
        "--rings-file",
        metavar="FILE",
        help="per-vertex r: text (one integer per line), .npy, or PLY vertex property 'rings'",
    )
    kinds = WEIGHT_KINDS
    p.add_argument(
        "--weights",
        default=DEFAULT_WEIGHTS,
        choices=kinds,
        help=f"edge weights: {', '.join(kinds)} (default {DEFAULT_WEIGHTS})",
    )
    p.add_argument(
        "--tol",
        type=tolerance,
        default=1e-3,
        help="stop when the relative energy decrease is below this (default 1e-3)",
    )
    p.add_argument(
        "--max-iter",
        type=iteration_cap,
        default=1000,
        metavar="N",
        help="iteration cap (default 1000)",
    )
    p.add_argument(
        "--init",
        choices=("identity", "laplacian"),
        default="identity",
        help="start from the rest shape (paper) or Laplacian editing (default identity)",
    )
    p.add_argument(
        "--accelerate",
        action="store_true",
        help="Anderson acceleration with an energy safeguard: fewer, costlier iterations "
        "(pays on large meshes; see docs/benchmarks.md)",
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="OUT",
        help="deformed mesh; format from the extension (.ply keeps energy and rings)",
    )
    p.add_argument(
        "--report",
        metavar="FILE",
        help="JSON report (parameters, timings, energy history); '-' for stdout",
    )
    p.add_argument("--figure", metavar="FILE", help="summary figure (.png, .pdf or .svg)")
    p.add_argument("--force", action="store_true", help="allow overwriting an input file")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar or notes")
    return p


def _check_outputs(args: argparse.Namespace) -> None:
    """Fail fast, before loading or solving, on any output that cannot be written."""
    from arapkit.fileio import check_output_path, mesh_format

    inputs = [args.mesh, args.handles, args.transform, args.rings_file]
    check_output_path(args.output, inputs, args.force, "output")
    mesh_format(args.output)
    outs = [Path(args.output).resolve()]
    if args.report and args.report != "-":
        check_output_path(args.report, inputs, args.force, "report")
        outs.append(Path(args.report).resolve())
    if args.figure:
        check_output_path(args.figure, inputs, args.force, "figure")
        ext = Path(args.figure).suffix.lower().lstrip(".")
        if ext not in _FIGURE_FORMATS:
            raise InputError(f"{args.figure}: unsupported figure format (use .png, .pdf or .svg)")
        outs.append(Path(args.figure).resolve())
    if len(set(outs)) != len(outs):
        raise InputError(f"{args.output}: output, report and figure must be different files")


def _rings(args: argparse.Namespace, n_vertices: int) -> np.ndarray | int:
    if args.rings_file:
        from arapkit.handles import load_rings

        return load_rings(args.rings_file, n_vertices)
    return int(args.rings)


def _report(args, mesh, hs, rings, res, wall_s: float) -> dict[str, Any]:
    from arapkit.cli import _version

    r = np.broadcast_to(np.asarray(rings), (mesh.n_vertices,))
    return {
        "arapkit_version": _version(),
        "command": ["arapkit", *getattr(args, "_argv", sys.argv[1:])],
        "input": {
            "mesh": args.mesh,
            "n_vertices": mesh.n_vertices,
            "n_faces": mesh.n_faces,
            "n_components": mesh.n_components,
            "n_boundary_loops": len(mesh.boundary_loops),
            "notes": list(mesh.notes),
            "handles": args.handles,
            "transform": args.transform,
            "rings_file": args.rings_file,
        },
        "parameters": {
            "rings": int(args.rings) if not args.rings_file else rings_summary(r),
            "weights": args.weights,
            "tol": args.tol,
            "max_iter": args.max_iter,
            "init": args.init,
            "accelerate": args.accelerate,
        },
        "handles": {
            "count": len(hs.indices),
            "groups": [
                {"name": g.name, "count": len(g.indices), "kind": g.kind} for g in hs.groups
            ],
        },
        "result": {
            "iterations": res.iterations,
            "converged": res.converged,
            "energy": res.energy,
            "energy_history": list(res.history),
            "max_handle_error": float(
                np.max(np.linalg.norm(res.vertices[hs.indices] - hs.targets, axis=1))
            ),
        },
        "timings": {**res.timings, "wall_s": wall_s},
        "outputs": {"mesh": args.output, "report": args.report, "figure": args.figure},
    }


def run(args: argparse.Namespace) -> int:
    """Execute ``arapkit deform``; returns the exit status."""
    from arapkit import Deformer
    from arapkit.fileio import save_mesh, write_json
    from arapkit.handles import load_handles

    t0 = time.perf_counter()
    _check_outputs(args)
    mesh = load_mesh_checked(args.mesh)
    for msg in mesh.notes:
        note(f"{args.mesh}: {msg}", args.quiet)
    hs = load_handles(args.handles, mesh.vertices, args.transform)
    rings = _rings(args, mesh.n_vertices)
    deformer = Deformer(
        mesh,
        hs.indices,
        rings=rings,
        weights=args.weights,
        tol=args.tol,
        max_iter=args.max_iter,
        init=args.init,
        accelerate=args.accelerate,
    )
    for msg in deformer.notes:
        note(f"{args.mesh}: {msg}", args.quiet)
    with Progress(disable=args.quiet) as progress:
        res = deformer.solve(hs.targets, callback=progress)
    if not res.converged:
        note(
            f"{args.mesh}: stopped after {res.iterations} iterations without converging "
            f"(relative decrease still >= {args.tol:g}; raise --max-iter)",
            args.quiet,
        )
    wall = time.perf_counter() - t0

    r_full = np.broadcast_to(np.asarray(deformer.rings), (mesh.n_vertices,))
    save_mesh(
        args.output,
        res.vertices,
        mesh.faces,
        {"energy": res.vertex_energy, "rings": r_full.astype(np.int32)},
    )
    report = _report(args, mesh, hs, r_full, res, wall)
    if args.report and args.report != "-":
        write_json(args.report, report)
    if args.figure:
        from arapkit.plots import deformation_figure, save_figure

        fig = deformation_figure(
            mesh.vertices,
            mesh.faces,
            res.vertices,
            res.vertex_energy,
            hs.indices,
            res.history,
            targets=hs.targets,
            fixed_mask=hs.fixed_mask,
            rings=r_full,
            title=f"{Path(args.mesh).name}: r = {_describe_rings(r_full)}, "
            f"{res.iterations} iterations",
        )
        save_figure(fig, args.figure)

    if args.report == "-":
        import json

        from arapkit.fileio import to_jsonable

        print(json.dumps(to_jsonable(report), indent=2))
    else:
        _print_summary(args, mesh, hs, res, wall)
    return 0


def _describe_rings(r: np.ndarray) -> str:
    lo, hi = int(r.min()), int(r.max())
    return str(lo) if lo == hi else f"{lo}..{hi}"


def _print_summary(args, mesh, hs, res, wall: float) -> None:
    lines = [
        f"output: {args.output}",
        f"vertices: {mesh.n_vertices}",
        f"faces: {mesh.n_faces}",
        f"handles: {len(hs.indices)} in {len(hs.groups)} group(s)",
        f"iterations: {res.iterations}",
        f"converged: {'yes' if res.converged else 'no'}",
        f"energy: {res.energy:.6g}",
        f"time_s: {wall:.3f}",
    ]
    if args.report:
        lines.append(f"report: {args.report}")
    if args.figure:
        lines.append(f"figure: {args.figure}")
    print("\n".join(lines))
