"""Learn a per-vertex rigidity map r_k from a set of deforming shapes (Chen et al. 2017, 3.4).

For every vertex ``k``, ring size ``r`` in ``[r_min, r_max]`` and example ``m`` (every shape
but the reference)::

    E(k, r, m) = sum_{(i,j) in N(k,r)} w_ij |(p_i^m - p_j^m) - R_k (p_i^1 - p_j^1)|^2

with ``R_k`` the best rotation for that neighbourhood, example and ``r``. It is normalised by
``A(k, r)``, the summed mixed Voronoi areas (on the reference) of the vertices of ``N(k, r)``
(those at graph distance <= r from k), averaged over the examples into ``E_ARAP(k, r)``, and

    r_k = argmin_r  E_ARAP(k, r) + omega (r_max - r).

The neighbourhoods come from one breadth-first search to ``r_max``
(:func:`arapkit.arap.rings.build_neighbourhoods`): ``N(k, r)`` is the prefix of ``N(k, r_max)``
whose entries have layer <= r, so one pass over each neighbourhood accumulates the
covariance of every r. The compiled kernel fits the rotations with
:func:`arapkit.arap.rotations.rotation_from_covariance`, the deformation engine's own kernel.

Choosing omega
--------------
``omega`` trades fit (E_ARAP grows with r where the shape bends) against rigidity. Where
E_ARAP(k, r) is convex in r, r_k is the largest r whose energy increment
``E_ARAP(k, r) - E_ARAP(k, r - 1)`` stays below omega, so omega is a threshold on increments.
The paper's 0.3 (:data:`PAPER_OMEGA`) suits its data sets; on skinned animations, whose
increments are much smaller, it gives r_max almost everywhere (899 of 901 vertices of the
panda walk). ``omega="auto"`` (:func:`auto_omega`) sets the threshold to the *mean* energy
increment per added ring over all vertices and steps (negative increments counted as 0):
a vertex whose energy grows faster than the shape's average gets a smaller r. The mean,
unlike a quantile, does not presume what fraction of the surface bends: parts that move
rigidly have increments near 0 and keep r_max, however large they are, while the joints
dominate the mean. On the panda walk it gives omega = 0.022 (r spread over 1..6, the head
rigid, shoulders and hips soft); on rigid motions, whose energies are rounding noise, the floor
:data:`AUTO_FLOOR` keeps r_max everywhere.

Examples
--------
>>> import numpy as np
>>> from arapkit.mesh.shapes import bar
>>> mesh = bar()
>>> moved = mesh.vertices @ np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]).T  # a rigid turn
>>> res = learn_rings(mesh, [moved], r_max=4)
>>> int(res.rings.min()), res.energies.shape == (mesh.n_vertices, 4)
(4, True)
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial

import numba as nb
import numpy as np

from ..arap.rings import MAX_RINGS, build_neighbourhoods
from ..arap.rotations import rotation_from_covariance
from ..errors import InputError
from ..mesh.model import Mesh
from ..mesh.weights import DEFAULT_WEIGHTS, edge_weights, voronoi_areas

__all__ = [
    "AUTO_FLOOR",
    "PAPER_OMEGA",
    "LearnedRings",
    "auto_omega",
    "combine_energies",
    "learn_rings",
    "learn_rings_sequences",
    "ring_energies",
    "rings_figure",
    "select_rings",
]

#: The paper's omega (sec. 3.4: "omega = 0.3 in all our experiments").
PAPER_OMEGA = 0.3
#: Smallest automatic omega. E_ARAP is dimensionless (energy over area, roughly a squared
#: strain), so an absolute floor is meaningful: 1e-6 treats strains below ~0.1% as rigid.
#: It only matters when the examples are (nearly) rigid motions of the reference, whose
#: energies are rounding noise (1e-16 .. 1e-10 for float32 data) that must not decide r.
AUTO_FLOOR = 1e-6
#: Memory for the per-edge example terms; more examples than fit are processed in batches.
EXAMPLE_BYTES = 256 * 2**20


# -- compiled kernels ------------------------------------------------------------------


@nb.njit(parallel=True, cache=True)
def _edge_terms(P0, Pm, edges, w, wd0, q0, dm, qm):
    """Per-edge data: ``w e^1``, ``w |e^1|^2`` and, per example, ``e^m`` and ``w |e^m|^2``.

    The example terms are stored edge-major, ``dm[e, m]``, so that the energy kernel reads
    all examples of an edge from one cache line.
    """
    M = Pm.shape[0]
    for e in nb.prange(edges.shape[0]):
        i, j = edges[e, 0], edges[e, 1]
        we = w[e]
        s = 0.0
        for a in range(3):
            d = P0[i, a] - P0[j, a]
            wd0[e, a] = we * d
            s += d * d
        q0[e] = we * s
        for m in range(M):
            s = 0.0
            for a in range(3):
                d = Pm[m, i, a] - Pm[m, j, a]
                dm[e, m, a] = d
                s += d * d
            qm[e, m] = we * s


@nb.njit(cache=True)
def _disk_areas(k, edges, edge_idx, edge_layer, e0, e1, areas, r_max, stamp, out):
    """``out[r-1] = A(k, r)`` for r = 1..r_max, from the edges of N(k, r_max) in BFS order.

    A vertex at distance d from k first appears in an edge of layer d (the one from its
    BFS parent; a lower layer would put it closer), so stamping endpoints in edge order
    assigns each vertex of the disk to its own ring.
    """
    for r in range(r_max):
        out[r] = 0.0
    stamp[k] = k
    out[0] = areas[k]
    for t in range(e0, e1):
        layer = edge_layer[t]
        e = edge_idx[t]
        for side in range(2):
            v = edges[e, side]
            if stamp[v] != k:
                stamp[v] = k
                out[layer - 1] += areas[v]
    for r in range(1, r_max):
        out[r] += out[r - 1]


@nb.njit(parallel=True, cache=True)
def _ring_energy_kernel(n, r_min, r_max, edges, edge_ptr, edge_idx, edge_layer, areas,
                        wd0, q0, dm, qm, mean_out, area_out, raw_out, n_chunks):
    """E_ARAP(k, r) for every vertex; optionally the raw E(k, r, m) too.

    For each k, one pass over N(k, r_max) accumulates, for all examples at once,
    ``S_m = sum w e^1 (e^m)^T`` and ``Q_m = sum w (|e^m|^2 + |e^1|^2)`` layer by layer; at
    the end of layer r the best rotation gives ``E(k, r, m) = Q_m - 2 tr(R S_m)``, the
    expanded form of the definition.
    """
    M = dm.shape[1]
    keep_raw = raw_out.shape[0] > 0
    size = (n + n_chunks - 1) // n_chunks
    for c in nb.prange(n_chunks):
        stamp = np.full(n, -1, dtype=np.int64)
        cum_area = np.empty(r_max)
        acc = np.empty((M, 9))
        q = np.empty(M)
        S = np.empty((3, 3))
        R = np.empty((3, 3))
        for k in range(c * size, min(n, (c + 1) * size)):
            e0, e1 = edge_ptr[k], edge_ptr[k + 1]
            _disk_areas(k, edges, edge_idx, edge_layer, e0, e1, areas, r_max, stamp, cum_area)
            acc[:, :] = 0.0
            q[:] = 0.0
            t = e0
            for r in range(1, r_max + 1):
                # N(k, r) = the entries of layer <= r: a prefix, so keep accumulating
                while t < e1 and edge_layer[t] <= r:
                    e = edge_idx[t]
                    a0, a1, a2 = wd0[e, 0], wd0[e, 1], wd0[e, 2]
                    qe = q0[e]
                    for m in range(M):
                        b0, b1, b2 = dm[e, m, 0], dm[e, m, 1], dm[e, m, 2]
                        acc[m, 0] += a0 * b0
                        acc[m, 1] += a0 * b1
                        acc[m, 2] += a0 * b2
                        acc[m, 3] += a1 * b0
                        acc[m, 4] += a1 * b1
                        acc[m, 5] += a1 * b2
                        acc[m, 6] += a2 * b0
                        acc[m, 7] += a2 * b1
                        acc[m, 8] += a2 * b2
                        q[m] += qe + qm[e, m]
                    t += 1
                if r < r_min:
                    continue
                j = r - r_min
                area = cum_area[r - 1]
                area_out[k, j] = area
                total = 0.0
                for m in range(M):
                    for a in range(3):
                        for b in range(3):
                            S[a, b] = acc[m, 3 * a + b]
                    rotation_from_covariance(S, R)
                    tr = 0.0
                    for a in range(3):
                        for b in range(3):
                            tr += R[a, b] * S[b, a]
                    energy = q[m] - 2.0 * tr
                    if keep_raw:
                        raw_out[k, j, m] = energy
                    total += energy
                # a vertex without faces has no area and no information: energy 0
                mean_out[k, j] = total / (M * area) if area > 0.0 else 0.0


def _neighbourhoods(mesh: Mesh, w: np.ndarray, r_max: int):
    """One BFS to r_max for every vertex (the engine's)."""
    return build_neighbourhoods(mesh, w, r_max)


def _chunks(n: int) -> int:
    # small chunks balance the uneven neighbourhood sizes across threads
    return max(1, min(n, 16 * nb.get_num_threads()))


# -- inputs -----------------------------------------------------------------------------


def _as_examples(reference: Mesh, examples) -> np.ndarray:
    """Stack the examples as an (M, n, 3) float64 array, checking their vertex counts."""
    n = reference.n_vertices
    if isinstance(examples, np.ndarray) and examples.ndim == 3:
        items = list(examples)
    elif isinstance(examples, (Mesh, np.ndarray)):
        items = [examples]
    else:
        items = list(examples)
    if not items:
        raise InputError("learning needs at least one example besides the reference (got none)")
    out = np.empty((len(items), n, 3))
    for m, item in enumerate(items):
        if isinstance(item, Mesh):
            if item.n_vertices != n:
                raise InputError(
                    f"example {m} ({item.name}) has {item.n_vertices} vertices, "
                    f"the reference {n}"
                )
            if item.faces.shape != reference.faces.shape or not np.array_equal(
                item.faces, reference.faces
            ):
                raise InputError(
                    f"example {m} ({item.name}) has different faces from the reference "
                    f"({item.n_faces} vs {reference.n_faces}): all shapes must share one "
                    "connectivity"
                )
            V = item.vertices
        else:
            V = np.asarray(item, dtype=np.float64)
            if V.ndim != 2 or V.shape[1] != 3:
                raise InputError(f"example {m}: vertices must have shape (n, 3), got {V.shape}")
            if len(V) != n:
                raise InputError(f"example {m} has {len(V)} vertices, the reference {n}")
        if not np.isfinite(V).all():
            raise InputError(f"example {m} has non-finite coordinates")
        out[m] = V
    return out


def _check_range(r_min: int, r_max: int) -> tuple[int, int]:
    if int(r_min) != r_min or int(r_max) != r_max:
        raise InputError(f"r_min and r_max must be integers, got {r_min} and {r_max}")
    r_min, r_max = int(r_min), int(r_max)
    if r_min < 1:
        raise InputError(f"r_min must be >= 1, got {r_min}")
    if r_max < r_min:
        raise InputError(f"r_max ({r_max}) must be >= r_min ({r_min})")
    if r_max > min(MAX_RINGS, 127):  # edge layers are stored as int8
        raise InputError(f"r_max must be <= {min(MAX_RINGS, 127)}, got {r_max}")
    return r_min, r_max


# -- public API ---------------------------------------------------------------------------


def ring_energies(
    reference: Mesh,
    examples,
    r_min: int = 1,
    r_max: int = 6,
    weights: str | np.ndarray = DEFAULT_WEIGHTS,
    per_example: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Normalised r-ring ARAP energies of every vertex (the table the paper minimises).

    Parameters
    ----------
    reference : Mesh
        The reference shape (the paper's model 1).
    examples : (M, n, 3) array, or sequence of (n, 3) arrays or Meshes
        The other shapes, same vertex order (and faces, for Meshes) as the reference.
    r_min, r_max : int
        Ring sizes to evaluate.
    weights : str or (E,) array
        Edge-weight kind for :func:`arapkit.mesh.weights.edge_weights`, or the weights of
        ``reference.edges`` themselves.
    per_example : bool
        Also return the raw energies ``E(k, r, m)``.

    Returns
    -------
    energies : (n, r_max - r_min + 1) float64
        ``E_ARAP(k, r)``: ``E(k, r, m) / A(k, r)`` averaged over the examples.
    areas : (n, r_max - r_min + 1) float64
        ``A(k, r)``.
    raw : (n, r_max - r_min + 1, M) float64 or None
        ``E(k, r, m)`` when ``per_example``.

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar()
    >>> E, A, _ = ring_energies(m, [m.vertices * [1.0, 1.0, 1.2]], r_max=3)
    >>> bool((E >= -1e-12).all() and (np.diff(A, axis=1) >= 0).all())
    True
    """
    r_min, r_max = _check_range(r_min, r_max)
    P = _as_examples(reference, examples)
    w = edge_weights(reference, weights) if isinstance(weights, str) else np.asarray(
        weights, dtype=np.float64
    )
    if w.shape != (len(reference.edges),):
        raise InputError(f"weights: expected {len(reference.edges)} values, got {w.shape}")
    nbh = _neighbourhoods(reference, w, r_max)
    return _energies_from(reference, P, nbh, w, r_min, r_max, per_example)


def _energies_from(reference, P, nbh, w, r_min, r_max, per_example):
    n, E, M = reference.n_vertices, reference.edges, len(P)
    nr = r_max - r_min + 1
    areas = voronoi_areas(reference)
    mean, area = np.zeros((n, nr)), np.empty((n, nr))
    raw_all = np.empty((n, nr, M)) if per_example else None
    # the per-edge example terms take 32 bytes per edge and example: bound them
    batch = max(1, min(M, EXAMPLE_BYTES // max(1, 32 * len(E))))
    for b0 in range(0, M, batch):
        Pb = P[b0:b0 + batch]
        mb = len(Pb)
        wd0, q0 = np.empty((len(E), 3)), np.empty(len(E))
        dm, qm = np.empty((len(E), mb, 3)), np.empty((len(E), mb))
        _edge_terms(reference.vertices, Pb, E, w, wd0, q0, dm, qm)
        part = np.empty((n, nr))
        raw = np.empty((n, nr, mb)) if per_example else np.empty((0, 0, 0))
        _ring_energy_kernel(n, r_min, r_max, E, nbh.edge_ptr, nbh.edge_idx, nbh.edge_layer,
                            areas, wd0, q0, dm, qm, part, area, raw, _chunks(n))
        mean += part * (mb / M)
        if raw_all is not None:
            raw_all[:, :, b0:b0 + mb] = raw
    return mean, area, raw_all


def auto_omega(energies: np.ndarray) -> float:
    """Automatic omega: the mean energy increment per added ring, over all vertices.

    ``mean over k and r of max(E_ARAP(k, r + 1) - E_ARAP(k, r), 0)``: negative increments
    (a larger neighbourhood that fits better already favours the larger r) count as 0.
    The result is at least :data:`AUTO_FLOOR`. See the module notes for the reasoning.

    Examples
    --------
    >>> import numpy as np
    >>> auto_omega(np.array([[0.0, 0.1, 0.3], [0.0, 0.0, 0.0]]))
    0.075
    """
    E = np.asarray(energies, dtype=np.float64)
    if E.shape[1] < 2:
        return AUTO_FLOOR  # a single r: omega cannot change anything
    d = np.diff(E, axis=1)
    d = np.where(np.isfinite(d), np.maximum(d, 0.0), 0.0)
    return max(float(d.mean()), AUTO_FLOOR)


def select_rings(energies: np.ndarray, omega: float, r_min: int, r_max: int) -> np.ndarray:
    """``r_k = argmin_r E_ARAP(k, r) + omega (r_max - r)`` (ties go to the larger r).

    Examples
    --------
    >>> import numpy as np
    >>> select_rings(np.array([[0.0, 0.1, 0.5], [0.0, 0.0, 0.0]]), 0.2, 1, 3).tolist()
    [2, 3]
    """
    E = np.asarray(energies, dtype=np.float64)
    r = np.arange(r_min, r_max + 1)
    cost = E + omega * (r_max - r)[None, :]
    # argmin over the reversed columns: on a tie the most rigid choice wins
    return (r_max - np.argmin(cost[:, ::-1], axis=1)).astype(np.int32)


@dataclass
class LearnedRings:
    """Result of :func:`learn_rings`.

    Attributes
    ----------
    rings : (n,) int32
        Learned r per vertex, in ``[r_min, r_max]``.
    energies : (n, r_max - r_min + 1) float64
        ``E_ARAP(k, r)``; column j is r = r_min + j.
    areas : (n, r_max - r_min + 1) float64
        ``A(k, r)``, the normalising areas.
    omega : float
        The omega used.
    omega_rule : str
        ``"given"`` or ``"auto"`` (how omega was chosen).
    r_min, r_max : int
    n_examples : int
        Examples averaged (the reference excluded).
    identical : list of int
        Indices (into ``examples``) of examples equal to the reference; they carry no
        information and only dilute the mean.
    timings : dict
        ``neighbourhood_s`` (BFS), ``energy_s`` (kernel), ``total_s``.
    """

    rings: np.ndarray
    energies: np.ndarray
    areas: np.ndarray
    omega: float
    omega_rule: str
    r_min: int
    r_max: int
    n_examples: int
    identical: list[int] = field(default_factory=list)
    timings: dict = field(default_factory=dict)

    def histogram(self) -> dict[int, int]:
        """Number of vertices per learned r.

        Examples
        --------
        >>> import numpy as np
        >>> LearnedRings(np.array([1, 3, 3]), np.zeros((3, 3)), np.ones((3, 3)), 0.3,
        ...              "given", 1, 3, 1).histogram()
        {1: 1, 2: 0, 3: 2}
        """
        counts = np.bincount(self.rings - self.r_min, minlength=self.r_max - self.r_min + 1)
        return {self.r_min + j: int(c) for j, c in enumerate(counts)}

    def with_omega(self, omega: float | str) -> LearnedRings:
        """The same energies, re-selected with another omega (no recomputation).

        Examples
        --------
        >>> import numpy as np
        >>> res = LearnedRings(np.array([2]), np.array([[0.0, 0.1]]), np.ones((1, 2)), 0.05,
        ...                    "given", 1, 2, 1)
        >>> res.with_omega(1.0).rings.tolist()
        [2]
        """
        value, rule = _resolve_omega(omega, self.energies)
        return LearnedRings(select_rings(self.energies, value, self.r_min, self.r_max),
                            self.energies, self.areas, value, rule, self.r_min, self.r_max,
                            self.n_examples, list(self.identical), dict(self.timings))


def _resolve_omega(omega: float | str, energies: np.ndarray) -> tuple[float, str]:
    if isinstance(omega, str):
        if omega.strip().lower() == "auto":
            return auto_omega(energies), "auto"
        try:
            omega = float(omega)
        except ValueError:
            raise InputError(f"omega must be a number >= 0 or 'auto', got {omega!r}") from None
    value = float(omega)
    if not np.isfinite(value) or value < 0:
        raise InputError(f"omega must be a number >= 0 or 'auto', got {omega!r}")
    return value, "given"


def learn_rings(
    reference: Mesh,
    examples,
    r_min: int = 1,
    r_max: int = 6,
    omega: float | str = PAPER_OMEGA,
    weights: str = DEFAULT_WEIGHTS,
) -> LearnedRings:
    """Learn a per-vertex ring size from example shapes (Chen et al. 2017, sec. 3.4).

    Parameters
    ----------
    reference : Mesh
        The reference shape; the learned map is for its vertices.
    examples : (M, n, 3) array, or sequence of (n, 3) arrays or Meshes
        The other shapes (M >= 1), with the reference's vertex order.
    r_min, r_max : int
        Range of ring sizes (paper: 1 and 6).
    omega : float or "auto"
        Weight of the rigidity preference ``r_max - r``. The paper uses 0.3; ``"auto"`` takes
        the mean energy increment per added ring (:func:`auto_omega`).
    weights : str
        Edge weights (:func:`arapkit.mesh.weights.edge_weights`), cotangent as in the paper.

    Returns
    -------
    LearnedRings

    Raises
    ------
    InputError
        No examples, mismatched vertex counts or faces, bad r range or omega.

    Warns
    -----
    UserWarning
        When some examples are identical to the reference.

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.mesh.shapes import bar
    >>> mesh = bar()
    >>> res = learn_rings(mesh, [mesh.vertices * [1.0, 1.0, 1.3]], r_max=3, omega="auto")
    >>> res.omega_rule, sorted(res.histogram()) == [1, 2, 3]
    ('auto', True)
    """
    t0 = time.perf_counter()
    r_min, r_max = _check_range(r_min, r_max)
    _resolve_omega(omega, np.zeros((1, 1)))  # reject a bad omega before the work
    P = _as_examples(reference, examples)
    identical = [m for m in range(len(P)) if np.array_equal(P[m], reference.vertices)]
    if identical:
        warnings.warn(
            f"{len(identical)} of {len(P)} examples are identical to the reference "
            f"(e.g. example {identical[0]}): they carry no information",
            UserWarning,
            stacklevel=2,
        )
    w = edge_weights(reference, weights)
    t1 = time.perf_counter()
    nbh = _neighbourhoods(reference, w, r_max)
    t2 = time.perf_counter()
    energies, areas, _ = _energies_from(reference, P, nbh, w, r_min, r_max, False)
    t3 = time.perf_counter()
    value, rule = _resolve_omega(omega, energies)
    rings = select_rings(energies, value, r_min, r_max)
    timings = {"neighbourhood_s": t2 - t1, "energy_s": t3 - t2,
               "total_s": time.perf_counter() - t0}
    return LearnedRings(rings, energies, areas, value, rule, r_min, r_max, len(P), identical,
                        timings)


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
    >>> bool(np.allclose(res.energies, learn_rings(mesh, a + b, r_max=3).energies))
    True
    """
    t0 = time.perf_counter()
    r_min, r_max = _check_range(r_min, r_max)
    _resolve_omega(omega, np.zeros((1, 1)))  # reject a bad omega before the work
    seqs = [_as_examples(reference, s) for s in sequences if len(s)]
    if not seqs:
        raise InputError("learning needs at least one example besides the reference (got none)")
    flat = [P for seq in seqs for P in seq]
    identical = [m for m, P in enumerate(flat) if np.array_equal(P, reference.vertices)]
    if identical:
        warnings.warn(
            f"{len(identical)} of {len(flat)} examples are identical to the reference "
            f"(e.g. example {identical[0]}): they carry no information",
            UserWarning,
            stacklevel=2,
        )
    t1 = time.perf_counter()
    task = partial(_sequence_energies, reference=reference, r_min=r_min, r_max=r_max,
                   weights=weights)
    tables = list(map(task, seqs))
    energies = combine_energies([E for E, _ in tables], [len(s) for s in seqs])
    areas = tables[0][1]
    t2 = time.perf_counter()
    value, rule = _resolve_omega(omega, energies)
    rings = select_rings(energies, value, r_min, r_max)
    timings = {"neighbourhood_s": 0.0, "energy_s": t2 - t1, "total_s": time.perf_counter() - t0}
    return LearnedRings(rings, energies, areas, value, rule, r_min, r_max, len(flat), identical,
                        timings)


def rings_figure(
    vertices: np.ndarray,
    faces: np.ndarray,
    rings: np.ndarray,
    r_min: int = 1,
    r_max: int = 6,
    title: str | None = None,
    views: Sequence[str] = ("front", "back"),
    up: str | None = None,
):
    """Figure of a shape coloured by ring size: :func:`arapkit.plots.figures.rings_figure`.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar()
    >>> len(rings_figure(m.vertices, m.faces, [3] * m.n_vertices).axes)  # 2 views + colour bar
    3
    """
    from ..plots.figures import rings_figure as _figure

    return _figure(vertices, faces, rings, r_min, r_max, title=title, views=views, up=up)
