"""What an r-ring build will cost, known before it starts: memory, time, and whether it fits.

The neighbourhoods of :mod:`arapkit.arap.rings` hold, for every vertex k, the edges of
``N(k, r_k)`` (5 bytes each: an edge id and its layer) and the vertices they touch with
their coefficients (28 bytes each). Both grow as ``r^2`` on a surface until a ring covers
its component: r = 100 on a 13,826-vertex mesh holds 8 GB. So before building, the size
is *estimated*: a breadth-first search from a sample of vertices counts, layer by layer,
how many vertices and edges each ring holds, for every r up to the vertex's own at once.
The vertices are sampled per value of r (stratified: a painted region of large r is
never missed), :data:`SAMPLES` of them in all, every vertex where there are fewer; each
value's total is its count times the sample mean plus two standard errors (an upper
estimate, exact when the whole group was searched). The sample searches cost a few
milliseconds to a few tenths of a second, against seconds to minutes for the build.

:func:`check_ring_memory` refuses, in one line, a build whose estimated peak exceeds the
memory available (read from the operating system, or :data:`RING_MEMORY_VARIABLE`), and
names the largest r that would fit. The accuracy, measured against real builds, is in
``docs/benchmarks.md`` ("r-ring build: cost estimate").

Examples
--------
>>> from arapkit.mesh.shapes import bar
>>> m = bar()
>>> cost = estimate_ring_cost(m.n_vertices, m.edges, 3)
>>> cost.exact, cost.edge_entries > 0
(False, True)
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

import numba as nb
import numpy as np

from ..errors import Advice, InputError
from ..mesh.topology import vertex_adjacency
from ..validate import MAX_RINGS, number, ring_sizes

__all__ = [
    "BYTES_PER_DISK_ENTRY",
    "BYTES_PER_EDGE_ENTRY",
    "RING_MEMORY_VARIABLE",
    "SAMPLES",
    "RingCost",
    "available_memory",
    "check_ring_memory",
    "estimate_ring_cost",
    "format_bytes",
    "format_seconds",
    "memory_share",
]

#: bytes of one (k, e) entry: the edge id (int32) and its layer (int8)
BYTES_PER_EDGE_ENTRY = 5
#: bytes of one (k, v) disk entry: the vertex id (int32) and ``c_kv`` (3 float64)
BYTES_PER_DISK_ENTRY = 28
#: bytes per vertex of one build thread's scratch (stamp, depth, queue position, queue, slot)
SCRATCH_BYTES_PER_VERTEX = 20
#: vertices searched for an estimate, over all values of r (every vertex of a smaller mesh)
SAMPLES = 512
#: fewest vertices searched for one value of r (all of them where it has fewer)
MIN_GROUP_SAMPLES = 32
#: environment variable that replaces the memory available to a ring build (MiB)
RING_MEMORY_VARIABLE = "ARAPKIT_RING_MEMORY_MB"
#: seconds per edge entry and per disk entry of the build on one thread of an idle machine
#: (13,750 vertices, r = 10 ... 50: 54-105 ns per edge plus two disk entries, see
#: ``docs/benchmarks.md``); the build runs on every thread numba has. A busy machine is
#: slower in proportion to its load
SECONDS_PER_EDGE_ENTRY = 8.0e-8
SECONDS_PER_DISK_ENTRY = 1.6e-7


@dataclass(frozen=True)
class RingCost:
    """The estimated cost of building one rigidity map's r-ring neighbourhoods.

    Attributes
    ----------
    n_vertices : int
    edge_entries, disk_entries : int
        Estimated ``sum_k |N(k, r_k)|`` and the number of (k, v) disk entries.
    bytes : int
        Size of the finished structure.
    peak_bytes : int
        Memory the build holds at its peak (the structure, the counts and the threads'
        scratch; twice the structure when the energy blends in a membrane term).
    seconds : float
        Estimated build time on this machine's threads.
    exact : bool
        Every vertex was searched: the counts are exact.
    """

    n_vertices: int
    edge_entries: int
    disk_entries: int
    bytes: int
    peak_bytes: int
    seconds: float
    exact: bool

    def describe(self) -> str:
        """``"about 2.1 GiB and 14 s"``: the estimate in a few words.

        Examples
        --------
        >>> RingCost(10, 100, 50, 3 * 2**30, 3 * 2**30, 75.0, False).describe()
        'about 3.0 GiB and 1.2 min'
        """
        return f"about {format_bytes(self.peak_bytes)} and {format_seconds(self.seconds)}"


def format_bytes(b: float) -> str:
    """A size in MiB or GiB, for messages.

    Examples
    --------
    >>> format_bytes(3 * 2**20), format_bytes(12.8 * 2**30)
    ('3 MiB', '12.8 GiB')
    """
    if b >= 2**30:
        return f"{b / 2**30:.1f} GiB"
    return f"{max(b / 2**20, 1.0):.0f} MiB"


def format_seconds(s: float) -> str:
    """A duration in s, min or h, for messages.

    Examples
    --------
    >>> format_seconds(0.04), format_seconds(14.2), format_seconds(200), format_seconds(9000)
    ('0.04 s', '14 s', '3.3 min', '2.5 h')
    """
    if s < 1.0:
        return f"{s:.2f} s"
    if s < 60.0:
        return f"{s:.0f} s"
    if s < 3600.0:
        return f"{s / 60:.1f} min"
    return f"{s / 3600:.1f} h"


# ------------------------------------------------------------------------ sampled search
@nb.njit(cache=True, nogil=True)
def _layer_counts(k, r, adj_ptr, adj_nbr, stamp, depth, pos, queue, hv, he):
    """BFS from k to depth r: ``hv[d]`` vertices at depth d, ``he[l]`` edges of layer l.

    An edge belongs to layer ``l = 1 + min(depth)`` of its ends (the build's rule); it is
    counted from whichever end leaves the queue first.
    """
    stamp[k] = k
    depth[k] = 0
    pos[k] = 0
    queue[0] = k
    hv[0] += 1
    head, tail = 0, 1
    while head < tail:
        u = queue[head]
        pu = head
        head += 1
        d = depth[u]
        if d >= r:
            continue
        for t in range(adj_ptr[u], adj_ptr[u + 1]):
            v = adj_nbr[t]
            if stamp[v] != k:
                stamp[v] = k
                depth[v] = d + 1
                pos[v] = tail
                queue[tail] = v
                tail += 1
                hv[d + 1] += 1
            elif pos[v] < pu:
                continue
            he[d + 1] += 1


@nb.njit(parallel=True, cache=True, nogil=True)
def _sample_layers(samples, depths, adj_ptr, adj_nbr, scratch, hv, he):
    """Layer histograms of the searches from ``samples`` to ``depths`` into hv, he."""
    for s in nb.prange(len(samples)):
        t = nb.get_thread_id()
        _layer_counts(samples[s], depths[s], adj_ptr, adj_nbr, scratch[0, t], scratch[1, t],
                      scratch[2, t], scratch[3, t], hv[s], he[s])


@dataclass(frozen=True)
class _Curves:
    """Per value of r: its vertex count and the sampled cumulative ring sizes."""

    values: np.ndarray  # (G,) the distinct r
    counts: np.ndarray  # (G,) vertices with each
    group: list[np.ndarray]  # per value: rows of the sample
    cum_v: np.ndarray  # (S, width) vertices within depth d
    cum_e: np.ndarray  # (S, width) edges of layers <= d
    exact: bool

    def totals(self, depth_of: Callable[[np.ndarray], np.ndarray], cap: int) -> tuple[int, int]:
        """Upper estimates of the disk and edge entries with r capped at ``cap``."""
        disk = edges = 0.0
        for g, (value, count) in enumerate(zip(self.values, self.counts, strict=True)):
            rows = self.group[g]
            d = int(depth_of(np.array([min(int(value), cap)]))[0])
            for cum, acc in ((self.cum_v, 0), (self.cum_e, 1)):
                x = cum[rows, d].astype(np.float64)
                m = len(rows)
                # the finite-population correction makes an exhaustive group exact
                spread = (x.std(ddof=1) * math.sqrt(max(0.0, 1.0 - m / count) / m)
                          if m > 1 else 0.0)
                total = count * (x.mean() + 2.0 * spread)
                if acc == 0:
                    disk += total
                else:
                    edges += total
        return int(math.ceil(disk)), int(math.ceil(edges))


def _sample(n: int, edges: np.ndarray, rings: np.ndarray,
            depth_of: Callable[[np.ndarray], np.ndarray], samples: int, seed: int) -> _Curves:
    values, inverse, counts = np.unique(rings, return_inverse=True, return_counts=True)
    rng = np.random.default_rng(seed)
    order = np.argsort(inverse, kind="stable")
    starts = np.concatenate([[0], np.cumsum(counts)])
    chosen, group, exact = [], [], True
    for g, count in enumerate(counts):
        members = order[starts[g]:starts[g + 1]]
        want = min(int(count), max(MIN_GROUP_SAMPLES, round(samples * count / n)))
        if want < count:
            members = rng.choice(members, want, replace=False)
            exact = False
        group.append(np.arange(len(chosen), len(chosen) + len(members)))
        chosen.extend(members.tolist())
    picks = np.asarray(chosen, dtype=np.int64)
    depths = depth_of(rings[picks]).astype(np.int32)
    width = int(depths.max()) + 1
    ptr, nbr, _ = vertex_adjacency(n, edges)
    hv = np.zeros((len(picks), width), dtype=np.int64)
    he = np.zeros((len(picks), width), dtype=np.int64)
    scratch = np.empty((4, nb.get_num_threads(), n), dtype=np.int32)
    scratch[0] = -1  # stamps: each search marks what it visited with its start vertex
    _sample_layers(picks, depths, ptr, nbr, scratch, hv, he)
    return _Curves(values, counts, group, np.cumsum(hv, axis=1), np.cumsum(he, axis=1), exact)


def _cost(n: int, m: int, disk: int, edges: int, blended: bool, exact: bool) -> RingCost:
    per_edge = BYTES_PER_EDGE_ENTRY + (8 if blended else 0)  # + each entry's weight
    # + r (int32) and the two row pointers (int64) per vertex, d_e (int64) per edge
    size = edges * per_edge + disk * BYTES_PER_DISK_ENTRY + 20 * (n + 1) + 8 * m
    threads = nb.get_num_threads()
    # the counts per vertex (2 x int64) and every thread's scratch, besides the structure;
    # a blended energy concatenates its parts into a second copy
    peak = size * (2 if blended else 1) + 16 * n + threads * SCRATCH_BYTES_PER_VERTEX * n
    seconds = (SECONDS_PER_EDGE_ENTRY * edges + SECONDS_PER_DISK_ENTRY * disk) / threads
    return RingCost(n, edges, disk, int(size), int(peak), seconds, exact)


def _identity(r: np.ndarray) -> np.ndarray:
    return r


def estimate_ring_cost(n: int, edges: np.ndarray, rings, *,
                       depth_of: Callable[[np.ndarray], np.ndarray] | None = None,
                       blended: bool = False, samples: int = SAMPLES,
                       seed: int = 0) -> RingCost:
    """Estimate the memory and time of the r-ring build of ``rings`` on an edge graph.

    Parameters
    ----------
    n : int
        Number of vertices.
    edges : (m, 2) int
    rings : int or (n,) int
        r per vertex.
    depth_of : callable, optional
        The rings actually searched for given r (a coarse mesh counting r on a finer
        one, :func:`arapkit.arap.energies.rring.ring_blend`); default: r itself.
    blended : bool
        The energy adds a membrane term (8 more bytes per entry, a second copy at peak).
    samples : int
        Vertices searched in all (every vertex when ``n`` is not larger).
    seed : int
        Seed of the sample (the estimate is deterministic).

    Examples
    --------
    >>> import numpy as np
    >>> E = np.array([[0, 1], [1, 2], [2, 3]])
    >>> c = estimate_ring_cost(4, E, 2)
    >>> c.exact, c.edge_entries, c.disk_entries  # a path: rings of 2, 3, 3, 2 edges
    (True, 10, 14)
    """
    E = np.asarray(edges).reshape(-1, 2)
    r = ring_sizes(rings, n)
    curves = _sample(n, E, r, depth_of or _identity, samples, seed)
    disk, entries = curves.totals(depth_of or _identity, MAX_RINGS)
    return _cost(n, len(E), disk, entries, blended, curves.exact)


# ------------------------------------------------------------------------ memory available
def _read_int(path: str) -> int | None:
    try:
        with open(path) as f:
            text = f.read().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _meminfo_available() -> int | None:
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _cgroup_room() -> int | None:
    """What this process's control group still allows (a container's limit), if any."""
    limit, used = _read_int("/sys/fs/cgroup/memory.max"), _read_int("/sys/fs/cgroup/memory.current")
    if limit is None:  # cgroup v1
        limit = _read_int("/sys/fs/cgroup/memory/memory.limit_in_bytes")
        used = _read_int("/sys/fs/cgroup/memory/memory.usage_in_bytes")
    if limit is None or used is None or limit >= 2**60:
        return None
    return max(0, limit - used)


#: how many builds share the memory available (see :func:`memory_share`)
_SHARE: ContextVar[int] = ContextVar("arapkit_ring_memory_share", default=1)


@contextmanager
def memory_share(parts: int) -> Iterator[None]:
    """Let the ring builds inside the block use ``1/parts`` of the memory available.

    For jobs that run side by side on one host (``arapkit batch``): each may use its share,
    so that together they fit. Has no effect on a limit set by :data:`RING_MEMORY_VARIABLE`.

    Examples
    --------
    >>> import os
    >>> os.environ.pop(RING_MEMORY_VARIABLE, None) and None
    >>> whole, _ = available_memory()
    >>> with memory_share(4):
    ...     part, source = available_memory()
    >>> whole is None or abs(part - whole / 4) < whole / 100, source
    (True, 'memory available to each of 4 jobs on this host')
    """
    token = _SHARE.set(max(1, int(parts)))
    try:
        yield
    finally:
        _SHARE.reset(token)


def available_memory() -> tuple[int | None, str]:
    """Bytes a ring build may use, and where the figure comes from.

    :data:`RING_MEMORY_VARIABLE` (MiB) when set; else the memory the operating system
    reports available (Linux ``MemAvailable``, within a container's limit; elsewhere the
    free pages). ``None`` when nothing tells: no build is then refused.

    Examples
    --------
    >>> import os
    >>> os.environ[RING_MEMORY_VARIABLE] = "64"
    >>> available_memory()
    (67108864, 'ARAPKIT_RING_MEMORY_MB')
    >>> del os.environ[RING_MEMORY_VARIABLE]
    """
    text = os.environ.get(RING_MEMORY_VARIABLE)
    if text is not None:
        return int(number(text, RING_MEMORY_VARIABLE, lo=0.0) * 2**20), RING_MEMORY_VARIABLE
    found = _meminfo_available()
    if found is None:
        try:
            found = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (AttributeError, ValueError, OSError):
            found = None
    room = _cgroup_room()
    if room is not None:
        found = room if found is None else min(found, room)
    share = _SHARE.get()
    if share > 1:
        return (None if found is None else found // share,
                f"memory available to each of {share} jobs on this host")
    return found, "memory available"


def _shown(rings: np.ndarray) -> str:
    lo, hi = int(rings.min()), int(rings.max())
    return f"r = {hi}" if lo == hi else f"r up to {hi} (a per-vertex map, {lo}..{hi})"


def check_ring_memory(n: int, edges: np.ndarray, rings, name: str = "mesh", *,
                      depth_of: Callable[[np.ndarray], np.ndarray] | None = None,
                      blended: bool = False) -> RingCost:
    """The estimated cost of a ring build, or a one-line refusal where it would not fit.

    Refused (:class:`~arapkit.errors.InputError`, an :class:`~arapkit.errors.Advice` that
    each door words for its own control of r) when the estimated peak memory exceeds
    :func:`available_memory`; the message names r, the mesh's size, the estimate and the
    largest r that fits.

    Examples
    --------
    >>> import os, numpy as np
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar()
    >>> os.environ[RING_MEMORY_VARIABLE] = "2"
    >>> check_ring_memory(m.n_vertices, m.edges, 30, "bar")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: bar: r = 30 on 1,154 vertices needs about ... for its r-ring \
neighbourhoods (estimated), more than the 2 MiB allowed by ARAPKIT_RING_MEMORY_MB; the \
largest r that fits is ... (rings=...)
    >>> del os.environ[RING_MEMORY_VARIABLE]
    """
    E = np.asarray(edges).reshape(-1, 2)
    r = ring_sizes(rings, n)
    depth = depth_of or _identity
    curves = _sample(n, E, r, depth, SAMPLES, 0)

    def cost_at(cap: int) -> RingCost:
        disk, entries = curves.totals(depth, cap)
        return _cost(n, len(E), disk, entries, blended, curves.exact)

    cost = cost_at(MAX_RINGS)
    budget, source = available_memory()
    if budget is None or cost.peak_bytes <= budget:
        return cost
    lo, hi = 0, int(r.max())  # cost_at(hi) does not fit; find the largest cap that does
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if cost_at(mid).peak_bytes <= budget:
            lo = mid
        else:
            hi = mid
    where = ("allowed by " + source if source == RING_MEMORY_VARIABLE else "of " + source)
    head = (f"{name}: {_shown(r)} on {n:,} vertices needs about "
            f"{format_bytes(cost.peak_bytes)} for its r-ring neighbourhoods (estimated), "
            f"more than the {format_bytes(budget)} {where}; ")
    if lo == 0:
        raise InputError(head + "even r = 1 does not fit (free memory, or decimate the mesh)")
    if r.min() != r.max():
        raise InputError(f"{head}capped at r = {lo} the map fits (lower its largest values)")
    escaped = head.replace("{", "{{").replace("}", "}}")
    raise InputError(Advice(escaped + f"the largest r that fits is {lo} ({{rings}})", rings=lo))
