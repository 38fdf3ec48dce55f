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
import glob
import os
import re
import sys
import time
import warnings

import numpy as np

from arapkit.cli.common import (
    add_example_epilog,
    add_view_options,
    add_weld_option,
    load_mesh_checked,
    positive_int,
)
from arapkit.errors import InputError, require_extra
from arapkit.io.fileio import load_numpy
from arapkit.mesh.weights import DEFAULT_WEIGHTS, WEIGHT_KINDS
from arapkit.validate import real_array

__all__ = ["Frames", "add_parser", "expand_frames", "load_frames", "parse_omega", "run"]

EXAMPLES = [
    "arapkit learn examples/finger-bend.npz -o rings.txt --figure rings.png",
    "arapkit learn 'poses/*.obj' -o rings.txt --ply rings.ply",
    "arapkit learn poses/ -o rings.txt --reference 2 --omega 0.3",
    "arapkit learn walk.npz run.npz jump.npz -o rings.txt --scheduler tcp://127.0.0.1:8786",
    "arapkit deform examples/finger.off --handles examples/handles/rotate-limb.json "
    "--rings-file rings.txt -o out.ply",
]
_MESH_SUFFIXES = (".off", ".obj", ".ply", ".stl")
_GLOB_CHARS = re.compile(r"[*?\[]")


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
        help="mesh files (OFF, OBJ, PLY, STL), globs, folders of meshes, or .npz files with "
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


# -- input frames ------------------------------------------------------------------------


class Frames:
    """Vertex positions of all frames, their shared faces and a name for each frame.

    Attributes
    ----------
    vertices : list of (n, 3) float64
    faces : (m, 3) int64, or None for mesh files (each file has its own, checked later)
    names : list of str
    meshes : list of Mesh or None (mesh files only)
    sequences : list of list of int
        Frame indices of each sequence (each .npz, folder or glob; listed files together).
    """

    def __init__(self, vertices, faces, names, meshes=None, sequences=None) -> None:
        self.vertices, self.faces, self.names, self.meshes = vertices, faces, names, meshes
        self.sequences = sequences if sequences is not None else [list(range(len(names)))]

    def __len__(self) -> int:
        return len(self.names)


def _natural_key(path: str) -> list:
    # frame_2 before frame_10
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", path)]


def _is_mesh_file(name: str) -> bool:
    low = name.lower()
    return low.endswith(_MESH_SUFFIXES) or low.endswith(tuple(s + ".gz" for s in _MESH_SUFFIXES))


def expand_frames(items: list[str]) -> list[str]:
    """Files named by ``items``: files as given, folders and globs expanded in natural order.

    Examples
    --------
    >>> expand_frames(["/no/such/*.obj"])
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: /no/such/*.obj: no files match
    """
    paths: list[str] = []
    for item in items:
        if os.path.isdir(item):
            found = sorted((os.path.join(item, f) for f in os.listdir(item) if _is_mesh_file(f)),
                           key=_natural_key)
            if not found:
                raise InputError(f"{item}: folder holds no mesh files (OFF, OBJ, PLY, STL)")
            paths += found
        elif not os.path.exists(item) and _GLOB_CHARS.search(item):
            found = sorted((f for f in glob.glob(item) if os.path.isfile(f)), key=_natural_key)
            if not found:
                raise InputError(f"{item}: no files match")
            paths += found
        else:
            if not os.path.exists(item):
                raise InputError(f"{item}: file not found")
            paths.append(item)
    return paths


def _load_npz(path: str, alone: bool = True) -> Frames:
    arrays = load_numpy(path, ["V", "F"])
    V, F = arrays["V"], arrays["F"]
    if V.ndim != 3 or V.shape[2] != 3:
        raise InputError(f"{path}: 'V' must have shape (frames, vertices, 3), got {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3:
        raise InputError(f"{path}: 'F' must have shape (triangles, 3), got {F.shape}")
    if len(V) < (2 if alone else 1):
        raise InputError(f"{path}: holds {len(V)} frame(s); learning needs at least two "
                         "(a reference and an example)")
    V = real_array(V, f"{path}: 'V'")
    F = real_array(F, f"{path}: 'F'", dtype=None)
    bad = ~np.isfinite(V).all(axis=2)
    if bad.any():
        frame, vertex = (int(i[0]) for i in np.nonzero(bad))
        raise InputError(f"{path}: frame {frame} has a non-finite coordinate at vertex {vertex} "
                         f"({int(bad.any(axis=1).sum())} such frames)")
    names = [f"{os.path.basename(path)}[{i}]" for i in range(len(V))]
    return Frames([v.astype(np.float64) for v in V], F, names)


def _sequence_paths(items: list[str]) -> list[list[str]]:
    """Files per sequence: each .npz, folder or glob is one; consecutive listed files one."""
    groups: list[list[str]] = []
    loose = False  # the last group holds individually listed mesh files
    for item in items:
        paths = expand_frames([item])
        single = len(paths) == 1 and paths[0] == item and not item.lower().endswith(".npz")
        if single and loose:
            groups[-1] += paths
            continue
        for p in paths:
            if p.lower().endswith(".npz"):
                groups.append([p])
        meshes = [p for p in paths if not p.lower().endswith(".npz")]
        if meshes:
            groups.append(meshes)
        loose = single
    return groups


def _load_npz_sequences(paths: list[str]) -> Frames:
    # one sequence must hold two frames; several may hold one each (the first is the reference)
    parts = [_load_npz(p, alone=len(paths) == 1) for p in paths]
    F = parts[0].faces
    for p, part in zip(paths[1:], parts[1:], strict=True):
        if part.faces.shape != F.shape or not np.array_equal(part.faces, F):
            raise InputError(f"{p}: faces differ from {paths[0]}: all sequences must share "
                             "one connectivity")
    seqs, start = [], 0
    for part in parts:
        seqs.append(list(range(start, start + len(part))))
        start += len(part)
    return Frames([v for part in parts for v in part.vertices], F,
                  [name for part in parts for name in part.names], sequences=seqs)


def load_frames(items: list[str]) -> Frames:
    """Read the frames named on the command line (see :func:`expand_frames`).

    Each ``.npz``, folder or glob is one sequence, and so are mesh files listed one after
    the other; ``Frames.sequences`` records them.

    Examples
    --------
    >>> load_frames(["/no/such.npz"])
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: /no/such.npz: file not found
    """
    groups = _sequence_paths(items)
    paths = [p for g in groups for p in g]
    npz = [p for p in paths if p.lower().endswith(".npz")]
    if npz:
        if len(npz) != len(paths):
            raise InputError(f"{npz[0]}: a .npz holds a whole sequence; give .npz files alone, "
                             f"not with {len(paths) - len(npz)} mesh file(s)")
        return _load_npz_sequences(npz)
    meshes = [load_mesh_checked(p) for p in paths]
    seqs, start = [], 0
    for g in groups:
        seqs.append(list(range(start, start + len(g))))
        start += len(g)
    return Frames([m.vertices for m in meshes], None, list(paths), meshes, seqs)


def _check_connectivity(frames: Frames, ref: int) -> None:
    """Every frame must have the reference's vertex count and (for mesh files) faces."""
    n = len(frames.vertices[ref])
    ref_name = os.path.basename(frames.names[ref])  # the path is in the message already
    for name, V in zip(frames.names, frames.vertices, strict=True):
        if len(V) != n:
            raise InputError(f"{name}: has {len(V)} vertices but the reference {ref_name} "
                             f"has {n}: all frames must share one mesh")
    if frames.meshes is None:
        return
    F0 = frames.meshes[ref].faces
    for path, m in zip(frames.names, frames.meshes, strict=True):
        if m.faces.shape != F0.shape or not np.array_equal(m.faces, F0):
            why = f" (loader: {'; '.join(m.notes)})" if m.notes else ""
            raise InputError(f"{path}: faces differ from the reference {ref_name}: all "
                             f"frames must share one connectivity{why}")


# -- running -------------------------------------------------------------------------------


def _check_outputs(args: argparse.Namespace, inputs: list[str]) -> None:
    """Fail before any work on an output that cannot be written."""
    from arapkit.io.fileio import check_figure_format, check_output_path, mesh_format

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


def _learn_sequences(args, frames: Frames, ref: int, reference):
    """One energy table per sequence (a Dask task each with --scheduler), combined."""
    from arapkit.learn.fit import learn_rings_sequences

    seqs = [[frames.vertices[i] for i in seq if i != ref] for seq in frames.sequences]
    if getattr(reference, "welded_from", None) is not None:
        from arapkit.mesh.welding import weld_frame

        seqs = [[weld_frame(reference, p) for p in seq] for seq in seqs]
    if not args.scheduler:
        return learn_rings_sequences(reference, seqs, args.r_min, args.r_max, args.omega,
                                     args.weights)
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
            print(f"arapkit: {len(seqs)} sequence(s), energy tables on {args.scheduler}",
                  file=sys.stderr)
        return learn_rings_sequences(reference, seqs, args.r_min, args.r_max, args.omega,
                                     args.weights, map=dask_map(client))


def _learn(args, frames: Frames, ref: int):
    from arapkit import Mesh
    from arapkit.learn.fit import learn_rings

    if frames.meshes is not None:
        reference = frames.meshes[ref]
    else:
        reference = Mesh(frames.vertices[ref], frames.faces, name=frames.names[ref])
    others = [i for i in range(len(frames)) if i != ref]
    poses = [frames.vertices[i] for i in others]
    if getattr(args, "weld", None) is not None:
        from arapkit.mesh.welding import weld, weld_frame

        # every frame shares the reference's vertices, so one weld map serves them all
        reference = weld(reference, args.weld)
        poses = [weld_frame(reference, p) for p in poses]
    with warnings.catch_warnings():
        # identical frames are reported below by file name instead
        warnings.simplefilter("ignore", UserWarning)
        if len(frames.sequences) > 1 or args.scheduler:
            res = _learn_sequences(args, frames, ref, reference)
        else:
            res = learn_rings(reference, poses, args.r_min, args.r_max, args.omega, args.weights)
    if not (np.isfinite(res.energies).all() and np.isfinite(res.omega)):
        # nothing non-finite is written (the energies file, the choice of r behind the map)
        raise InputError(f"{frames.names[ref]}: the ARAP energies overflow double precision "
                         "(coordinates too large); rescale the frames")
    # warnings are shown even with --quiet: they say the result may be meaningless
    for j in res.identical:
        _warn(f"{frames.names[others[j]]} is identical to the reference: it carries no "
              "information")
    if len(res.identical) == len(others):
        _warn("every frame equals the reference, so the map is r_max everywhere")
    return reference, res


def _write(args, reference, res) -> None:
    from arapkit.io.handles import save_rings
    from arapkit.mesh.welding import to_source

    # a welded reference: the map is written for the input's own vertices
    save_rings(args.output, to_source(reference, res.rings))
    if args.ply:
        from arapkit.io.fileio import save_mesh

        for line in save_mesh(args.ply, reference.vertices, like=reference,
                              vertex_properties={"rings": res.rings.astype(np.int32)}):
            _warn(line)
    if args.energies:
        from arapkit.io.fileio import atomic_open

        energies = to_source(reference, res.energies)
        with atomic_open(args.energies, "wb") as f:
            if args.energies.lower().endswith(".npy"):
                np.save(f, energies)
            else:
                cols = " ".join(f"r{r}" for r in range(res.r_min, res.r_max + 1))
                np.savetxt(f, energies, fmt="%.9g", header=f"E_ARAP(k, r): {cols}")
    if args.figure:
        from arapkit.learn.fit import rings_figure
        from arapkit.plots.figures import save_figure

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
    _check_connectivity(frames, ref)
    reference, res = _learn(args, frames, ref)
    _write(args, reference, res)
    counts = ", ".join(f"{r}: {c}" for r, c in res.histogram().items())
    print(f"learned r for {len(res.rings)} vertices of {frames.names[ref]} from "
          f"{_examples(res.n_examples)}; omega = {res.omega:.4g} ({res.omega_rule})")
    print(f"vertices per r: {counts}")
    print(f"wrote {args.output} in {time.perf_counter() - t0:.2f} s "
          f"(energies {res.timings['energy_s']:.2f} s)")
    sys.stdout.flush()
    return 0
