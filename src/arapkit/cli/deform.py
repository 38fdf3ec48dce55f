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

from arapkit.arap.domains import all_weight_kinds
from arapkit.cli.common import (
    Progress,
    RingProgress,
    add_example_epilog,
    add_graph_options,
    add_view_options,
    add_weld_option,
    iteration_cap,
    note,
    positive_float,
    ring_size,
    tolerance,
    warn,
)
from arapkit.errors import InputError, require_extra, worded_for
from arapkit.io.clouds import shape_formats_text
from arapkit.mesh.cloud_weights import CLOUD_WEIGHT_KINDS, DEFAULT_CLOUD_WEIGHTS
from arapkit.mesh.weights import DEFAULT_WEIGHTS, WEIGHT_KINDS

__all__ = ["add_parser", "run"]

EXAMPLES = [
    "arapkit deform examples/bar.off --handles examples/bar-bend.json --dry-run "
    "--figure groups.png",
    "arapkit deform examples/bar.off --handles examples/bar-bend.json --rings 6 -o bar6.ply "
    "--figure bar6.png",
    "arapkit deform examples/bar.off --handles examples/bar.sel --transform examples/bar.def "
    "--rings-file examples/bar-rings.txt -o out.off",
    "arapkit deform examples/cactus.off --handles examples/cactus.json -o out.ply --report - "
    "--quiet | jq .result",
    "arapkit deform examples/cactus.off --handles examples/cactus.json --groups "
    "examples/cactus-groups.json -o rigid-arm.ply",
]


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
    p.add_argument("mesh", metavar="MESH",
                   help=f"input mesh or point cloud ({shape_formats_text()}; text formats "
                   "may be .gz); a file without faces is a point cloud (docs/clouds.md)")
    p.add_argument(
        "--handles",
        "-H",
        required=True,
        metavar="FILE",
        help="handle groups (.json, schema in docs/handles.md) or a per-vertex status file (.sel)",
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
    p.add_argument(
        "--groups",
        "-G",
        metavar="FILE",
        help="rigid parts and shared-rotation groups (docs/groups.md): JSON entries with "
        "the handle files' selectors and \"rigid\": true|false, a per-vertex id file (.npy "
        "or text: libigl's G, -1 for none), or PLY vertex properties 'part'/'group'",
    )
    p.add_argument(
        "--weights",
        default=None,
        choices=all_weight_kinds(),
        help=f"edge weights: on a mesh {', '.join(WEIGHT_KINDS)} (default {DEFAULT_WEIGHTS}); "
        f"on a point cloud {', '.join(CLOUD_WEIGHT_KINDS)} (default {DEFAULT_CLOUD_WEIGHTS})",
    )
    add_graph_options(p)
    p.add_argument(
        "--energy",
        default="rring",
        metavar="NAME",
        help="method: rring (r-ring ARAP, default), spokes-and-rims, sr-arap, smooth-arap "
        "(no spike under a single-vertex handle), embedded (see docs/methods.md)",
    )
    p.add_argument(
        "--nodes",
        metavar="N",
        help="embedded deformation: deformation-graph nodes (default 200)",
    )
    p.add_argument(
        "--sr-alpha",
        metavar="A",
        help="SR-ARAP rotation-smoothness weight, times the surface area (default 0.02)",
    )
    p.add_argument(
        "--smooth-lambda",
        metavar="L",
        help="Smooth ARAP: weight of the Laplacian term, in [0, 1) (default 0.99; 0 is ARAP)",
    )
    p.add_argument(
        "--tol",
        type=tolerance,
        default=None,
        help="stop when the relative energy decrease is below this (default 1e-3; 1e-5 with "
        "--volumetric)",
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
        action=argparse.BooleanOptionalAction,
        default=None,
        help="Anderson acceleration with an energy safeguard: fewer, costlier iterations "
        "(pays on large meshes; see docs/benchmarks.md; default off, on with --volumetric "
        "and on meshes of 100,000 vertices or more, which are solved coarse to fine)",
    )
    p.add_argument(
        "-o",
        "--output",
        metavar="OUT",
        help="deformed mesh; format from the extension (.ply keeps energy and rings); "
        "required unless --dry-run",
    )
    p.add_argument(
        "--report",
        metavar="FILE",
        help="JSON report (parameters, timings, energy history); '-' for stdout",
    )
    p.add_argument("--figure", metavar="FILE", help="summary figure (.png, .pdf, .svg or .jpg)")
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="no solve: print each handle group's vertex count and motion, and draw the "
        "groups on the rest shape with --figure",
    )
    add_view_options(p)
    add_weld_option(p)
    p.add_argument("--force", action="store_true", help="allow overwriting an input file")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar or notes")
    _add_volume_options(p)
    return p


def _check_method(args: argparse.Namespace) -> dict[str, Any]:
    """Fail fast on a bad method or option; the keyword arguments for the Deformer."""
    from arapkit.methods.deformer import check_method
    from arapkit.methods.registry import method, methods

    options = check_method(args.energy, args.sr_alpha, args.nodes,
                           smooth_lambda=args.smooth_lambda)
    can = method(args.energy, "cli")
    if not can.rigidity_map and (args.rings_file or args.rings != 1):
        raise InputError(f"--energy {args.energy}: has no rigidity map (drop --rings/--rings-file)")
    if args.groups and not can.groups:
        takes = ", ".join(m.name for m in methods("cli") if m.groups)
        raise InputError(f"--groups: --energy {args.energy} takes no vertex groups (these "
                         f"methods do: {takes})")
    if args.groups and args.volumetric:
        raise InputError("--groups: vertex groups are for surface ARAP, not --volumetric")
    if not can.accelerate and args.accelerate:
        raise InputError(f"--accelerate: not available with --energy {args.energy} "
                         "(only for the local/global descent methods)")
    args._method_options = options
    return {"energy": args.energy, "sr_alpha": args.sr_alpha, "nodes": args.nodes,
            "smooth_lambda": args.smooth_lambda}


# -- volumetric ARAP (arapkit.methods.volumetric) -------------------------------------------------


def _add_volume_options(p: argparse.ArgumentParser) -> None:
    """``--volumetric`` and its options: fill the closed surface with tetrahedra."""
    g = p.add_argument_group("volumetric ARAP (needs pip install 'arapkit[volume]')")
    g.add_argument(
        "--volumetric",
        action="store_true",
        help="fill the closed surface with tetrahedra and solve ARAP on the volume (inner "
        "edges against folding and volume loss); the output is still the input's surface",
    )
    g.add_argument(
        "--interior-density",
        type=positive_float,
        default=None,
        metavar="X",
        help="spacing of the interior points in multiples of the surface's mean edge length, "
        "or of 1/40 of the bounding-box diagonal where that is larger (default 1; 0.5 gives "
        "about 8x the points)",
    )
    g.add_argument(
        "--save-volume",
        metavar="FILE",
        help="also write the deformed tet mesh (.vtu, .msh, .vtk or .mesh, via meshio)",
    )


def _check_volume_options(args: argparse.Namespace, inputs: list) -> Path | None:
    """Refuse volume options without --volumetric, a missing mesher, a bad volume path."""
    from arapkit.io import check_output_path
    from arapkit.methods.volumetric import MESHER_HINT, VOLUME_FORMATS, have_mesher

    if not args.volumetric:
        for flag, value in (("--interior-density", args.interior_density),
                            ("--save-volume", args.save_volume)):
            if value is not None:
                raise InputError(f"{flag} needs --volumetric")
        return None
    if not have_mesher():
        raise InputError(MESHER_HINT)
    if args.save_volume is None:
        return None
    check_output_path(args.save_volume, inputs, args.force, "volume")
    if Path(args.save_volume).suffix.lower() not in VOLUME_FORMATS:
        raise InputError(f"{args.save_volume}: unsupported volume format (use "
                         f"{', '.join(VOLUME_FORMATS)})")
    return Path(args.save_volume).resolve()


def _check_outputs(args: argparse.Namespace) -> None:
    """Fail fast, before loading or solving, on any output that cannot be written."""
    from arapkit.io import check_figure_format, check_output_path
    from arapkit.io.clouds import check_shape_output

    inputs = [args.mesh, args.handles, args.transform, args.rings_file, args.groups]
    outs = []
    if args.output is None and not args.dry_run:
        raise InputError("-o/--output OUT is required (only --dry-run writes no mesh)")
    if args.output is not None:
        check_output_path(args.output, inputs, args.force, "output")
        check_shape_output(args.output, args.mesh)
        outs.append(Path(args.output).resolve())
    if args.report and args.report != "-":
        check_output_path(args.report, inputs, args.force, "report")
        outs.append(Path(args.report).resolve())
    if args.figure:
        require_extra("matplotlib", "plots", "arapkit deform --figure")
        check_output_path(args.figure, inputs, args.force, "figure")
        check_figure_format(args.figure)
        outs.append(Path(args.figure).resolve())
    volume_out = _check_volume_options(args, inputs)
    if volume_out is not None:
        outs.append(volume_out)
    if len(set(outs)) != len(outs):
        raise InputError(f"{outs[0]}: output, report, figure and volume must be different "
                         "files")


def _job(args: argparse.Namespace, method: dict[str, Any]):
    """The library's job description of these arguments."""
    from arapkit.workflows.jobs import DeformJob

    return DeformJob(
        mesh=args.mesh,
        handles=args.handles,
        transform=args.transform,
        rings=args.rings,
        rings_file=args.rings_file,
        weights=args.weights,
        **_solve_defaults(args),
        max_iter=args.max_iter,
        init=args.init,
        weld=getattr(args, "weld", None),
        neighbours=args.neighbours,
        radius=args.radius,
        volumetric=args.volumetric,
        interior_density=args.interior_density,
        groups=args.groups,
        **method,
    )


def run(args: argparse.Namespace) -> int:
    """Execute ``arapkit deform``; returns the exit status."""
    from arapkit.io import write_json
    from arapkit.workflows.jobs import job_report, load_job_inputs, prepare_job, save_result

    t0 = time.perf_counter()
    method = _check_method(args)
    _check_outputs(args)
    job = _job(args, method)
    tell = lambda msg: note(worded_for(msg, "cli"), args.quiet)  # noqa: E731
    if args.dry_run:
        inputs = load_job_inputs(job, note=tell)
        return _dry_run(args, inputs.mesh, inputs.handles, inputs.rings, inputs.groups)
    if args.volumetric and args.weights not in (None, DEFAULT_WEIGHTS):
        from arapkit.methods.volumetric import DEFAULT_VOLUME_WEIGHTS

        note(f"--weights {args.weights} applies to surface ARAP; the volume's edges use "
             f"'{DEFAULT_VOLUME_WEIGHTS}' weights (see docs/volumetric.md)", args.quiet)
    with RingProgress(disable=args.quiet):  # a large r's build shows its progress
        prepared = prepare_job(job, note=tell)
    mesh, hs = prepared.mesh, prepared.handles
    if args.output is not None:  # now that the input is read: a mesh's or a cloud's format
        from arapkit.io.clouds import check_shape_output

        check_shape_output(args.output, mesh)
    with Progress(disable=args.quiet) as progress:
        res = prepared.solve(callback=progress)
    if not res.converged:
        note(
            f"{args.mesh}: stopped after {res.iterations} iterations without converging "
            f"(relative decrease still >= {job.tol:g}; raise --max-iter)",
            args.quiet,
        )
    if args.volumetric and args.save_volume:
        prepared.deformer.save_volume(args.save_volume)
    wall = time.perf_counter() - t0

    r_full = prepared.rings
    for line in save_result(args.output, prepared, res):
        warn(line)
    report = job_report(
        job,
        prepared,
        res,
        wall,
        command=["arapkit", *getattr(args, "_argv", sys.argv[1:])],
        outputs={"mesh": args.output, "report": args.report, "figure": args.figure},
    )
    if args.report and args.report != "-":
        write_json(args.report, report)
    if args.figure:
        from arapkit.plots.figures import deformation_figure, save_figure

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
            title=f"{Path(args.mesh).name}: {_describe_method(args, r_full)}, "
            f"{res.iterations} iterations",
            view=args.view,
            up=args.up,
        )
        save_figure(fig, args.figure)

    if args.report == "-":
        import json

        from arapkit.io import to_jsonable

        print(json.dumps(to_jsonable(report), indent=2))
    else:
        _print_summary(args, mesh, hs, res, wall, prepared.groups)
    return 0


def _method_options(args: argparse.Namespace) -> dict[str, Any]:
    """The method's options as used (defaults filled in), named as in the CLI."""
    opts = getattr(args, "_method_options", {})
    return {("sr_alpha" if k == "alpha" else k): v for k, v in opts.items()}


def _solve_defaults(args: argparse.Namespace) -> dict[str, Any]:
    """``tol`` and ``accelerate`` as given, else the method's defaults: volumetric ARAP's
    converged ones (:data:`~arapkit.methods.volumetric.VOLUME_SOLVE_DEFAULTS`) or the
    Deformer's."""
    from arapkit.methods.volumetric import VOLUME_SOLVE_DEFAULTS
    from arapkit.workflows.jobs import DeformJob

    own = VOLUME_SOLVE_DEFAULTS if args.volumetric else {
        "tol": DeformJob.tol, "accelerate": DeformJob.accelerate}
    given = {"tol": args.tol, "accelerate": args.accelerate}
    return {k: own[k] if v is None else v for k, v in given.items()}


def _describe_method(args: argparse.Namespace, r: np.ndarray) -> str:
    from arapkit.methods.registry import method
    from arapkit.workflows.jobs import describe_rings

    info = method(args.energy)
    opts = _method_options(args)
    shown = [o.describe.format(opts[k]) for k, o in info.options.items()
             if o.describe is not None and k in opts]
    if info.rigidity_map:
        # r-ring ARAP is named by its r alone; a method with options of its own says which
        return ", ".join([*([info.label, *shown] if shown else []), f"r = {describe_rings(r)}"])
    return ", ".join([info.label, *shown])


def _dry_run(args: argparse.Namespace, mesh, hs, rings, groups=None) -> int:
    """Print what the handle file selects and how it moves it; draw it; solve nothing."""
    from arapkit.mesh.cloud import counted
    from arapkit.mesh.orientation import bounding_box
    from arapkit.workflows.jobs import describe_groups, describe_rings

    box = bounding_box(mesh.vertices)
    cloud = mesh.faces is None
    kind = "point cloud" if cloud else "mesh"
    print(f"{kind}: {args.mesh} ({counted(mesh.n_vertices, points=cloud)}, box min "
          f"{_vec(box.min)} max {_vec(box.max)})")
    print(f"handles: {counted(len(hs.indices), points=cloud)} in {len(hs.groups)} group(s) "
          f"from {args.handles}")
    for line in describe_groups(mesh.vertices, hs, points=cloud):
        print(f"  {line}")
    if groups is not None:
        print(f"groups: {groups.summary(points=cloud)} from {args.groups}")
        sizes = groups.sizes
        for i, name in enumerate(groups.names):
            kind = "rigid part" if groups.rigid[i] else "shared rotation"
            print(f"  {name}: {counted(int(sizes[i]), points=cloud)}, {kind}")
    print(f"rings: r = {describe_rings(rings)}; dry run: nothing solved, no mesh written")
    if args.figure:
        from arapkit.plots.figures import groups_figure, save_figure

        groups = [(g.name, g.indices) for g in hs.groups]
        fig = groups_figure(mesh.vertices, mesh.faces, groups, view=args.view, up=args.up,
                            title=f"{Path(args.handles).name} on {Path(args.mesh).name}")
        save_figure(fig, args.figure)
        print(f"figure: {args.figure}")
    return 0


def _vec(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:.4g}" for x in v) + "]"


def _print_summary(args, mesh, hs, res, wall: float, groups=None) -> None:
    lines = [
        f"output: {args.output}",
        f"vertices: {mesh.n_vertices}"
        + ("" if mesh.welded_from is None else
           f" (welded from the input's {mesh.welded_from.source.n_vertices}; the output "
           "has the input's vertices)"),
        f"faces: {mesh.n_faces}" if mesh.faces is not None else
        f"graph: {mesh.graph_description}, {len(mesh.edges)} edges (a point cloud)",
        f"handles: {len(hs.indices)} in {len(hs.groups)} group(s)",
        *([f"groups: {groups.summary()}"] if groups is not None else []),
        f"method: {args.energy}",
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
