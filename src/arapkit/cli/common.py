"""Helpers shared by the subcommands: argument types, mesh loading, progress bar."""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from typing import Any

from arapkit import validate
from arapkit.errors import InputError
from arapkit.mesh.neighbours import MAX_NEIGHBOURS

__all__ = [
    "Progress",
    "RingProgress",
    "add_graph_options",
    "add_weld_option",
    "graph_options",
    "add_view_options",
    "iteration_cap",
    "maybe_weld",
    "note",
    "port",
    "positive_float",
    "positive_int",
    "neighbour_count",
    "ring_size",
    "tolerance",
    "upload_mb",
]


def _option_type(check: Callable[[str, str], Any], name: str) -> Callable[[str], Any]:
    """An argparse ``type`` running a :mod:`arapkit.validate` rule on the option's text.

    argparse prefixes the option name itself, so the rule's own prefix is dropped.
    """

    def parse(text: str) -> Any:
        try:
            return check(text, "value")
        except InputError as e:
            raise argparse.ArgumentTypeError(str(e).removeprefix("value: ")) from None

    parse.__name__ = name  # argparse names the type in some messages
    return parse


#: argparse type: an integer >= 1 (bounded, no overflow)
positive_int = _option_type(lambda t, w: validate.integer(t, w, lo=1), "positive_int")
#: argparse type: a finite number > 0
positive_float = _option_type(lambda t, w: validate.number(t, w, lo=0.0, lo_open=True),
                              "positive_float")
#: argparse type: the convergence tolerance (finite, >= 0)
tolerance = _option_type(validate.tolerance, "tolerance")
#: argparse type: an iteration cap (1..10^9)
iteration_cap = _option_type(validate.iteration_cap, "iteration_cap")
#: argparse type: a ring size r (1..MAX_RINGS)
ring_size = _option_type(validate.ring_size, "ring_size")
#: argparse type: a point cloud's neighbour count k (1..MAX_NEIGHBOURS)
neighbour_count = _option_type(lambda t, w: validate.integer(t, w, lo=1, hi=MAX_NEIGHBOURS),
                               "neighbour_count")
#: argparse type: a TCP port (1..65535)
port = _option_type(validate.port, "port")
#: argparse type: an upload cap in MiB (finite, > 0)
upload_mb = _option_type(validate.upload_mb, "upload_mb")


def add_view_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--view`` and ``--up`` to a command that draws figures.

    Read them back with ``view=args.view, up=args.up`` for the functions of
    :mod:`arapkit.plots.figures` (``up`` None means the guess of
    :func:`arapkit.mesh.orientation.guess_up`).

    Examples
    --------
    >>> p = argparse.ArgumentParser(); add_view_options(p)
    >>> a = p.parse_args(["--view", "iso", "--up=-y"]); a.view, a.up
    ('iso', '-y')
    """
    from arapkit.mesh.orientation import AXES, VIEWS

    def axis(text: str) -> str:
        t = text.strip().lower()
        t = "+" + t if t in ("x", "y", "z") else t
        if t not in AXES:
            raise argparse.ArgumentTypeError(f"expected one of {', '.join(AXES)}, got {text!r}")
        return t

    parser.add_argument(
        "--view",
        choices=VIEWS,
        default="front",
        help="camera of the figures: front looks along the thinnest horizontal axis "
        "(default front)",
    )
    parser.add_argument(
        "--up",
        type=axis,
        default=None,
        metavar="AXIS",
        help=f"axis pointing up in the figures: {', '.join(AXES)}; write a negative one as "
        "--up=-y (default: guessed; arapkit info prints the guess)",
    )


def weld_tolerance(text: str) -> float:
    """argparse type: a finite number >= 0 (the weld distance relative to the diagonal).

    Examples
    --------
    >>> weld_tolerance("1e-6")
    1e-06
    """
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value) or value < 0 or value >= 1:
        raise argparse.ArgumentTypeError(f"must be a number in [0, 1), got {text}")
    return value


def add_weld_option(p: argparse.ArgumentParser) -> None:
    """``--weld [TOL]``: merge coincident vertices for the solve (see
    :mod:`arapkit.mesh.welding`)."""
    from arapkit.mesh.welding import WELD_TOL

    p.add_argument(
        "--weld",
        nargs="?",
        const=WELD_TOL,
        default=None,
        type=weld_tolerance,
        metavar="TOL",
        help="merge vertices closer than TOL times the bounding-box diagonal "
        f"(default {WELD_TOL:g}) for the solve, for triangle soups and split-vertex files; "
        "results are written to the input's own vertices (put it after MESH, or write "
        "--weld=TOL)",
    )


def add_graph_options(p: argparse.ArgumentParser) -> None:
    """``--neighbours K`` / ``--radius R``: a point cloud's graph (:class:`arapkit.PointCloud`)."""
    from arapkit.mesh.neighbours import DEFAULT_NEIGHBOURS

    g = p.add_mutually_exclusive_group()
    g.add_argument("--neighbours", "-k", type=neighbour_count, default=None, metavar="K",
                   help="a point cloud's graph: each point linked to its K nearest "
                   f"(symmetrised; default {DEFAULT_NEIGHBOURS})")
    g.add_argument("--radius", type=positive_float, default=None, metavar="R",
                   help="a point cloud's graph: every pair of points closer than R instead")


def graph_options(args: argparse.Namespace) -> dict[str, Any]:
    """The ``neighbours`` / ``radius`` keywords of :func:`arapkit.io.load_shape` that
    :func:`add_graph_options` parsed (None each where not given, or not offered).

    Examples
    --------
    >>> graph_options(argparse.Namespace(neighbours=6))
    {'neighbours': 6, 'radius': None}
    """
    return {"neighbours": getattr(args, "neighbours", None),
            "radius": getattr(args, "radius", None)}


def maybe_weld(mesh, tol: float | None):
    """``mesh`` welded with ``tol`` (relative), or ``mesh`` itself when ``tol`` is None."""
    if tol is None:
        return mesh
    from arapkit.mesh.welding import weld

    return weld(mesh, tol)


def note(message: str, quiet: bool) -> None:
    """Informational line on stderr (stdout is reserved for results)."""
    if not quiet:
        print(f"arapkit: {message}", file=sys.stderr)


def warn(message: str) -> None:
    """Warning line on stderr, shown even with --quiet (something was not written)."""
    print(f"arapkit: warning: {message}", file=sys.stderr)


class Progress:
    """Solver progress on stderr, fed by :meth:`arapkit.Deformer.solve`'s callback.

    On a terminal: a tqdm bar (iteration, energy, relative decrease) that appears once a
    solve has run for ``delay`` seconds, so quick solves print nothing. Elsewhere (a log
    file, a pipe, CI) a bar's carriage returns would garble the log, so a plain line is
    printed instead, after ``delay`` seconds and then every ``interval`` seconds.

    Examples
    --------
    >>> with Progress(total=10, disable=True) as p:
    ...     p(1, 2.0, None)
    False
    """

    def __init__(
        self,
        total: int | None = None,
        disable: bool = False,
        delay: float = 0.5,
        desc: str = "",
        interval: float = 5.0,
    ) -> None:
        self._desc = desc or "solving"
        self._disable, self._delay, self._interval = disable, delay, interval
        self._bar = None
        self._start = time.perf_counter()
        self._last_line = -math.inf
        if not disable and _is_terminal(sys.stderr):
            from tqdm import tqdm

            self._bar = tqdm(
                total=total,
                delay=delay,
                file=sys.stderr,
                desc=self._desc,
                unit="it",
                dynamic_ncols=True,
                leave=False,
            )
        self._prev: float | None = None

    def __call__(self, iteration: int, energy: float, vertices: Any) -> bool:
        status = f"energy {energy:.4g}"
        if self._prev is not None and self._prev != 0:
            # the first iteration has nothing to compare with: no "nan" for a user to read
            status += f", rel. decrease {(self._prev - energy) / abs(self._prev):.2e}"
        self._prev = energy
        if self._bar is not None:
            self._bar.update(max(iteration - self._bar.n, 0))
            self._bar.set_postfix_str(status, refresh=False)
        elif not self._disable:
            now = time.perf_counter()
            if now - self._start >= self._delay and now - self._last_line >= self._interval:
                self._last_line = now
                print(f"arapkit: {self._desc}: iteration {iteration}, {status}",
                      file=sys.stderr, flush=True)
        return False

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class RingProgress:
    """Progress of the r-ring builds run inside the block, on stderr.

    A long build (estimated at a second or more: r = 50 on 14K vertices takes about 15 s)
    first says what it will cost, then shows a tqdm bar on a terminal, or a plain line every
    ``interval`` seconds elsewhere. Quick builds print nothing.

    Examples
    --------
    >>> with RingProgress(disable=True):
    ...     pass
    """

    def __init__(self, disable: bool = False, interval: float = 5.0, delay: float = 1.0
                 ) -> None:
        self._disable, self._interval, self._delay = disable, interval, delay
        self._bar: Any = None
        self._started = False
        self._last_line = -math.inf
        self._context: Any = None

    def __call__(self, fraction: float, cost: Any) -> bool:
        if self._disable or cost.seconds < self._delay:
            return False
        if not self._started:
            self._started = True
            print(f"arapkit: building the r-ring neighbourhoods ({cost.describe()}, "
                  "estimated)", file=sys.stderr, flush=True)
            if _is_terminal(sys.stderr):
                from tqdm import tqdm

                self._bar = tqdm(total=100, file=sys.stderr, desc="r-rings", unit="%",
                                 dynamic_ncols=True, leave=False,
                                 bar_format="{desc}: {percentage:3.0f}%|{bar}| "
                                            "[{elapsed}<{remaining}]")
        if self._bar is not None:
            self._bar.update(max(0.0, 100.0 * fraction - self._bar.n))
            if fraction >= 1.0:
                self._bar.close()
                self._bar = None
        else:
            now = time.perf_counter()
            if now - self._last_line >= self._interval and 0.0 < fraction < 1.0:
                self._last_line = now
                print(f"arapkit: r-rings {100 * fraction:.0f}% built", file=sys.stderr,
                      flush=True)
        return False

    def __enter__(self) -> RingProgress:
        from arapkit.arap.rings import ring_progress

        self._context = ring_progress(self)
        self._context.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.close()
        self._context.__exit__(*exc)


def _is_terminal(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # replaced or closed streams
        return False



def add_example_epilog(examples: list[str]) -> dict[str, Callable | str]:
    """Keyword arguments for ``add_parser`` that show ``examples`` verbatim in ``--help``."""
    return {
        "epilog": "examples:\n" + "\n".join(f"  {e}" for e in examples),
        "formatter_class": argparse.RawDescriptionHelpFormatter,
    }
