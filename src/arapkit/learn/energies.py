"""The r-ring ARAP energy table ``E_ARAP(k, r)`` of example shapes (Chen et al. 2017, 3.4).

For every vertex ``k``, ring size ``r`` in ``[r_min, r_max]`` and example ``m`` (every shape
but the reference)::

    E(k, r, m) = sum_{(i,j) in N(k,r)} w_ij |(p_i^m - p_j^m) - R_k (p_i^1 - p_j^1)|^2

with ``R_k`` the best rotation for that neighbourhood, example and ``r``. It is normalised by
``A(k, r)``, the summed mixed Voronoi areas (on the reference) of the vertices of ``N(k, r)``
(those at graph distance <= r from k), and averaged over the examples into ``E_ARAP(k, r)``.

The neighbourhoods come from one breadth-first search to ``r_max``
(:func:`arapkit.arap.rings.build_neighbourhoods`): ``N(k, r)`` is the prefix of ``N(k, r_max)``
whose entries have layer <= r, so one pass over each neighbourhood accumulates the
covariance of every r. The compiled kernel fits the rotations with
:func:`arapkit.arap.rotations.rotation_from_covariance`, the deformation engine's own kernel.

Examples
--------
>>> from arapkit.mesh.shapes import bar
>>> m = bar()
>>> E, A, _ = ring_energies(m, [m.vertices * [1.0, 1.0, 1.2]], r_max=3)
>>> E.shape == A.shape == (m.n_vertices, 3)
True
"""

from __future__ import annotations

import time
import warnings

import numba as nb
import numpy as np

from ..arap.rings import MAX_RINGS, build_neighbourhoods
from ..arap.rotations import rotation_from_covariance
from ..errors import InputError
from ..mesh.model import Mesh
from ..mesh.weights import DEFAULT_WEIGHTS, edge_weights, voronoi_areas

__all__ = ["EXAMPLE_BYTES", "as_examples", "check_ring_range", "energy_tables",
           "identical_examples", "ring_energies"]

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


def _chunks(n: int) -> int:
    # small chunks balance the uneven neighbourhood sizes across threads
    return max(1, min(n, 16 * nb.get_num_threads()))


# -- inputs -----------------------------------------------------------------------------


def as_examples(reference: Mesh, examples) -> np.ndarray:
    """Stack the examples as an (M, n, 3) float64 array, checking their vertex counts.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar()
    >>> as_examples(m, [m.vertices, m]).shape == (2, m.n_vertices, 3)
    True
    """
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


def check_ring_range(r_min: int, r_max: int) -> tuple[int, int]:
    """The range of ring sizes to learn from, as integers: ``1 <= r_min <= r_max``, with
    ``r_max`` within the engine's cap.

    Examples
    --------
    >>> check_ring_range(1.0, 6)
    (1, 6)
    """
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


def identical_examples(reference: Mesh, P: np.ndarray) -> list[int]:
    """Indices of the examples equal to the reference, with a warning when there are any
    (they carry no information and only dilute the mean).

    Examples
    --------
    >>> import warnings
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar()
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     identical_examples(m, as_examples(m, [m.vertices * 2, m.vertices]))
    [1]
    """
    identical = [m for m in range(len(P)) if np.array_equal(P[m], reference.vertices)]
    if identical:
        warnings.warn(
            f"{len(identical)} of {len(P)} examples are identical to the reference "
            f"(e.g. example {identical[0]}): they carry no information",
            UserWarning,
            stacklevel=3,  # the caller of learn_rings
        )
    return identical


# -- the table ---------------------------------------------------------------------------


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
    r_min, r_max = check_ring_range(r_min, r_max)
    P = as_examples(reference, examples)
    w = edge_weights(reference, weights) if isinstance(weights, str) else np.asarray(
        weights, dtype=np.float64
    )
    if w.shape != (len(reference.edges),):
        raise InputError(f"weights: expected {len(reference.edges)} values, got {w.shape}")
    return energy_tables(reference, P, w, r_min, r_max, per_example)


def energy_tables(
    reference: Mesh,
    P: np.ndarray,
    w: np.ndarray,
    r_min: int,
    r_max: int,
    per_example: bool = False,
    timings: dict | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """:func:`ring_energies` of checked inputs: ``P`` from :func:`as_examples`, edge
    weights ``w``, a range from :func:`check_ring_range`.

    ``timings``, when given, receives ``neighbourhood_s`` (the BFS) and ``energy_s``
    (the kernel).

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> from arapkit.mesh.weights import edge_weights
    >>> m = bar()
    >>> E, A, _ = energy_tables(m, as_examples(m, [m.vertices]), edge_weights(m), 1, 2)
    >>> E.shape == A.shape == (m.n_vertices, 2), float(abs(E).max()) < 1e-12
    (True, True)
    """
    t0 = time.perf_counter()
    # one BFS to r_max; the per-vertex regrouping (vdisk_*) serves the solver only
    nbh = build_neighbourhoods(reference, w, r_max)
    t1 = time.perf_counter()
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
    if timings is not None:
        timings.update(neighbourhood_s=t1 - t0, energy_s=time.perf_counter() - t1)
    return mean, area, raw_all
