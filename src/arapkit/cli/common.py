"""Helpers shared by the subcommands: argument types, mesh loading, progress bar."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

import numpy as np

from arapkit import validate
from arapkit.errors import InputError

__all__ = [
    "Progress",
    "iteration_cap",
    "load_mesh_checked",
    "note",
    "port",
    "positive_float",
    "positive_int",
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
#: argparse type: a TCP port (1..65535)
port = _option_type(validate.port, "port")
#: argparse type: an upload cap in MiB (finite, > 0)
upload_mb = _option_type(validate.upload_mb, "upload_mb")


def load_mesh_checked(path: str):
    """:func:`arapkit.load_mesh`, turning any parse failure into an :class:`InputError`.

    A loader that trips over a malformed file (IndexError, ValueError ...) means the file
    is bad, not that arapkit is broken, so the user gets exit status 2 and a one-liner.
    """
    from arapkit import load_mesh

    try:
        return load_mesh(path)
    except InputError:
        raise
    except (ValueError, IndexError, KeyError, EOFError, UnicodeDecodeError, OSError,
            OverflowError) as e:
        raise InputError(f"{path}: cannot read mesh ({type(e).__name__}: {e})") from None


def note(message: str, quiet: bool) -> None:
    """Informational line on stderr (stdout is reserved for results)."""
    if not quiet:
        print(f"arapkit: {message}", file=sys.stderr)


class Progress:
    """tqdm progress bar on stderr fed by :meth:`arapkit.Deformer.solve`'s callback.

    Shows iteration, energy and relative decrease. It only appears once a solve has run
    for ``delay`` seconds, so quick solves print nothing.

    Examples
    --------
    >>> with Progress(total=10, disable=True) as p:
    ...     p(1, 2.0, None)
    False
    """

    def __init__(
        self, total: int | None = None, disable: bool = False, delay: float = 0.5, desc: str = ""
    ) -> None:
        from tqdm import tqdm

        self._bar = tqdm(
            total=total,
            disable=disable,
            delay=delay,
            file=sys.stderr,
            desc=desc or "solving",
            unit="it",
            dynamic_ncols=True,
            leave=False,
        )
        self._prev: float | None = None

    def __call__(self, iteration: int, energy: float, vertices: Any) -> bool:
        rel = float("nan")
        if self._prev is not None and self._prev != 0:
            rel = (self._prev - energy) / abs(self._prev)
        self._prev = energy
        self._bar.update(max(iteration - self._bar.n, 0))
        self._bar.set_postfix_str(f"energy {energy:.4g}, rel. decrease {rel:.2e}", refresh=False)
        return False

    def close(self) -> None:
        self._bar.close()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def rings_summary(rings: np.ndarray) -> dict[str, Any]:
    """Compact description of a rigidity map for reports.

    Examples
    --------
    >>> rings_summary(np.array([2, 2, 6]))
    {'min': 2, 'max': 6, 'counts': {'2': 2, '6': 1}}
    """
    values, counts = np.unique(np.asarray(rings), return_counts=True)
    return {
        "min": int(values.min()),
        "max": int(values.max()),
        "counts": {str(int(v)): int(c) for v, c in zip(values, counts, strict=True)},
    }


def add_example_epilog(examples: list[str]) -> dict[str, Callable | str]:
    """Keyword arguments for ``add_parser`` that show ``examples`` verbatim in ``--help``."""
    return {
        "epilog": "examples:\n" + "\n".join(f"  {e}" for e in examples),
        "formatter_class": argparse.RawDescriptionHelpFormatter,
    }
