"""``arapkit learn``: learn a per-vertex rigidity map from a set of deforming shapes.

The shapes share one connectivity: several mesh files (listed, as a glob, or a folder) or
``.npz`` files holding ``V`` (frames x vertices x 3) and ``F``. Each ``.npz``, folder or glob
is a sequence; with several, each sequence's energy table is computed on its own (as a Dask
task with ``--scheduler``) and the tables are averaged by example count. The result is one ring size
per vertex of the reference, written as text (one r per line) for
``arapkit deform --rings-file``.

The default omega is ``auto`` (see :func:`arapkit.learn.fit.auto_omega`), not the paper's 0.3:
on skinned animations 0.3 gives r_max on nearly every vertex, i.e. no map at all. The
paper's value stays one option away (``--omega 0.3``), and the omega used is printed.

Examples
--------
::

    arapkit learn walk.npz -o rings.txt --figure rings.png
    arapkit learn frames/ -o rings.txt --reference 3 --omega 0.3
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from arapkit.cli.common import (
    RingProgress,
    add_example_epilog,
    add_view_options,
    add_weld_option,
    positive_int,
)
from arapkit.errors import InputError, require_extra
from arapkit.io import readable_formats
from arapkit.mesh.weights import DEFAULT_WEIGHTS, WEIGHT_KINDS

# the frames are read by the library; their names stay importable here
from arapkit.workflows.learning import (
    Frames,
    FramesLearned,
    check_connectivity,
    expand_frames,
    learn_from_frames,
    load_frames,
)

__all__ = ["Frames", "add_parser", "expand_frames", "load_frames", "parse_omega", "run"]

EXAMPLES = [
    "arapkit learn examples/finger-bend.npz -o rings.txt --figure rings.png",
    "arapkit learn 'poses/*.obj' -o rings.txt --ply rings.ply",
    "arapkit learn poses/ -o rings.txt --reference 2 --omega 0.3",
    "arapkit learn walk.npz run.npz jump.npz -o rings.txt --scheduler tcp://127.0.0.1:8786",
    "arapkit deform examples/finger.off --handles examples/handles/rotate-limb.json "
    "--rings-file rings.txt -o out.ply",
]


def parse_omega(text: str) -> float | str:
    """argparse type: ``auto`` or a number >= 0.

    Examples
    --------
    >>> parse_omega("0.3"), parse_omega("AUTO")
    (0.3, 'auto')
    """
    if text.strip().lower() == "auto":
        return "auto"
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or 'auto', got {text!r}") from None
    if not np.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"must be a number >= 0 or 'auto', got {text}")
    return value


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``learn`` with its options."""
    p = subparsers.add_parser(
        "learn",
        help="learn per-vertex rigidity r from deforming shapes (paper sec. 3.4)",
        description="Learn a ring size r per vertex from shapes that share one connectivity "
        "(Chen et al. 2017, sec. 3.4): r_k = argmin_r E_ARAP(k, r) + omega (r_max - r). "
        "A summary goes to stdout, notes and warnings to stderr.",
        **add_example_epilog(EXAMPLES),
    )
    p.add_argument(
        "frames",
        nargs="+",
        metavar="FRAMES",
        help=f"mesh files ({readable_formats()}), globs, folders of meshes, or .npz files with "
        "V (frames x vertices x 3) and F; each .npz, folder or glob is one sequence",
    )
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="rigidity map: text, one r per line (or .npy)")
    p.add_argument("--reference", type=int, default=0, metavar="I",
                   help="index of the reference frame (default 0, the first)")
    p.add_argument("--r-min", type=positive_int, default=1, metavar="N",
                   help="smallest ring size (default 1)")
    p.add_argument("--r-max", type=positive_int, default=6, metavar="N",
                   help="largest ring size (default 6)")
    p.add_argument("--omega", type=parse_omega, default="auto", metavar="W",
                   help="rigidity preference: a number (the paper uses 0.3) or 'auto', the "
                   "mean energy increment per ring (default auto)")
    kinds = WEIGHT_KINDS
    p.add_argument("--weights", default=DEFAULT_WEIGHTS, choices=kinds,
                   help=f"edge weights: {', '.join(kinds)} (default {DEFAULT_WEIGHTS})")
    p.add_argument("--figure", metavar="FILE",
                   help="the reference coloured by r, 1 blue ... 6+ red, from the front and "
                   "the back (.png, .pdf, .svg)")
    add_view_options(p)
    p.add_argument("--ply", metavar="FILE", help="the reference as PLY with a 'rings' property")
    p.add_argument("--energies", metavar="FILE",
                   help="table E_ARAP(k, r), one row per vertex (.npy, or text otherwise)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="compute each sequence's energy table as a task on this Dask cluster "
                   "(tcp://HOST:PORT; needs pip install 'arapkit[batch]')")
    p.add_argument("--force", action="store_true", help="allow overwriting an input file")
    add_weld_option(p)
    p.add_argument("--quiet", "-q", action="store_true", help="no notes on stderr")
    return p


# -- running -------------------------------------------------------------------------------


def _check_outputs(args: argparse.Namespace, inputs: list[str]) -> None:
    """Fail before any work on an output that cannot be written."""
    from arapkit.io import check_figure_format, check_output_path, mesh_format

    if args.output.lower().endswith((".ply", ".ply.gz")):
        raise InputError(f"{args.output}: the rigidity map is text or .npy; "
                         "use --ply for a PLY with a 'rings' property")
    check_output_path(args.output, inputs, args.force, "output")
    if args.ply:
        check_output_path(args.ply, inputs, args.force, "PLY")
        if mesh_format(args.ply)[0] != "ply":
            raise InputError(f"{args.ply}: --ply needs a .ply (or .ply.gz) file name")
    if args.figure:
        require_extra("matplotlib", "plots", "arapkit learn --figure")
        check_output_path(args.figure, inputs, args.force, "figure")
        check_figure_format(args.figure)
    if args.energies:
        check_output_path(args.energies, inputs, args.force, "energies")


def _warn(message: str) -> None:
    print(f"arapkit: warning: {message}", file=sys.stderr)


def _learn(args, frames: Frames, ref: int) -> FramesLearned:
    """Learn the map, each sequence's table as a Dask task with --scheduler."""
    options = dict(r_min=args.r_min, r_max=args.r_max, omega=args.omega, weights=args.weights,
                   weld=getattr(args, "weld", None))
    if not args.scheduler:
        learned = learn_from_frames(frames, ref, **options)
    else:
        from arapkit.workflows.batch import dask_map, require_dask

        require_dask()
        from distributed import Client

        try:
            client = Client(args.scheduler, timeout=30)
        except (OSError, TimeoutError, ValueError) as e:
            raise InputError(f"{args.scheduler}: cannot reach the Dask scheduler "
                             f"({type(e).__name__}: {e})") from None
        with client:
            if not args.quiet:
                print(f"arapkit: {len(frames.sequences)} sequence(s), energy tables on "
                      f"{args.scheduler}", file=sys.stderr)
            learned = learn_from_frames(frames, ref, **options, map=dask_map(client))
    # warnings are shown even with --quiet: they say the result may be meaningless
    for name in learned.identical:
        _warn(f"{name} is identical to the reference: it carries no information")
    if learned.all_identical:
        _warn("every frame equals the reference, so the map is r_max everywhere")
    return learned


def _write(args, reference, res) -> None:
    from arapkit.io import save_rings
    from arapkit.mesh.welding import to_source

    # a welded reference: the map is written for the input's own vertices
    save_rings(args.output, to_source(reference, res.rings))
    if args.ply:
        from arapkit.io import save_mesh

        for line in save_mesh(args.ply, reference.vertices, like=reference,
                              vertex_properties={"rings": res.rings.astype(np.int32)}):
            _warn(line)
    if args.energies:
        from arapkit.workflows.learning import save_energies

        save_energies(args.energies, reference, res)
    if args.figure:
        from arapkit.plots.figures import rings_figure, save_figure

        title = (f"{reference.name}: learned r from {_examples(res.n_examples)}, "
                 f"omega = {res.omega:.3g} ({res.omega_rule})")
        # the default view gets its opposite too, so no part of the map stays hidden
        views = ("front", "back") if args.view == "front" else (args.view,)
        save_figure(rings_figure(reference.vertices, reference.faces, res.rings, res.r_min,
                                 res.r_max, title=title, views=views, up=args.up),
                    args.figure, dpi=150)


def _examples(n: int) -> str:
    return "1 example" if n == 1 else f"{n} examples"


def run(args: argparse.Namespace) -> int:
    """Run ``arapkit learn``; returns the exit status (InputError propagates as status 2)."""
    t0 = time.perf_counter()
    if args.r_max < args.r_min:
        raise InputError(f"--r-max ({args.r_max}) must be >= --r-min ({args.r_min})")
    _check_outputs(args, [f for f in args.frames if os.path.isfile(f)])
    frames = load_frames(args.frames)
    if len(frames) < 2:
        raise InputError(f"{', '.join(frames.names) or 'no frames'}: learning needs at least "
                         f"two frames (a reference and an example), got {len(frames)}")
    ref = args.reference
    if not 0 <= ref < len(frames):
        raise InputError(f"--reference {ref} is out of range: there are {len(frames)} frames "
                         f"(0..{len(frames) - 1})")
    check_connectivity(frames, ref)
    with RingProgress(disable=args.quiet):  # r_max's rings on a large mesh take a while
        learned = _learn(args, frames, ref)
    reference, res = learned.reference, learned.result
    _write(args, reference, res)
    counts = ", ".join(f"{r}: {c}" for r, c in res.histogram().items())
    print(f"learned r for {len(res.rings)} vertices of {frames.names[ref]} from "
          f"{_examples(res.n_examples)}; omega = {res.omega:.4g} ({res.omega_rule})")
    print(f"vertices per r: {counts}")
    print(f"wrote {args.output} in {time.perf_counter() - t0:.2f} s "
          f"(energies {res.timings['energy_s']:.2f} s)")
    sys.stdout.flush()
    return 0
