"""``arapkit fit``: fit a template mesh to a scan (a mesh or a point cloud).

Non-rigid ICP with the r-ring ARAP energy as the regulariser
(:mod:`arapkit.methods.fit`); the fitted template keeps the template file's vertex order,
faces and attributes. A summary goes to stdout; ``--report`` writes the JSON report and
``--figure`` the fitted template coloured by its distance to the target.

Examples
--------
::

    arapkit fit template.ply scan.ply -o fitted.ply --landmarks landmarks.json
    arapkit fit template.obj scan.xyz -o fitted.obj --rings-file rings.txt --report fit.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from arapkit.cli.common import add_example_epilog, add_view_options, positive_float, ring_size
from arapkit.errors import InputError, require_extra
from arapkit.io import readable_formats
from arapkit.mesh.weights import DEFAULT_WEIGHTS, WEIGHT_KINDS
from arapkit.methods.fit import DEFAULT_SCHEDULE

__all__ = ["SCALES", "add_parser", "run"]

#: ``--scale`` choices and the library's ``scale=`` for each
SCALES = {"auto": None, "fit": True, "keep": False}

EXAMPLES = [
    "arapkit fit examples/finger.off examples/finger-scan.xyz -o fitted.ply "
    "--landmarks examples/finger-landmarks.json --figure fitted.png",
    "arapkit fit template.obj scan.ply -o fitted.obj --rings-file rings.txt --report fit.json",
    "arapkit fit head.obj face-scan.ply -o fitted.obj --landmarks lm.json --scale fit",
]


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``fit`` with its options."""
    p = subparsers.add_parser(
        "fit",
        help="fit a template mesh to a scan (mesh or point cloud) with ARAP-regularised ICP",
        description="Fit TEMPLATE to TARGET: non-rigid ICP with the r-ring ARAP energy as "
        "the regulariser, from stiff to soft, with optional landmarks and a per-vertex "
        "rigidity map (where the fit may bend). The output keeps the template's vertex "
        "order, faces and attributes. A summary goes to stdout.",
        **add_example_epilog(EXAMPLES),
    )
    p.add_argument("template", metavar="TEMPLATE",
                   help=f"the template mesh ({readable_formats()})")
    p.add_argument("target", metavar="TARGET",
                   help="the scan: a mesh, or a point cloud (.npy, .xyz/.txt/.pts with x y z "
                   "[nx ny nz] a line, or a PLY without faces)")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="the fitted template (format from the extension)")
    p.add_argument("--landmarks", metavar="FILE",
                   help='JSON list of {"vertex": i, "target": [x, y, z]}: template vertices '
                   "and where they must land (met exactly)")
    rings = p.add_mutually_exclusive_group()
    rings.add_argument("--rings", "-r", type=ring_size, default=1, metavar="N",
                       help="r for every vertex: 1 bends freely, larger keeps larger patches "
                       "rigid (default 1)")
    rings.add_argument("--rings-file", metavar="FILE",
                       help="per-vertex r (text, .npy, or PLY property 'rings'), painted or "
                       "from arapkit learn")
    p.add_argument("--scale", choices=SCALES, default="auto",
                   help="the template's size: 'fit' it (a generic template of another size), "
                   "'keep' it, or 'auto': fit it when the landmarks say the target is more "
                   "than twice or less than half the template's size (another unit), else "
                   "keep it (default auto)")
    p.add_argument("--schedule", type=positive_float, nargs="+", metavar="L",
                   default=list(DEFAULT_SCHEDULE),
                   help="stiffness lengths of the stages, stiff to soft, as fractions of the "
                   "template's diagonal (default "
                   f"{' '.join(f'{b:g}' for b in DEFAULT_SCHEDULE)})")
    p.add_argument("--weights", default=DEFAULT_WEIGHTS, choices=WEIGHT_KINDS,
                   help=f"edge weights of the ARAP energy (default {DEFAULT_WEIGHTS})")
    p.add_argument("--report", metavar="FILE",
                   help="JSON report (residuals, iterations, time, stages); '-' for stdout")
    p.add_argument("--figure", metavar="FILE",
                   help="the fitted template coloured by its distance to the target (.png, "
                   ".pdf, .svg)")
    add_view_options(p)
    p.add_argument("--force", action="store_true", help="allow overwriting an input file")
    p.add_argument("--quiet", "-q", action="store_true", help="no notes on stderr")
    return p


def _check_outputs(args: argparse.Namespace, inputs: list[str]) -> None:
    """Fail before any work on an output that cannot be written."""
    from arapkit.io import check_figure_format, check_output_path, mesh_format

    outs = [check_output_path(args.output, inputs, args.force, "output").resolve()]
    mesh_format(args.output)
    if args.report and args.report != "-":
        outs.append(check_output_path(args.report, inputs, args.force, "report").resolve())
    if args.figure:
        require_extra("matplotlib", "plots", "arapkit fit --figure")
        outs.append(check_output_path(args.figure, inputs, args.force, "figure").resolve())
        check_figure_format(args.figure)
    if len(set(outs)) < len(outs):
        raise InputError(f"{outs[0]}: output, report and figure must be different files")


def run(args: argparse.Namespace) -> int:
    """Run ``arapkit fit``; returns the exit status (InputError propagates as status 2)."""
    from arapkit.io import to_jsonable, write_json
    from arapkit.workflows.fitting import FitJob, fit_report, load_fit_inputs, run_fit, save_fit

    job = FitJob(args.template, args.target, args.landmarks, args.rings, args.rings_file,
                 SCALES[args.scale], tuple(args.schedule), args.weights)
    _check_outputs(args, job.input_files())
    inputs = load_fit_inputs(job)
    if not args.quiet:
        for n in inputs.notes:
            print(f"arapkit: {Path(args.template).name}: {n}", file=sys.stderr)
    result = run_fit(inputs)
    for line in save_fit(args.output, inputs, result):
        print(f"arapkit: warning: {line}", file=sys.stderr)
    report = fit_report(inputs, result, {"mesh": args.output, "report": args.report,
                                         "figure": args.figure})
    if args.report and args.report != "-":
        write_json(args.report, report)
    if args.figure:
        from arapkit.plots.figures import save_figure
        from arapkit.plots.fit import residual_figure

        rep = result.report
        title = (f"{rep.template} fitted to {rep.target}: mean "
                 f"{100 * rep.residual['mean']:.2f} %, p95 {100 * rep.residual['p95']:.2f} % "
                 "of the diagonal")
        views = ("front", "back") if args.view == "front" else (args.view,)
        save_figure(residual_figure(result.vertices, inputs.template.faces, result.residuals,
                                    rep.diagonal, points=inputs.target.points, title=title,
                                    views=views, up=args.up), args.figure, dpi=150)
    if args.report == "-":
        print(json.dumps(to_jsonable(report), indent=2))
    else:
        for line in result.report.summary():
            print(line)
        print(f"wrote {args.output}"
              + (f", report {args.report}" if args.report else "")
              + (f", figure {args.figure}" if args.figure else ""))
    sys.stdout.flush()
    return 0
