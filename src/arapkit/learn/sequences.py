"""Learning from several sequences: one energy table per sequence, combined.

Each sequence's table is a unit of work (a Dask task with
:func:`arapkit.workflows.batch.dask_map`); the tables are averaged by example count, so the
result does not depend on where they were computed.

Examples
--------
>>> import numpy as np
>>> combine_energies([np.array([[1.0]]), np.array([[4.0]])], [1, 2]).tolist()
[[3.0]]
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from functools import partial

import numpy as np

from ..errors import InputError
from ..mesh.model import Mesh
from ..mesh.weights import DEFAULT_WEIGHTS
from .energies import as_examples, check_ring_range, identical_examples, ring_energies
from .selection import PAPER_OMEGA, LearnedRings, choose_rings, resolve_omega

__all__ = ["combine_energies", "learn_rings_sequences"]


def combine_energies(tables: Sequence[np.ndarray], counts: Sequence[int]) -> np.ndarray:
    """Mean ``E_ARAP`` table of several sequences from their own means and example counts.

    Each table averages its sequence's examples, so the mean over all examples is the
    mean of the tables weighted by example count, accumulated as :func:`ring_energies`
    accumulates its batches of examples (one table gives that table exactly).

    Examples
    --------
    >>> import numpy as np
    >>> combine_energies([np.array([[1.0]]), np.array([[4.0]])], [1, 2]).tolist()
    [[3.0]]
    """
    total = int(sum(counts))
    if total < 1 or len(tables) != len(counts):
        raise InputError("combining energies needs one table per sequence and >= 1 example")
    out = np.zeros_like(np.asarray(tables[0], dtype=np.float64))
    for E, m in zip(tables, counts, strict=True):
        out += np.asarray(E, dtype=np.float64) * (m / total)
    return out


def _sequence_energies(examples: np.ndarray, reference: Mesh, r_min: int, r_max: int,
                       weights: str) -> tuple[np.ndarray, np.ndarray]:
    """One sequence's ``(E_ARAP, A)`` tables: the unit of work of a distributed learn."""
    E, A, _ = ring_energies(reference, examples, r_min, r_max, weights)
    return E, A


def learn_rings_sequences(
    reference: Mesh,
    sequences: Sequence,
    r_min: int = 1,
    r_max: int = 6,
    omega: float | str = PAPER_OMEGA,
    weights: str = DEFAULT_WEIGHTS,
    map: Callable = map,  # noqa: A002 - the builtin's protocol, on purpose
) -> LearnedRings:
    """:func:`learn_rings` over several sequences, one energy table per sequence.

    The tables are computed by ``map(func, sequences)`` (the builtin by default; a Dask
    client's map and gather for a cluster, see :func:`arapkit.workflows.batch.dask_map`) and
    combined by :func:`combine_energies`, so every ``map`` gives the same result. It
    equals :func:`learn_rings` on all examples at once up to rounding (the mean is summed
    per sequence), exactly for one sequence.

    Parameters
    ----------
    reference : Mesh
    sequences : sequence of example stacks
        Each an (M, n, 3) array or a sequence of (n, 3) arrays / Meshes; empty ones are
        ignored. ``LearnedRings.identical`` indexes the examples of all sequences in order.
    r_min, r_max, omega, weights
        As for :func:`learn_rings`.
    map : callable
        ``map(func, items)`` returning the results in order.

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.mesh.shapes import bar
    >>> mesh = bar()
    >>> a, b = [mesh.vertices * [1.0, 1.0, 1.3]], [mesh.vertices * [1.2, 1.0, 1.0]] * 2
    >>> res = learn_rings_sequences(mesh, [a, b], r_max=3, omega="auto")
    >>> from arapkit.learn import learn_rings
    >>> bool(np.allclose(res.energies, learn_rings(mesh, a + b, r_max=3).energies))
    True
    """
    t0 = time.perf_counter()
    r_min, r_max = check_ring_range(r_min, r_max)
    resolve_omega(omega, np.zeros((1, 1)))  # reject a bad omega before the work
    seqs = [as_examples(reference, s) for s in sequences if len(s)]
    if not seqs:
        raise InputError("learning needs at least one example besides the reference (got none)")
    identical = identical_examples(reference, np.concatenate(seqs))
    t1 = time.perf_counter()
    task = partial(_sequence_energies, reference=reference, r_min=r_min, r_max=r_max,
                   weights=weights)
    tables = list(map(task, seqs))
    energies = combine_energies([E for E, _ in tables], [len(s) for s in seqs])
    t2 = time.perf_counter()
    timings = {"neighbourhood_s": 0.0, "energy_s": t2 - t1, "total_s": time.perf_counter() - t0}
    return choose_rings(energies, tables[0][1], omega, r_min, r_max, sum(len(s) for s in seqs),
                        identical, timings)
