"""``arapkit simulate``: ARAP dynamics of one mesh, written as frames.

Examples
--------
::

    arapkit simulate examples/bar.off --handles examples/bar-bend.json -o frames.npz \\
        --figure film.png
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from arapkit.cli.common import (
    add_example_epilog,
    add_view_options,
    iteration_cap,
    note,
    positive_float,
    positive_int,
    ring_size,
    tolerance,
    warn,
)
from arapkit.errors import InputError, require_extra
from arapkit.io.formats import readable_formats
from arapkit.mesh.mass import MASS_KINDS
from arapkit.mesh.weights import DEFAULT_WEIGHTS, WEIGHT_KINDS

__all__ = ["add_parser", "run"]

EXAMPLES = [
    "arapkit simulate examples/bar.off -o fall.npz --figure fall.png",
    "arapkit simulate examples/bar.off --handles examples/bar-bend.json --frames 180 "
    "-o bend.npz --figure bend.png",
    "arapkit simulate examples/cactus.off --handles examples/cactus.json --rings 3 "
    "-o cactus.obj   (cactus_0000.obj, cactus_0001.obj ...)",
    "arapkit simulate examples/cactus.off --handles examples/cactus.json --groups "
    "examples/cactus-groups.json --frames 60 -o rigid-arm.npz",
]


def _finite(text: str) -> float:
    """argparse type: a finite number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text}")
    return value


def _at_least_zero(text: str) -> float:
    value = _finite(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be at least 0, got {text}")
    return value


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``simulate`` with its options."""
    from arapkit.methods.dynamics import (
        DEFAULT_DAMPING,
        DEFAULT_DT,
        DEFAULT_STIFFNESS,
        DEFAULT_TOL,
    )

    p = subparsers.add_parser(
        "simulate",
        help="simulate a mesh as an elastic body (ARAP dynamics) and write its frames",
        description="Simulate MESH as an elastic body whose energy is ARAP's (implicit Euler "
        "steps, docs/dynamics.md): it falls under gravity, hangs from pinned handles, lags "
        "behind handles that move and settles. Units are SI with the mesh in metres. Frames "
        "go to one .npz (V, F, times) or a numbered mesh sequence; a summary goes to stdout.",
        **add_example_epilog(EXAMPLES),
    )
    p.add_argument("mesh", metavar="MESH", help=f"input mesh ({readable_formats()}; may be .gz)")
    p.add_argument("--handles", "-H", metavar="FILE",
                   help="handle groups (.json, schema in README) or a .sel file: fixed groups "
                   "stay pinned, moved groups reach their pose during --ramp (default: none, "
                   "a free body)")
    p.add_argument("--transform", "-T", metavar="FILE",
                   help="4x4 matrix (.def) moving the status-2 vertices of a .sel file")
    p.add_argument("--ramp", type=_at_least_zero, default=1.0, metavar="SECONDS",
                   help="moved handles go from rest to their pose in this time, then stay "
                   "(default 1)")
    p.add_argument("--frames", "-n", type=positive_int, default=120, metavar="N",
                   help="frames to write, the rest shape first (default 120)")
    p.add_argument("--dt", type=positive_float, default=DEFAULT_DT, metavar="SECONDS",
                   help=f"time step (default 1/60 = {DEFAULT_DT:.4g})")
    p.add_argument("--gravity", type=_finite, nargs=3, default=None, metavar=("GX", "GY", "GZ"),
                   help="acceleration in m/s^2 (default 9.81 down the guessed up axis, see "
                   "arapkit info; 0 0 0 for none)")
    p.add_argument("--stiffness", "-k", type=positive_float, default=DEFAULT_STIFFNESS,
                   metavar="N_PER_M", help="ARAP stiffness in N/m, independent of --dt "
                   f"(default {DEFAULT_STIFFNESS:g})")
    p.add_argument("--density", type=positive_float, default=1.0, metavar="KG_PER_M2",
                   help="surface density in kg/m^2 (default 1)")
    p.add_argument("--damping", type=_at_least_zero, default=DEFAULT_DAMPING, metavar="PER_S",
                   help=f"mass damping rate in 1/s (default {DEFAULT_DAMPING:g}; 0 for none)")
    p.add_argument("--mass", choices=MASS_KINDS, default=MASS_KINDS[0],
                   help="lumped vertex masses: voronoi (mixed Voronoi areas, libigl's "
                   "default) or barycentric (a third of each triangle); default voronoi")
    rig = p.add_mutually_exclusive_group()
    rig.add_argument("--rings", "-r", type=ring_size, default=1, metavar="N",
                     help="ring size r for every vertex; larger is stiffer (default 1)")
    rig.add_argument("--rings-file", metavar="FILE",
                     help="per-vertex r: text (one integer per line), .npy, or PLY vertex "
                     "property 'rings'")
    p.add_argument("--groups", "-G", metavar="FILE",
                   help="rigid parts and shared-rotation groups, as for arapkit deform "
                   "(docs/groups.md): a part moves by one rigid motion at every step")
    p.add_argument("--weights", default=DEFAULT_WEIGHTS, choices=WEIGHT_KINDS,
                   help=f"edge weights (default {DEFAULT_WEIGHTS})")
    p.add_argument("--energy", default="rring", metavar="NAME",
                   help="elastic energy: rring (default) or spokes-and-rims")
    p.add_argument("--tol", type=tolerance, default=DEFAULT_TOL,
                   help="a step ends when its objective's relative decrease is below this "
                   f"(default {DEFAULT_TOL:g})")
    p.add_argument("--max-iter", type=iteration_cap, default=1000, metavar="N",
                   help="iteration cap per step (default 1000)")
    p.add_argument("--accelerate", action=argparse.BooleanOptionalAction, default=True,
                   help="Anderson acceleration of each step's iterations (default on)")
    p.add_argument("-o", "--output", metavar="OUT", required=True,
                   help="frames: OUT.npz (V, F, times), or a mesh file name (.obj, .ply ...) "
                   "for one file per frame, OUT_0000.obj, OUT_0001.obj ...")
    p.add_argument("--figure", metavar="FILE",
                   help="filmstrip of six frames (.png, .pdf, .svg or .jpg)")
    add_view_options(p)
    p.add_argument("--force", action="store_true", help="allow overwriting an input file")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress or notes")
    return p


def _check_outputs(args: argparse.Namespace) -> None:
    """Fail fast, before loading or simulating, on outputs that cannot be written."""
    from arapkit.io import check_figure_format, check_output_path
    from arapkit.io.frames import frame_paths

    inputs = [args.mesh, args.handles, args.transform, args.rings_file, args.groups]
    paths = frame_paths(args.output, args.frames)
    for p in (paths[0], paths[-1]):
        check_output_path(p, inputs, args.force, "output")
    if args.figure:
        require_extra("matplotlib", "plots", "arapkit simulate --figure")
        check_output_path(args.figure, inputs, args.force, "figure")
        check_figure_format(args.figure)
        if Path(args.figure).resolve() in {p.resolve() for p in paths}:
            raise InputError(f"{args.figure}: the figure and the frames must be different "
                             "files")


def _check_energy(name: str) -> None:
    from arapkit.arap.energies import energy_info
    from arapkit.methods.registry import method

    info = method(name, "cli")
    if not info.local_global or not energy_info(info.name).descent:
        raise InputError(f"--energy {name}: dynamics needs an elastic energy of the "
                         "local/global loop that each step lowers (rring, spokes-and-rims)")


class _FrameProgress:
    """Frames done on stderr: a tqdm bar on a terminal, else a line every few seconds."""

    def __init__(self, total: int, disable: bool) -> None:
        self.total, self.disable = total, disable
        self.bar = None
        self.start = time.perf_counter()
        self.last = -math.inf
        if not disable and sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, delay=0.5, file=sys.stderr, desc="simulating",
                            unit="frame", dynamic_ncols=True, leave=False)

    def __call__(self, frame: int, step: Any) -> bool:
        if self.bar is not None:
            self.bar.update(1)
        elif not self.disable:
            now = time.perf_counter()
            if now - self.start >= 0.5 and now - self.last >= 5.0:
                self.last = now
                print(f"arapkit: simulating: step {frame} of {self.total}",
                      file=sys.stderr, flush=True)
        return False

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def run(args: argparse.Namespace) -> int:
    """Execute ``arapkit simulate``; returns the exit status."""
    from arapkit.io.frames import save_frames
    from arapkit.workflows.simulation import SimulationJob, run_simulation

    t0 = time.perf_counter()
    _check_energy(args.energy)
    _check_outputs(args)
    job = SimulationJob(
        mesh=args.mesh, handles=args.handles, transform=args.transform, frames=args.frames,
        ramp=args.ramp, gravity=args.gravity, rings=args.rings, rings_file=args.rings_file,
        weights=args.weights, energy=args.energy, dt=args.dt, stiffness=args.stiffness,
        density=args.density, damping=args.damping, mass=args.mass, tol=args.tol,
        max_iter=args.max_iter, accelerate=args.accelerate, groups=args.groups,
    )
    progress = _FrameProgress(args.frames - 1, args.quiet)
    try:
        out = run_simulation(job, note=lambda m: note(m, args.quiet), callback=progress)
    finally:
        progress.close()
    traj = out.trajectory
    if args.gravity is None:
        note(f"gravity {_vec(out.gravity)} m/s^2, {out.gravity_reason}; set it with "
             "--gravity GX GY GZ", args.quiet)
    stalled = int((~traj.converged).sum())
    if stalled:
        note(f"{stalled} of {len(traj.converged)} steps stopped at --max-iter {args.max_iter} "
             f"before the relative decrease fell below {args.tol:g}", args.quiet)
    lost: list[str] = []
    written = save_frames(args.output, traj.vertices, traj.faces, traj.times, like=out.mesh,
                          warnings=lost)
    for line in lost:
        warn(line)
    if args.figure:
        _figure(args, out)
    _summary(args, out, written, time.perf_counter() - t0)
    return 0


def _figure(args: argparse.Namespace, out: Any) -> None:
    from arapkit.plots.figures import save_figure
    from arapkit.plots.filmstrip import filmstrip_figure, pick_frames

    traj = out.trajectory
    ks = pick_frames(len(traj.vertices), 6)
    fig = filmstrip_figure(
        traj.faces, [traj.vertices[k] for k in ks], [float(traj.times[k]) for k in ks],
        handles=traj.handles, view=args.view, up=args.up,
        title=f"{Path(args.mesh).name}: stiffness {args.stiffness:g} N/m, damping "
              f"{args.damping:g}/s, dt {args.dt:.4g} s, g {_vec(out.gravity)}")
    save_figure(fig, args.figure)


def _vec(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:.4g}" for x in v) + "]"


def _summary(args: argparse.Namespace, out: Any, written: list[Path], wall: float) -> None:
    traj = out.trajectory
    its = traj.iterations
    shown = str(written[0]) if len(written) == 1 else f"{written[0]} ... {written[-1].name}"
    lines = [
        f"output: {shown}",
        f"frames: {len(traj.vertices)} ({traj.times[-1]:.4g} s at dt {args.dt:.4g} s)",
        f"vertices: {out.mesh.n_vertices}",
        f"handles: {len(traj.handles)}",
        *([f"groups: {out.groups.summary()}"] if out.groups is not None else []),
        f"gravity: {_vec(out.gravity)}",
        "iterations per step: " + (f"mean {its.mean():.1f}, max {its.max()}" if len(its)
                                   else "none (one frame)"),
        f"converged steps: {int(traj.converged.sum())} of {len(traj.converged)}",
        f"energy at the end: kinetic {traj.kinetic[-1]:.6g} J, elastic "
        f"{traj.elastic[-1]:.6g} J",
        f"time_s: {wall:.3f}",
    ]
    if args.figure:
        lines.append(f"figure: {args.figure}")
    print("\n".join(lines))
