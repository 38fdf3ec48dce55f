"""``arapkit compare``: several methods on the same handles, one figure and one table.

Examples
--------
::

    arapkit compare cow.off --handles cow.json -o cmp --rings 4
    arapkit compare bar.off --handles bar.json --rings-file r.txt -o cmp
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from arapkit.arap.domains import all_weight_kinds
from arapkit.cli.common import (
    Progress,
    RingProgress,
    add_example_epilog,
    add_graph_options,
    add_view_options,
    add_weld_option,
    note,
    positive_float,
    positive_int,
    warn,
)
from arapkit.errors import InputError, require_extra
from arapkit.io.clouds import shape_formats_text
from arapkit.mesh.cloud_weights import DEFAULT_CLOUD_WEIGHTS
from arapkit.mesh.weights import DEFAULT_WEIGHTS

__all__ = ["add_parser", "run"]


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``compare``."""
    p = subparsers.add_parser(
        "compare",
        help="run ARAP, SR-ARAP, embedded deformation and r-ring ARAP on the same handles",
        description="Deform MESH with ARAP (r = 1), SR-ARAP, embedded deformation, r-ring "
        "ARAP at --rings and, with --rings-file, r-ring ARAP with that rigidity map. Writes "
        "DIR/compare.png (all results side by side, one camera, handles marked), "
        "DIR/compare.csv and one PLY per method; prints the table on stdout.",
        **add_example_epilog([
            "arapkit compare cow.off --handles cow.json -o cmp --rings 4",
            "arapkit compare bar.off --handles bar.json --rings-file r.txt -o cmp",
        ]),
    )
    p.add_argument("mesh", metavar="MESH",
                   help=f"input mesh or point cloud ({shape_formats_text()}); on a point "
                   "cloud only the methods that apply run (docs/clouds.md)")
    p.add_argument("--handles", "-H", required=True, metavar="FILE",
                   help="handle groups (.json) or a per-vertex status file (.sel)")
    p.add_argument("--transform", "-T", metavar="FILE",
                   help="4x4 matrix (.def) for a .sel file (default: the .def next to it)")
    p.add_argument("--rings", "-r", type=positive_int, default=3, metavar="N",
                   help="r of the uniform r-ring run (default 3)")
    p.add_argument("--rings-file", metavar="FILE",
                   help="per-vertex r for an extra mixed-r run (text, .npy or PLY 'rings')")
    p.add_argument("--weights", default=None, choices=all_weight_kinds(),
                   help=f"edge weights of the ARAP methods (default {DEFAULT_WEIGHTS} on a "
                   f"mesh, {DEFAULT_CLOUD_WEIGHTS} on a point cloud)")
    add_graph_options(p)
    p.add_argument("--sr-alpha", metavar="A", help="SR-ARAP alpha (default 0.02)")
    p.add_argument("--nodes", metavar="N", help="embedded deformation graph nodes (default 200)")
    p.add_argument("--tol", type=positive_float, default=1e-3,
                   help="relative energy decrease to stop at (default 1e-3)")
    p.add_argument("--max-iter", type=positive_int, default=1000, metavar="N",
                   help="iteration cap per method (default 1000)")
    p.add_argument("-o", "--out", required=True, metavar="DIR",
                   help="output folder (created if missing)")
    p.add_argument("--volumetric", action="store_true",
                   help="also run volumetric ARAP (tetrahedra inside the closed surface; needs "
                   "pip install 'arapkit[volume]')")
    p.add_argument("--dry-run", action="store_true",
                   help="no solve: print each handle group's vertex count and motion and draw "
                   "the groups on the rest shape (DIR/groups.png)")
    add_view_options(p)
    add_weld_option(p)
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bars or notes")
    return p


def _prepare_out(path: str, inputs: list[str | None]) -> Path:
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")
    if str(out.parent) and not out.parent.is_dir():
        raise InputError(f"{out}: parent folder {str(out.parent)!r} does not exist")
    for i in inputs:
        if i and Path(i).resolve().parent == out.resolve():
            names = {"compare.png", "compare.csv"}
            if Path(i).name in names or Path(i).suffix == ".ply":
                raise InputError(f"{i}: an input lies in the output folder {out} and could be "
                                 "overwritten; choose another -o")
    out.mkdir(exist_ok=True)
    return out


def _slug(label: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in label.lower()).strip("_")


def run(args: argparse.Namespace) -> int:
    """Execute ``arapkit compare``; returns the exit status."""
    require_extra("matplotlib", "plots", "arapkit compare")  # it always draws compare.png
    from arapkit.io import save_mesh
    from arapkit.methods.deformer import check_method
    from arapkit.plots.figures import save_figure
    from arapkit.workflows.compare import (
        comparison_figure,
        comparison_rows,
        format_rows,
        run_comparison,
        write_csv,
    )
    from arapkit.workflows.jobs import DeformJob, load_job_inputs

    t0 = time.perf_counter()
    check_method("sr-arap", args.sr_alpha)
    check_method("embedded", None, args.nodes)
    if args.volumetric:
        from arapkit.methods.volumetric import MESHER_HINT, have_mesher

        if not have_mesher():
            raise InputError(MESHER_HINT)
    out = _prepare_out(args.out, [args.mesh, args.handles, args.transform, args.rings_file])
    # the same reading as deform and batch: mesh, optional weld, handles and r mapped onto it
    inputs = load_job_inputs(
        DeformJob(mesh=args.mesh, handles=args.handles, transform=args.transform,
                  rings_file=args.rings_file, weld=args.weld, neighbours=args.neighbours,
                  radius=args.radius),
        note=lambda msg: note(msg, args.quiet))
    mesh, hs = inputs.mesh, inputs.handles
    rings_map = inputs.rings if args.rings_file else None
    if args.dry_run:
        return _dry_run(args, mesh, hs, out)
    if args.volumetric:
        from arapkit.methods.deformer import check_domain
        from arapkit.methods.volumetric import check_closed

        check_domain(mesh, volumetric=True)  # a point cloud has no volume to fill
        check_closed(mesh)  # refuse an open surface before any method runs
    if mesh.faces is None:
        from arapkit.methods.registry import methods

        skipped = [m.name for m in methods("compare") if not m.applies_to(False)]
        if skipped:
            note(f"{args.mesh}: a point cloud: {', '.join(skipped)} need(s) a triangle mesh "
                 "and did not run", args.quiet)

    def progress(label: str) -> Progress:
        return Progress(disable=args.quiet, desc=label)

    with RingProgress(disable=args.quiet):
        runs = run_comparison(mesh, hs.indices, hs.targets, rings=args.rings,
                              rings_map=rings_map, weights=args.weights, tol=args.tol,
                              max_iter=args.max_iter,
                              sr_alpha=args.sr_alpha, nodes=args.nodes,
                              volumetric=args.volumetric,
                              progress=None if args.quiet else progress)
    for r in runs:
        for msg in r.notes:
            note(f"{r.label}: {msg}", args.quiet)
        if not r.result.converged:
            note(f"{r.label}: stopped after {r.result.iterations} iterations without "
                 "converging (raise --max-iter)", args.quiet)
        for line in save_mesh(out / f"{_slug(r.label)}.ply", r.result,
                              vertex_properties={"energy": r.result.vertex_energy}, like=mesh):
            warn(line)
    rows = comparison_rows(runs)
    write_csv(out / "compare.csv", rows)
    fig = comparison_figure(mesh, runs, hs.indices, hs.targets, hs.fixed_mask,
                            title=f"{Path(args.mesh).name}: {mesh.n_vertices} vertices, "
                            f"{len(hs.indices)} handles", view=args.view, up=args.up)
    save_figure(fig, out / "compare.png")
    print(format_rows(rows))
    print("self-intersecting faces: not counted (no dependency of arapkit counts them)")
    print(f"wrote compare.png, compare.csv and {len(runs)} meshes to {out} "
          f"in {time.perf_counter() - t0:.1f} s")
    return 0


def _dry_run(args: argparse.Namespace, mesh, hs, out: Path) -> int:
    """What ``deform --dry-run`` shows, for the comparison's handles; solves nothing."""
    from arapkit.mesh.cloud import counted
    from arapkit.plots.figures import groups_figure, save_figure
    from arapkit.workflows.jobs import describe_groups

    cloud = mesh.faces is None
    print(f"{'point cloud' if cloud else 'mesh'}: {args.mesh} "
          f"({counted(mesh.n_vertices, points=cloud)})")
    print(f"handles: {counted(len(hs.indices), points=cloud)} in {len(hs.groups)} group(s) "
          f"from {args.handles}")
    for line in describe_groups(mesh.vertices, hs, points=cloud):
        print(f"  {line}")
    fig = groups_figure(mesh.vertices, mesh.faces, [(g.name, g.indices) for g in hs.groups],
                        view=args.view, up=args.up,
                        title=f"{Path(args.handles).name} on {Path(args.mesh).name}")
    save_figure(fig, out / "groups.png")
    print(f"dry run: nothing solved; wrote {out / 'groups.png'}")
    return 0
