"""Coarse-to-fine ARAP for large meshes: a decimated proxy previews and starts the exact solve.

At 0.4–2M vertices one local/global iteration costs 0.1–0.4 s on two cores and the
low-frequency part of a deformation needs hundreds of them from rest. The same energy on a
proxy of about 20K vertices (quadric decimation, ``fast-simplification``, MIT) costs a few
milliseconds per iteration and converges in tens, so:

* **preview** (:meth:`MultiresDeformer.preview`): iterate the proxy, warm-started from its
  last shape, and map it to the full mesh by rotation-aware skinning: every full vertex
  ``v`` follows the proxy vertex it was collapsed into and that one's nearest neighbours
  ``q`` (:class:`Binding`), ``x_v = sum_q a_vq (y_q + R_q (v - q))`` (inverse squared
  distance weights), with
  ``R_q`` the proxy's fitted rotation. A rigid motion of the handles gives a rigid proxy
  solution (every ``R_q`` that motion's rotation), so the preview is then exact;
* **solve** (:meth:`MultiresDeformer.solve`): solve the proxy from rest, skin it (through
  the intermediate meshes of ``levels=``, if any, each solved in its turn), and run the
  full-resolution local/global iteration
  (Anderson-accelerated) from there. Every step is deterministic (same targets, same
  start), so the editor's result on release and a script's ``Deformer(...).solve(targets)``
  are the same computation.

The proxy poses the same problem at its own scale: its handles are the proxy vertices bound
to handle vertices, moved by the rigid motion fitted to each connected handle region
(:func:`arapkit.arap.constraints.rigid_motions`) (exact
for the editor's rigid gizmo moves). The proxy is as stiff as the full mesh: it reads the
full mesh's r and counts it in the full mesh's rings (``ring_scale = h_full / h_proxy``, ``h``
the mean edge length): ``max(1, rint(r s))`` rings of its own, and where even one of them is
stiffer than the full mesh's r-ring (r = 1 on a scan's 20K proxy) the one-ring energy is
blended with a rotation per triangle (:mod:`arapkit.arap.energies.rring`). With the plain
one-ring the 20K proxy of the 437K scan was several times stiffer than the scan, and its
solution 1.7 % (p95) / 4.0 % (max) of the diagonal from the scan's minimum.
``docs/interactive.md`` has the measurements behind each choice.

Examples
--------
>>> from arapkit.mesh.shapes import bar, bar_bend
>>> mesh = bar(segments=(60, 8, 8))
>>> h, t = bar_bend(mesh, 60)
>>> d = MultiresDeformer(mesh, h, proxy_vertices=300)
>>> d.proxy_mesh.n_vertices < mesh.n_vertices
True
>>> res = d.solve(t)
>>> bool(res.converged), res.timings["proxy_iterations"] > 0
(True, True)
"""

from __future__ import annotations

import io
import subprocess
import sys
import threading
import time
from collections import OrderedDict
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass

import numba
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..arap.childfactor import factors_in_child
from ..arap.constraints import (
    Followers,
    anchor_components,
    check_handles,
    check_targets,
    rigid_motions,
)
from ..arap.energies.rring import ring_blend
from ..arap.loop import Result
from ..errors import InputError
from ..mesh.model import Mesh
from ..mesh.weights import DEFAULT_WEIGHTS
from ..validate import integer, ring_sizes
from . import decimation_child
from .decimation_child import simplify as simplify_with_homes
from .deformer import MULTIRES_AUTO_VERTICES, Deformer, register_variant
from .registry import method

__all__ = ["AUTO_MIN_VERTICES", "DEFAULT_PROXY_VERTICES", "Binding", "Level",
           "MultiresDeformer", "Preview", "decimate", "decimation", "proxy_rings",
           "specks", "start_decimation"]

#: proxy size: its iteration (5–8 ms on two cores) leaves room for a 30 Hz frame
DEFAULT_PROXY_VERTICES = 20_000
#: ``Deformer(..., multires=None)`` (the default) turns coarse-to-fine on from this size
AUTO_MIN_VERTICES = MULTIRES_AUTO_VERTICES
#: the proxy's own stopping test in :meth:`MultiresDeformer.solve`: tighter than the full
#: solve's, since its iterations are cheap. The stiffness-matched proxy is slow to converge
#: (its bending is soft): at 1e-5 the 437K scan's release took 4.6 s instead of 2.6 s, for
#: an exact result 0.37 % (p95) of the diagonal from the minimum instead of 0.56 %
PROXY_TOL = 1e-4
PROXY_MAX_ITER = 2000
#: the stiffness-matched proxy is soft against bending: solved from rest it settled in a
#: kinked minimum (2.5 % of the diagonal from the full one at its worst vertex, where the
#: same energy continued from the stiff one-ring's solution is 1.3 % away), so it starts
#: from the plain one-ring proxy's solution, solved to this
STIFF_TOL = 1e-4
#: an intermediate mesh's stopping test: its iterations cost a quarter of the full mesh's
LEVEL_TOL = 1e-4
#: points per handle region that fit its rigid motion (a scan's region holds 10^5: fitting
#: them all cost 57 ms a move at 1.75M; a rigid motion is found exactly from any three)
FIT_POINTS = 2048
#: how far ahead a preview's start runs, in moves as long as the last one (a drag move
#: the editor dropped makes the next one twice as long)
LEAD_MAX = 2.0
#: decimated proxies kept in memory, by content hash (re-opening a mesh skips decimation)
_CACHE_SIZE = 4
_cache: OrderedDict[str, tuple[np.ndarray, np.ndarray]] = OrderedDict()
_cache_lock = threading.Lock()


def _content_key(mesh: Mesh, n_target: int) -> str:
    return f"{mesh.content_hash}:{n_target}"


def _frame(mesh: Mesh) -> tuple[np.ndarray, float]:
    """The corner and diagonal of ``mesh``'s bounding box: the decimator's unit frame."""
    return mesh.vertices.min(axis=0), (mesh.bounding_box_diagonal or 1.0)


def specks(mesh: Mesh, n_target: int) -> np.ndarray | None:
    """(n,) bool: the vertices of ``mesh``'s specks at a coarse mesh of ``n_target``
    vertices, or None when it has none to leave out.

    A speck is a part (connected set of faces) of fewer vertices than one coarse vertex
    stands for, ``n / n_target``: a scan's floating debris, too small to be seen at the
    coarse mesh's resolution. The decimator cannot collapse an isolated triangle, so 20,000
    of them round the dragon made its "20K" proxy 51,443 vertices, and every preview
    iteration 2.5 times as dear. They are left out of the decimator's input; a full shape
    made from the proxy places them by the full solve's own rule
    (:meth:`MultiresDeformer.to_full`). None where the mesh is its own coarse mesh, and
    where specks are more than half of it (an unwelded triangle soup: every face a part).

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> b = bar(segments=(60, 8, 8))
    >>> V = np.vstack([b.vertices, np.eye(3) * 9])
    >>> m = Mesh(V, np.vstack([b.faces, np.array([[0, 1, 2]]) + b.n_vertices]))
    >>> int(specks(m, 300).sum()), specks(b, 300) is None
    (3, True)
    """
    own, n_target = _own_proxy(mesh, n_target)  # not the content hash: 0.09 s at 1.75M
    if own:
        return None
    least = mesh.n_vertices // n_target
    labels = mesh.component_labels  # kept by the mesh: the binding asks again
    sizes = np.bincount(labels)[labels]
    small = sizes < least
    small[mesh.unreferenced] = False  # a vertex in no face is in no part
    count = int(small.sum())
    return small if 0 < count <= mesh.n_vertices // 2 else None


def _decimator_input(mesh: Mesh, frame: tuple[np.ndarray, float],
                     n_target: int) -> tuple[np.ndarray, np.ndarray]:
    """The decimator's arrays: vertices in the unit ``frame`` (:func:`_frame`), as float32,
    and the faces of every part but the :func:`specks`.

    The decimator's error threshold is absolute (``1e-9 (t + 3)^agg`` at pass ``t``): a
    scan measured in micrometres or millimetres did not reach the target (a 97K-vertex
    "20K" proxy of the dragon scaled to a 10^6 diagonal), and a scan far from the origin
    lost its detail to float32. In the unit frame the proxy is the same at every scale
    and place.
    """
    lo, size = frame
    faces = mesh.faces
    small = specks(mesh, n_target)
    if small is not None:
        faces = faces[~small[faces[:, 0]]]  # a face's corners are in one part
    # writable copies: the wrapper refuses read-only arrays
    return (((mesh.vertices - lo) / size).astype(np.float32),
            np.array(faces, dtype=np.int64))


def _simplify(V: np.ndarray, F: np.ndarray,
              n_target: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """fast-simplification to about ``n_target`` vertices (2 faces per vertex), with each
    input vertex's home (:func:`arapkit.methods.decimation_child.homes`)."""
    return simplify_with_homes(V, F, 2 * n_target)


#: the script a child decimates with (it imports no arapkit: see :func:`_run_child`)
_CHILD = decimation_child.__file__


def _run_child(V: np.ndarray, F: np.ndarray,
               n_target: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_simplify` in a child Python running :mod:`.decimation_child` as a script
    (NumPy and fast-simplification only: it starts in about 0.2 s); raises where it fails."""
    buf = io.BytesIO()
    np.lib.format.write_array(buf, V, allow_pickle=False)
    np.lib.format.write_array(buf, F, allow_pickle=False)
    done = subprocess.run([sys.executable, _CHILD, str(2 * n_target)],
                          input=buf.getvalue(), capture_output=True, check=True, timeout=600)
    out = io.BytesIO(done.stdout)
    return tuple(np.lib.format.read_array(out) for _ in range(3))


def _simplify_in_child(V: np.ndarray, F: np.ndarray,
                       n_target: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_simplify` in a child Python: it holds the GIL for seconds, a child does not.

    Falls back to this process where a child cannot run (an embedded interpreter, a
    missing executable): same library, same input, same result.
    """
    try:
        return _run_child(V, F, n_target)
    except (OSError, TypeError, ValueError, subprocess.SubprocessError):
        # TypeError: no sys.executable (an embedded interpreter)
        return _simplify(V, F, n_target)


def _proxy_arrays(U: np.ndarray, G: np.ndarray, home: np.ndarray,
                  frame: tuple[np.ndarray, float]) -> tuple[np.ndarray, ...]:
    """The decimator's output back in the mesh's frame, without the vertices it left
    unreferenced, and the full vertices' homes renumbered to match."""
    used = np.zeros(len(U), dtype=bool)
    used[G.ravel()] = True
    new = np.cumsum(used) - 1
    lo, size = frame
    # a home is a vertex some face uses: it is kept
    home = np.where(home >= 0, new[np.maximum(home, 0)], -1).astype(np.int32)
    return np.asarray(U, dtype=np.float64)[used] * size + lo, new[G].astype(np.int64), home


def _own_proxy(mesh: Mesh, n_target: int) -> tuple[bool, int]:
    """Whether ``mesh`` is its own proxy (at most twice ``n_target``: decimating it would
    save less than it costs), and the checked ``n_target``."""
    n_target = integer(n_target, "proxy_vertices", lo=100)
    return mesh.n_vertices <= 2 * n_target, n_target


def _proxy_key(mesh: Mesh, n_target: int) -> tuple[str | None, int]:
    """The cache key of ``mesh``'s proxy and the checked ``n_target``; the key is None
    where the mesh is its own proxy (:func:`_own_proxy`)."""
    own, n_target = _own_proxy(mesh, n_target)
    return (None if own else _content_key(mesh, n_target)), n_target


_pending: dict[str, Future] = {}
_child_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="arapkit-decimate")


def start_decimation(mesh: Mesh, n_target: int = DEFAULT_PROXY_VERTICES) -> bool:
    """Start decimating ``mesh`` in a child process; :func:`decimate` then collects it.

    For a caller with other work meanwhile (the editor draws the mesh and loads its kernels
    while the proxy is made): the decimator holds the GIL for seconds in this process, and a
    child runs on another core. Returns whether a decimation was started (not when the mesh
    is its own proxy, or the proxy is cached or already on its way).

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> start_decimation(bar(), 20_000)  # small enough to be its own proxy
    False
    """
    key, n_target = _proxy_key(mesh, n_target)
    if key is None:
        return False
    with _cache_lock:
        if key in _cache or key in _pending:
            return False
        frame = _frame(mesh)
        job = _child_pool.submit(_simplify_in_child, *_decimator_input(mesh, frame, n_target),
                                 n_target)
        _pending[key] = job
    # into the cache when done, whether or not anyone collects it (outside the lock: a job
    # already done runs the callback here and now)
    job.add_done_callback(lambda f: _keep(key, f, frame))
    return True


def _keep(key: str, job: Future, frame: tuple[np.ndarray, float]) -> None:
    """Move a finished child decimation into the cache (a failed one is just forgotten)."""
    arrays = None if job.exception() is not None else _proxy_arrays(*job.result(), frame)
    with _cache_lock:
        _pending.pop(key, None)
        if arrays is not None:
            _store(key, arrays)


def _store(key: str, arrays: tuple[np.ndarray, ...]) -> None:
    """Cache a proxy (``_cache_lock`` held), dropping the least recently used."""
    _cache[key] = arrays
    _cache.move_to_end(key)
    while len(_cache) > _CACHE_SIZE:
        _cache.popitem(last=False)


def decimate(mesh: Mesh, n_target: int = DEFAULT_PROXY_VERTICES) -> Mesh:
    """A proxy of about ``n_target`` vertices by quadric decimation (deterministic, cached).

    Unreferenced vertices the decimator leaves are dropped. A mesh already at most twice
    ``n_target`` is returned as it is: decimating it would save less than it costs. A
    decimation begun by :func:`start_decimation` is waited for.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar(segments=(60, 8, 8))
    >>> p = decimate(m, 300)
    >>> 200 < p.n_vertices < 400 and p.name.endswith("proxy")
    True
    """
    return decimation(mesh, n_target)[0]


def decimation(mesh: Mesh, n_target: int = DEFAULT_PROXY_VERTICES) -> tuple[Mesh, np.ndarray]:
    """:func:`decimate`, and each full vertex's home: the proxy vertex it was collapsed
    into (-1 where it has none: a speck, a vertex in no face, a part collapsed away).

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar(segments=(60, 8, 8))
    >>> p, home = decimation(m, 300)
    >>> home.shape == (m.n_vertices,) and set(home) == set(range(p.n_vertices))
    True
    """
    key, n_target = _proxy_key(mesh, n_target)
    if key is None:
        return mesh, np.arange(mesh.n_vertices, dtype=np.int32)
    with _cache_lock:
        hit = _cache.get(key)
        if hit is not None:
            _cache.move_to_end(key)
        running = _pending.get(key)
    if hit is None and running is not None:
        # the child falls back to this process itself: an error here is the decimator's own
        hit = _proxy_arrays(*running.result(), _frame(mesh))
        # kept here too: the job's done callback (_keep) runs on the pool's thread after
        # result() has returned, so a caller could still find the job pending and no proxy
        with _cache_lock:
            if _pending.get(key) is running:
                del _pending[key]
            _store(key, hit)
    if hit is None:
        frame = _frame(mesh)
        hit = _proxy_arrays(*_simplify(*_decimator_input(mesh, frame, n_target), n_target),
                            frame)
        with _cache_lock:
            _store(key, hit)
    return Mesh(hit[0], hit[1], name=f"{mesh.name} proxy"), hit[2]


#: proxy vertices each full vertex follows at most (inverse squared distance weights;
#: :class:`Binding`): with its one nearest, the cells' seams put the 437K scan's settled
#: preview 0.99 % of the diagonal from the exact result at its worst vertex, 0.65 % with four
SKIN_NEIGHBOURS = 4
#: nearest proxy vertices looked at for those, of which only the full vertex's home and
#: the home's neighbours on the proxy are taken
_CANDIDATES = 8
#: full vertices queried at once (the candidates' arrays: 16 bytes each per candidate)
_QUERY_ROWS = 1 << 18


@numba.njit(parallel=True, cache=True, nogil=True)
def _skin(Y, R, Q, V, near, wts, out):  # pragma: no cover - compiled
    for v in numba.prange(near.shape[0]):
        x0 = x1 = x2 = tot = 0.0
        for j in range(near.shape[1]):
            q = near[v, j]
            w = np.float64(wts[v, j])
            d0, d1, d2 = V[v, 0] - Q[q, 0], V[v, 1] - Q[q, 1], V[v, 2] - Q[q, 2]
            x0 += w * (Y[q, 0] + R[q, 0, 0] * d0 + R[q, 0, 1] * d1 + R[q, 0, 2] * d2)
            x1 += w * (Y[q, 1] + R[q, 1, 0] * d0 + R[q, 1, 1] * d1 + R[q, 1, 2] * d2)
            x2 += w * (Y[q, 2] + R[q, 2, 0] * d0 + R[q, 2, 1] * d1 + R[q, 2, 2] * d2)
            tot += w
        # normalised here, in double: a rigid motion of the proxy stays one to round-off
        out[v, 0] = x0 / tot
        out[v, 1] = x1 / tot
        out[v, 2] = x2 / tot


@numba.njit(parallel=True, cache=True, nogil=True)
def _pick(V, Q, cand, dist, home, adj_ptr, adj_idx, floor, near, wts):  # pragma: no cover
    """Up to ``near.shape[1]`` proxy vertices per full vertex, nearest first among those
    it may follow, with inverse squared distance weights (0 in unused slots).

    A vertex with a home follows the home and the home's neighbours on the proxy that are
    among its candidates; one without follows its nearest candidates. The weights are
    scaled in double to a largest of 1 before they are stored as float32.
    """
    k = near.shape[1]
    for v in numba.prange(cand.shape[0]):
        w = np.zeros(k)
        h = home[v]
        c = 0
        if h >= 0:
            d = np.sqrt((V[v, 0] - Q[h, 0]) ** 2 + (V[v, 1] - Q[h, 1]) ** 2
                        + (V[v, 2] - Q[h, 2]) ** 2)
            near[v, 0] = h
            w[0] = 1.0 / max(d, floor) ** 2
            c = 1
        for j in range(cand.shape[1]):
            if c == k:
                break
            q = cand[v, j]
            if h >= 0:
                if q == h:
                    continue
                found = False
                for t in range(adj_ptr[h], adj_ptr[h + 1]):
                    if adj_idx[t] == q:
                        found = True
                        break
                if not found:
                    continue
            near[v, c] = q
            w[c] = 1.0 / max(dist[v, j], floor) ** 2
            c += 1
        top = w.max()
        for j in range(c):
            wts[v, j] = w[j] / top
        for j in range(c, k):
            near[v, j] = near[v, 0]
            wts[v, j] = 0.0


def full_tree_of(full: np.ndarray) -> cKDTree:
    """The full mesh's k-d tree for :meth:`Binding.between` (unbalanced: it serves one
    query, and builds 2x faster)."""
    return cKDTree(full, balanced_tree=False)


@dataclass(frozen=True)
class Binding:
    """How the full mesh and its proxy correspond at rest.

    Attributes
    ----------
    idx : (n,) int64
        The nearest proxy vertex of each full vertex (a full handle pins it).
    near : (n, k) int32
        The proxy vertices each full vertex follows, which the skinning blends
        ``x_v = sum_q a_vq (y_q + R_q (v - q))``: its home (the proxy vertex it was collapsed
        into) first, then those of the home's neighbours on the proxy that are among the
        full vertex's nearest, up to :data:`SKIN_NEIGHBOURS` (the nearest, where it has no
        home). Bound by distance alone, a full vertex of a thin part followed the other side
        of a narrow gap: on the 1.75M dragon a region 260 edges away on the surface, 7.8 %
        of the diagonal from where the exact solve put it.
    weights : (n, k) float32
        Their weights ``a_vq`` up to a factor per row (inverse squared distances; 0 in
        unused slots).
    full, proxy : (n, 3), (m, 3)
        The rest positions bound (the caller's arrays, not copied).
    near_full : (m,) int64
        The nearest full vertex of each proxy vertex (where the proxy reads r and handles;
        read by homes instead, the 1.75M dragon's proxy had 4,277 handle vertices instead of
        4,238 and its preview's p95 rose from 1.7 % to 3.8 % of the diagonal).
    covered : (n,) bool or None
        Which full vertices the proxy was made from (None: all); the others are
        :func:`specks`, which only follow their nearest proxy vertices.
    """

    idx: np.ndarray
    near: np.ndarray
    weights: np.ndarray
    full: np.ndarray
    proxy: np.ndarray
    near_full: np.ndarray
    covered: np.ndarray | None = None

    @classmethod
    def between(cls, full: np.ndarray, proxy: np.ndarray,
                full_tree: cKDTree | None = None, left_out: np.ndarray | None = None,
                home: np.ndarray | None = None,
                proxy_faces: np.ndarray | None = None) -> Binding:
        """Bind ``full`` (n, 3) rest positions to ``proxy`` (m, 3) ones.

        ``full_tree``: :func:`full_tree_of` ``full``, when made beforehand; ``left_out``:
        the full vertices left out of the proxy, its :func:`specks`; ``home`` (with the
        proxy's faces): each full vertex's home (:func:`decimation`), -1 where it has none.
        Without homes every full vertex follows its nearest proxy vertices.

        Examples
        --------
        >>> import numpy as np
        >>> b = Binding.between(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]),
        ...                     np.array([[0.1, 0, 0], [2.1, 0, 0]]))
        >>> b.idx.tolist(), b.near_full.tolist(), b.near.shape
        ([0, 0, 1], [0, 2], (3, 2))
        """
        full = np.ascontiguousarray(full, dtype=np.float64)
        proxy = np.ascontiguousarray(proxy, dtype=np.float64)
        n, m = len(full), len(proxy)
        k = min(SKIN_NEIGHBOURS, m)
        homes = np.full(n, -1, dtype=np.int32) if home is None else np.asarray(home, np.int32)
        if home is None:
            ptr, nbr = np.zeros(m + 1, dtype=np.int64), np.zeros(0, dtype=np.int32)
        else:
            adj = Mesh(proxy, proxy_faces).adjacency
            ptr, nbr = adj.indptr.astype(np.int64), adj.indices.astype(np.int32)
        near = np.empty((n, k), dtype=np.int32)
        weights = np.empty((n, k), dtype=np.float32)
        idx = np.empty(n, dtype=np.int64)
        tree = cKDTree(proxy)
        c = min(_CANDIDATES if home is not None else k, m)
        # a full vertex on a proxy vertex follows that one alone (to float32's precision);
        # 1 / floor^2 stays finite
        size = max(float(np.linalg.norm(np.ptp(proxy, axis=0))),
                   float(np.linalg.norm(np.ptp(full, axis=0))) if n else 0.0)
        floor = max(1e-9 * size, 1e-150)
        for a in range(0, n, _QUERY_ROWS):  # the queries run on every core
            b = min(n, a + _QUERY_ROWS)
            dist, cand = tree.query(full[a:b], k=c, workers=-1)
            dist, cand = dist.reshape(b - a, c), cand.reshape(b - a, c).astype(np.int32)
            idx[a:b] = cand[:, 0]
            _pick(full[a:b], proxy, cand, dist, homes[a:b], ptr, nbr, floor, near[a:b],
                  weights[a:b])
        if full_tree is None:
            full_tree = full_tree_of(full)
        near_full = full_tree.query(proxy, k=1, workers=-1)[1].astype(np.int64)
        return cls(idx, near, weights, full, proxy, near_full,
                   None if left_out is None else ~left_out)

    @property
    def offsets(self) -> np.ndarray:
        """``v - q`` at rest for each full vertex v and its nearest proxy vertex q."""
        return self.full - self.proxy[self.idx]

    def skin(self, Y: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Full positions from proxy positions ``Y`` (m, 3) and rotations ``R`` (m, 3, 3).

        Examples
        --------
        >>> import numpy as np
        >>> b = Binding.between(np.array([[0.0, 0, 0], [1, 0, 0]]), np.array([[0.0, 0, 0]]))
        >>> Rz = np.array([[[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]])
        >>> b.skin(np.array([[5.0, 0, 0]]), Rz).tolist()
        [[5.0, 0.0, 0.0], [5.0, 1.0, 0.0]]
        """
        out = np.empty((len(self.idx), 3))
        _skin(np.ascontiguousarray(Y, dtype=np.float64), np.ascontiguousarray(R, np.float64),
              self.proxy, self.full, self.near, self.weights, out)
        return out


_kernels_loaded = threading.Event()


def _load_kernels() -> None:
    """Load the compiled local/global kernels once per process, on a 50-vertex problem.

    Loading them from numba's cache takes about 0.4 s of a large mesh's opening: done while
    :func:`start_decimation`'s child works, it is off the path to the first preview.
    """
    if _kernels_loaded.is_set():
        return
    from ..mesh.shapes import bar, bar_bend

    m = bar(segments=(4, 2, 2))
    h, t = bar_bend(m, 30)
    # with a callback: the preview's solves watch every iteration
    Deformer(m, h, accelerate=True, free_components="follow", multires=False).solve(
        t, max_iter=2, callback=lambda *_: False)
    Binding.between(m.vertices, m.vertices[:8]).skin(m.vertices[:8], np.tile(np.eye(3), (8, 1, 1)))
    _kernels_loaded.set()


def _can_overlap() -> bool:
    """Whether numba's parallel kernels may run on two threads at once.

    Its ``workqueue`` layer (where neither OpenMP nor TBB is found) is not thread-safe:
    there the full problem is built when first needed instead of beside the preview.
    """
    try:
        return numba.threading_layer() != "workqueue"
    except ValueError:  # no parallel kernel has run yet: unknown, so no
        return False


def proxy_rings(rings: np.ndarray, near_full: np.ndarray) -> np.ndarray:
    """The proxy's rigidity map: the full r where each proxy vertex is bound.

    The proxy counts these r in the full mesh's rings (its solver's ``ring_scale`` is
    ``h_full / h_proxy``), so that it is as stiff as the full mesh
    (:mod:`arapkit.arap.energies.rring`).

    Examples
    --------
    >>> import numpy as np
    >>> proxy_rings(np.array([1, 5, 9]), np.array([2, 0])).tolist()
    [9, 1]
    """
    return np.asarray(rings, dtype=np.int32)[near_full]


def _handle_regions(mesh: Mesh, handles: np.ndarray) -> np.ndarray:
    """The connected region (of the handle vertices' own edges) of each handle."""
    pos = np.full(mesh.n_vertices, -1, dtype=np.int64)
    pos[handles] = np.arange(len(handles))
    # the edges of the faces with two or more handle corners (no sorted edge list built,
    # nothing the size of all the faces' edges), kept where both ends are handles
    P = pos[mesh.faces]
    P = P[(P >= 0).sum(axis=1) >= 2]
    pairs = np.concatenate([P[:, [0, 1]], P[:, [1, 2]], P[:, [2, 0]]])
    a, b = pairs[(pairs[:, 0] >= 0) & (pairs[:, 1] >= 0)].T
    n = len(handles)
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _region_sample(region: np.ndarray, most: int) -> np.ndarray:
    """Up to ``most`` evenly spaced members of each region (indices into ``region``)."""
    order = np.argsort(region, kind="stable")
    counts = np.bincount(region) if len(region) else np.zeros(0, np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    picks = [order[a + np.unique(np.linspace(0, c - 1, min(c, most)).astype(np.int64))]
             for a, c in zip(starts, counts)]
    return np.sort(np.concatenate(picks)) if picks else np.zeros(0, np.int64)


def coarse_handles(binding: Binding, handles: np.ndarray, region: np.ndarray,
                   n_full: int) -> tuple[np.ndarray, np.ndarray]:
    """A coarser mesh's handles: its vertices bound to a full handle, with their regions.

    Those whose nearest full vertex is a handle, and the nearest of each handle vertex
    (so that a one-vertex handle is not lost); each takes the region of the handle it
    reads (``region``: the region of each row of ``handles``).

    Examples
    --------
    >>> import numpy as np
    >>> b = Binding.between(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]),
    ...                     np.array([[0.1, 0, 0], [2.1, 0, 0]]))
    >>> [a.tolist() for a in coarse_handles(b, np.array([2]), np.array([0]), 3)]
    [[1], [0]]
    """
    pos = np.full(n_full, -1, dtype=np.int64)
    pos[handles] = np.arange(len(handles))
    near = binding.near_full
    q1 = np.flatnonzero(pos[near] >= 0)
    own = np.arange(len(handles))
    covered = None if binding.covered is None else binding.covered[handles]
    if covered is not None and covered.any():
        # a handle on a speck would pin the nearest vertex of another part: the speck
        # follows its handle in the exact solve, the part stays free there
        own = own[covered]
    q = np.concatenate([q1, binding.idx[handles[own]]])
    src = np.concatenate([pos[near[q1]], own])
    picked, first = np.unique(q, return_index=True)
    return picked, region[src[first]]


def _same_targets(a: np.ndarray | None, b: np.ndarray) -> bool:
    """Whether ``a`` holds the targets ``b``: the same array (a drag passes one read-only
    array chunk after chunk, and comparing a scan's 10^5 targets costs about a millisecond)
    or an equal one (a pose submitted again).

    Examples
    --------
    >>> T = np.zeros((2, 3))
    >>> _same_targets(T, T), _same_targets(T.copy(), T), _same_targets(None, T)
    (True, True, False)
    >>> _same_targets(np.zeros((3, 3)), T)
    False
    """
    return a is not None and (a is b or np.array_equal(a, b))


def _repose(solver: Deformer, handles: np.ndarray, rings: np.ndarray) -> None:
    """Give ``solver`` these handles and r where they changed, and factorise it."""
    if not np.array_equal(solver.handles, handles):
        solver.set_handles(handles)
    if not np.array_equal(solver.rings, rings):
        solver.set_rings(rings)
    solver.prepare()


@dataclass
class Level:
    """An intermediate mesh of the exact solve, between the proxy and the full mesh.

    Attributes
    ----------
    mesh : Mesh
        A decimation of the full mesh.
    up : Binding
        This mesh (as "full") against the next coarser one (the proxy for the first level):
        how a coarser solution is skinned onto it.
    full : Binding
        The full mesh against this one: where its handles and r come from, and how its
        solution is skinned onto the full mesh (the last level).
    edge_ratio : float
        ``h_full / h_level``, as :attr:`MultiresDeformer.edge_ratio`.
    solver : Deformer or None
        Its own solver, for the current handles and r (built with the full problem).
    handles, region : (k,) int64
        Its handle vertices and the full handle region each follows.
    """

    mesh: Mesh
    up: Binding
    full: Binding
    edge_ratio: float
    solver: Deformer | None = None
    handles: np.ndarray | None = None
    region: np.ndarray | None = None


@dataclass
class Preview:
    """One preview: the proxy's shape and, mapped from it, the full mesh's.

    Attributes
    ----------
    vertices : (n, 3) or None
        The full mesh's preview (skinned; handles at their targets); None when not asked
        for (``preview(..., full=False)``).
    proxy : Result
        The proxy solve (its ``vertices`` are what the editor draws while dragging).
    """

    vertices: np.ndarray | None
    proxy: Result


class MultiresDeformer:
    """ARAP on a large mesh, coarse to fine: what ``Deformer(..., multires=True)`` returns.

    Same interface as :class:`arapkit.Deformer` (``solve``, ``set_handles``,
    ``set_rings``, ``prepare``, ``problem``, ``notes``), plus :meth:`preview`. ``solve``
    returns the full-resolution result, converged by the full mesh's own test, started from
    the skinned proxy solution.

    Parameters
    ----------
    mesh, handles, rings, weights :
        As for :class:`arapkit.Deformer`.
    proxy_vertices : int
        The proxy's size (default :data:`DEFAULT_PROXY_VERTICES`).
    levels : sequence of int, optional
        Sizes of the intermediate meshes the exact solve passes through between the proxy
        and the full mesh, coarse first (each a decimation of the full mesh, solved to
        :data:`LEVEL_TOL` from the coarser one's skinned solution). Default: none. With
        the stiffness-matched proxy a 100K level under the 437K scan cost 1.1 s of the
        release and saved 0.5-0.8 s of full iterations (``docs/interactive.md``). The
        preview does not use them.
    background : bool
        Build the full-resolution problem and its factor on a background thread (the
        editor: the proxy can preview at once); :meth:`solve` waits for it.
    **options
        :class:`arapkit.Deformer`'s other options, for the full-resolution solve.
        ``accelerate`` defaults to True here (Anderson acceleration on both levels).

    Attributes
    ----------
    proxy_mesh : Mesh
        The decimated proxy.
    proxy : Deformer
        The proxy's own solver (its handles are :meth:`proxy_targets`' rows).
    binding : Binding
        How full and proxy vertices correspond at rest.
    levels : list of Level
        The intermediate meshes, built with the full problem (empty until then).
    edge_ratio : float
        ``h_full / h_proxy``, the mean edge lengths' ratio that scales r onto the proxy.
    lead : bool
        Whether a preview for new targets starts ahead along the drag (see
        :meth:`preview`). False by default: it pays where a preview gets a fixed number
        of iterations a move, not in the editor's 20 ms chunks (``docs/interactive.md``,
        fifteenth pass).

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.mesh.shapes import bar, bar_bend
    >>> mesh = bar(segments=(60, 8, 8))
    >>> h, t = bar_bend(mesh, 60)
    >>> d = MultiresDeformer(mesh, h, proxy_vertices=300)
    >>> p = d.preview(t)
    >>> p.vertices.shape == mesh.vertices.shape
    True
    """

    def __init__(self, mesh: Mesh, handles, rings=1, weights: str = DEFAULT_WEIGHTS, *,
                 proxy_vertices: int = DEFAULT_PROXY_VERTICES, levels=None,
                 background: bool = False, **options) -> None:
        energy = options.get("energy", "rring")
        if not method(energy).multires:
            raise InputError(f"multires: energy '{energy}' cannot be solved coarse to fine "
                             "(use multires=False)")
        t0 = time.perf_counter()
        self.mesh = mesh
        self.energy = energy
        self.handles = check_handles(mesh, handles)
        self._rings = ring_sizes(rings, mesh.n_vertices)
        self._weights = weights
        # acceleration is part of the machinery here: on unless asked off
        if options.get("accelerate") is None:
            options["accelerate"] = True
        self._options = options
        self.accelerate = bool(options["accelerate"])
        self.tol = self._options.get("tol", 1e-3)
        # what needs no proxy first: a child process may still be decimating
        _load_kernels()
        full = np.asarray(mesh.vertices, dtype=np.float64)
        tree = full_tree_of(full)
        _ = mesh.mean_edge_length
        left_out = specks(mesh, proxy_vertices)
        self._index_handles()
        # needs no proxy: 0.5 s at 1.75M off the wait
        self._parts = self._free_parts(None if left_out is None else ~left_out)
        self.proxy_mesh, self._home = decimation(mesh, proxy_vertices)
        self._level_sizes = self._check_levels(levels, proxy_vertices)
        self.levels: list[Level] = []
        self.binding = Binding.between(full, self.proxy_mesh.vertices, tree, left_out,
                                       self._home, self.proxy_mesh.faces)
        self.edge_ratio = mesh.mean_edge_length / max(self.proxy_mesh.mean_edge_length, 1e-300)
        self._bind_handles()
        self.proxy = self._coarse_solver(self.proxy_mesh, self._proxy_handles,
                                         self._proxy_rings(), self.edge_ratio)
        self.proxy.prepare()
        self._stiff: Deformer | None = None
        self._pose_stiff()
        self._open_s = time.perf_counter() - t0
        self._proxy_shape: np.ndarray | None = None
        self.lead = False
        #: the last two moves a preview saw: their proxy targets, and the shape the older one
        #: ended at (see :meth:`_lead_start`)
        self._moves: tuple[np.ndarray | None, np.ndarray, np.ndarray | None] | None = None
        #: the targets the preview has brought the plain one-ring proxy to convergence for
        #: (forgotten with the handles or r)
        self._stiff_done_for: np.ndarray | None = None
        self._checked: np.ndarray | None = None
        self._full: Deformer | None = None
        # the handles and r change a version; the full problem records the one it was built
        # for (comparing 10^6-entry arrays on every access cost milliseconds)
        self._version = 0
        self._built = -1
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="arapkit-full")
        self._pending: Future | None = None
        self._pending_version = -1
        if background:
            self.prepare(background=True)

    # -- the full-resolution problem, built lazily or in the background --------------
    def _coarse_solver(self, mesh: Mesh, handles: np.ndarray, rings: np.ndarray,
                       edge_ratio: float | None) -> Deformer:
        """A coarser mesh's solver: the full problem's method and weights, with r counted in
        the full mesh's rings (``edge_ratio``: ``h_full / h_coarse``; None: its own) where
        the method has a rigidity map, so that the coarse mesh is as stiff as the full one;
        its parts without a handle follow, whatever the full mesh does with its own."""
        scale = {}
        if edge_ratio is not None and method(self.energy).rigidity_map:
            scale["ring_scale"] = self._options.get("ring_scale", 1.0) * edge_ratio
        return Deformer(mesh, handles, rings, self._weights, energy=self.energy,
                        accelerate=True, free_components="follow", multires=False, **scale,
                        **{k: v for k, v in self._options.items()
                           if k in ("sr_alpha", "history")})

    def _pose_stiff(self) -> None:
        """Give the plain one-ring proxy, which the matched proxy's solve from rest starts
        from, the proxy's handles and rings (none where the proxy is not blended)."""
        p = self.proxy
        searched, share = ring_blend(p.rings, p.ring_scale)
        if not (share < 1.0).any():
            self._stiff = None
            return
        if self._stiff is None:
            self._stiff = self._coarse_solver(self.proxy_mesh, p.handles, searched, None)
        _repose(self._stiff, p.handles, searched)

    def _check_levels(self, levels, proxy_vertices: int) -> list[int]:
        n = self.mesh.n_vertices
        if levels is None:
            return []
        try:
            sizes = [integer(k, "levels", lo=1) for k in levels]
        except TypeError:
            raise InputError(f"levels must be a sequence of vertex counts, got {levels!r}") \
                from None
        lo = self.proxy_mesh.n_vertices
        for k in sizes:
            if not lo < k <= n // 2:
                raise InputError(
                    f"levels: {k} vertices is not between the coarser mesh ({lo}) and half "
                    f"the mesh ({n // 2}); give increasing sizes in that range")
            lo = k
        return sizes

    def _make_levels(self) -> None:
        """Decimate and bind the intermediate meshes (once: they depend on the mesh only)."""
        for size in self._level_sizes:  # in a child process: the GIL stays free
            start_decimation(self.mesh, size)
        full = np.asarray(self.mesh.vertices, dtype=np.float64)
        tree = full_tree_of(full) if self._level_sizes else None
        coarser, coarser_home = self.proxy_mesh, self._home
        for size in self._level_sizes:
            m, home = decimation(self.mesh, size)
            down = Binding.between(full, m.vertices, tree, specks(self.mesh, size), home,
                                   m.faces)
            # a level vertex's home on the coarser mesh: that of the full vertex it reads
            up_home = coarser_home[down.near_full]
            self.levels.append(Level(
                m, Binding.between(m.vertices, coarser.vertices, home=up_home,
                                   proxy_faces=coarser.faces),
                down, self.mesh.mean_edge_length / max(m.mean_edge_length, 1e-300)))
            coarser, coarser_home = m, home

    def _pose_level(self, level: Level, handles: np.ndarray, region: np.ndarray,
                    rings: np.ndarray) -> None:
        """Give ``level`` the full mesh's handles and r, and factorise its solver."""
        lh, lr = coarse_handles(level.full, handles, region, self.mesh.n_vertices)
        lrings = proxy_rings(rings, level.full.near_full)
        if level.solver is None:
            level.solver = self._coarse_solver(level.mesh, lh, lrings, level.edge_ratio)
        _repose(level.solver, lh, lrings)
        level.handles, level.region = lh, lr

    def _build_full(self) -> Deformer:
        version, handles, rings = self._version, self.handles, self._rings
        region = self._region
        if len(self.levels) < len(self._level_sizes):
            self._make_levels()
        for level in self.levels:
            self._pose_level(level, handles, region, rings)
        if self._full is None:
            self._full = Deformer(self.mesh, handles, rings, self._weights, multires=False,
                                  **self._options)
        _repose(self._full, handles, rings)
        self._built = version
        return self._full

    def _build_full_beside(self) -> Deformer:
        """:meth:`_build_full` on the background thread, its large factors made and solved in
        a child process: cholespy holds the GIL throughout, and a factor built here froze
        every other thread (the editor's page and preview: 19 s at 1.75M vertices)."""
        with factors_in_child():
            return self._build_full()

    def _stale(self) -> bool:
        return self._full is None or self._built != self._version

    @property
    def full(self) -> Deformer:
        """The full-resolution :class:`arapkit.Deformer` (waits for a background build)."""
        if self._pending is not None:
            self._pending.result()
            self._pending = None
        if self._stale():
            self._build_full()
        return self._full

    @property
    def full_ready(self) -> bool:
        """Whether the full-resolution factor is built (no wait in :meth:`solve`)."""
        return (self._pending is None or self._pending.done()) and not self._stale()

    def wait_ready(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s for the full factor (built in the background if needed).

        Lets a caller stay responsive while a large factor is being built.
        """
        if self.full_ready:
            return True
        # a finished build may be for handles or r changed since: then build again
        if self._pending is None or self._pending.done():
            self._pending_version = self._version
            self._pending = self._pool.submit(self._build_full_beside)
        try:
            self._pending.result(timeout)
        except FutureTimeout:
            return False
        return self.full_ready

    def prepare(self, background: bool = False) -> None:
        """Build the full-resolution factor now (or on a background thread, where safe)."""
        if background:
            # once per version of the handles and r: a caller may ask on every request
            if _can_overlap() and self._stale() and not (
                    self._pending is not None and not self._pending.done()
                    and self._pending_version == self._version):
                self._pending_version = self._version
                self._pending = self._pool.submit(self._build_full_beside)
        else:
            _ = self.full

    # -- what the proxy sees ------------------------------------------------------------
    def _index_handles(self) -> None:
        """What the full mesh's handles need of the full mesh only: their regions, the
        points their motions are fitted to; the parts' rule is found again on first use."""
        H = self.handles
        self._motions_for: tuple[np.ndarray, tuple[np.ndarray, np.ndarray]] | None = None
        self._last_targets: tuple[np.ndarray, np.ndarray] | None = None
        self._rest_handles = np.asarray(self.mesh.vertices, dtype=np.float64)[H]
        self._region = _handle_regions(self.mesh, H)
        self._n_regions = int(self._region.max()) + 1 if len(H) else 0
        self._fit = _region_sample(self._region, FIT_POINTS)
        self._parts: tuple[np.ndarray, Followers | None, Followers | None] | None = None

    def _bind_handles(self) -> None:
        """Proxy handles: proxy vertices bound to a handle, each with its handle region."""
        self._proxy_handles, self._proxy_region = coarse_handles(
            self.binding, self.handles, self._region, self.mesh.n_vertices)

    def _proxy_rings(self) -> np.ndarray:
        return proxy_rings(self._rings, self.binding.near_full)

    def proxy_targets(self, targets: np.ndarray) -> np.ndarray:
        """Targets of the proxy's handles: each handle region's fitted rigid motion.

        Examples
        --------
        >>> import numpy as np
        >>> from arapkit.mesh.shapes import bar, bar_bend
        >>> mesh = bar(segments=(60, 8, 8))
        >>> h, t = bar_bend(mesh, 0)
        >>> d = MultiresDeformer(mesh, h, proxy_vertices=300)
        >>> Q = d.proxy_mesh.vertices
        >>> bool(np.allclose(d.proxy_targets(t), Q[d.proxy.handles]))
        True
        """
        return self._proxy_targets(self.checked_targets(targets))

    def checked_targets(self, targets) -> np.ndarray:
        """``targets`` validated once, as a read-only array the methods here accept unchecked.

        A drag previews the same targets chunk after chunk; checking a scan's 4 x 10^5
        handle targets costs about 10 ms each time. Being read-only, the returned array
        cannot change between calls, so passing it back skips the check and the fit.

        Examples
        --------
        >>> from arapkit.mesh.shapes import bar, bar_bend
        >>> mesh = bar(segments=(60, 8, 8))
        >>> h, t = bar_bend(mesh, 30)
        >>> d = MultiresDeformer(mesh, h, proxy_vertices=300)
        >>> T = d.checked_targets(t)
        >>> T.flags.writeable, d.checked_targets(T) is T
        (False, True)
        """
        last = self._checked
        if last is not None and targets is last:
            return last
        T = check_targets(self.handles, targets)
        T.flags.writeable = False
        self._checked = T
        return T

    def _proxy_targets(self, T: np.ndarray) -> np.ndarray:
        # a drag sends the same targets chunk after chunk: fit them once
        last = self._last_targets
        if last is not None and _same_targets(last[0], T):
            return last[1]
        out = self._moved(T, self.proxy_mesh.vertices[self._proxy_handles],
                          self._proxy_region)
        self._last_targets = (T if not T.flags.writeable else T.copy(), out)
        return out

    def _moved(self, T: np.ndarray, Q: np.ndarray, region: np.ndarray) -> np.ndarray:
        """Rest points ``Q`` moved by the rigid motion fitted to each one's handle region."""
        last = self._motions_for
        if last is not None and last[0] is T and not T.flags.writeable:
            R, t = last[1]
        else:
            fit = self._fit
            R, t = rigid_motions(self._rest_handles[fit], T[fit], self._region[fit],
                                 self._n_regions)
            self._motions_for = (T, (R, t))
        return np.einsum("vij,vj->vi", R[region], Q) + t[region]

    # -- configuration ------------------------------------------------------------------
    def set_handles(self, handles) -> None:
        """Use a new handle set: the proxy is refactorised now, the full mesh lazily."""
        self.handles = check_handles(self.mesh, handles)
        self._version += 1
        self._checked = None
        self._index_handles()
        self._bind_handles()
        self.proxy.set_handles(self._proxy_handles)
        self.proxy.prepare()
        self._pose_stiff()
        self._proxy_shape = None
        self._moves = self._stiff_done_for = None

    def set_rings(self, rings) -> None:
        """Use a new rigidity map: the proxy's is rebuilt now, the full mesh's lazily."""
        self._rings = ring_sizes(rings, self.mesh.n_vertices)
        self._version += 1
        self.proxy.set_rings(self._proxy_rings())
        self.proxy.prepare()
        self._pose_stiff()
        self._moves = self._stiff_done_for = None

    # -- the Deformer interface ---------------------------------------------------------
    @property
    def rings(self) -> np.ndarray:
        """r per vertex of the full mesh."""
        return self._rings

    @property
    def problem(self):
        """The full-resolution ARAP problem (built on first use)."""
        return self.full.problem

    @property
    def energy_is_sum_of_squares(self) -> bool:
        """Whether the full problem's weights are all >= 0 (so E >= 0)."""
        return self.full.energy_is_sum_of_squares

    @property
    def notes(self) -> list[str]:
        """What was done about the input: the proxy, then the full problem's notes."""
        pm, full = self.proxy_mesh, self.full
        via = "".join(f", then a {lv.mesh.n_vertices}-vertex level" for lv in self.levels)
        return [f"coarse to fine: a {pm.n_vertices}-vertex proxy (opened in "
                f"{self._open_s:.1f} s){via} starts the full solve"] + full.notes

    @property
    def timings(self) -> dict[str, float]:
        """The full problem's precomputation times, plus ``proxy_open_s``."""
        return {**self.full.timings, "proxy_open_s": self._open_s}

    def vertex_energy(self, P: np.ndarray, R: np.ndarray) -> np.ndarray:
        """See :meth:`arapkit.Deformer.vertex_energy` (the full problem's)."""
        return self.full.vertex_energy(P, R)

    def energy_of(self, P: np.ndarray, targets) -> float:
        """See :meth:`arapkit.Deformer.energy_of` (the full problem's)."""
        return self.full.energy_of(P, targets)

    # -- solving ------------------------------------------------------------------------
    def preview(self, targets, max_iter: int | None = None, tol: float = 1e-4,
                callback=None, restart: bool = False, full: bool = True) -> Preview:
        """Iterate the proxy from its last shape and map it to the full mesh.

        Parameters
        ----------
        targets : (h, 3)
            The full handles' targets.
        max_iter : int, optional
            Proxy iterations at most (a frame's budget); default: to ``tol``.
        tol : float
            The proxy's stopping test.
        callback : callable(iteration, energy, proxy_vertices) -> bool, optional
            As for :meth:`arapkit.Deformer.solve`, on the proxy.
        restart : bool
            Start the proxy from rest instead of its last shape.
        full : bool
            Map the proxy to the full mesh (else ``Preview.vertices`` is None: a display
            that draws the proxy saves 3–80 ms a frame; :meth:`to_full` maps it later).

        Notes
        -----
        A drag's few iterations per move leave the shape behind its targets, by about as
        many moves as the slowest mode needs iterations. With :attr:`lead` set, where the
        targets changed along the last move's direction the proxy starts as far ahead as
        its shape moved over the last move: a steady drag then leaves no lag, only what
        changes in its speed. Bending a bar at 2.5 degrees a move with 3 iterations a
        move, the shape stays within 0.36 % of the diagonal of its own targets' solution
        instead of 6.4 %. In the editor it is off: there it made each iteration dearer
        (the rotations move more per step) and cost a quarter of the shapes sent, for a
        mid-drag figure within the bench's noise (``docs/interactive.md``).
        """
        T = self.checked_targets(targets)
        cap = max_iter or PROXY_MAX_ITER
        if restart or self._proxy_shape is None:
            self._moves = None
            res = self._proxy_from_rest(T, callback, tol, cap)
        else:
            self._lead_start(self._proxy_targets(T))
            res = self._proxy_onwards(T, callback, tol, cap)
        self._proxy_shape = res.vertices
        if self._moves is None:
            self._moves = (None, self._proxy_targets(T), None)
        return Preview(self.to_full(res, T) if full else None, res)

    def _lead_start(self, PT: np.ndarray) -> None:
        """Where ``PT`` are new proxy targets, note the move and start the preview ahead.

        The start is ``Y + s (Y - Y_prev)``: ``Y`` the shape the last move ended at,
        ``Y_prev`` the one before, ``s`` the new move's length along the last one's (the
        projection of the targets' change on theirs, in ``[0, 2]``: up to 2 because a
        move the editor dropped makes the next one twice as long; a reversed or sideways
        move starts where the shape is). It runs ahead only where that lowers the
        energy for the new targets (:meth:`~arapkit.Deformer.energy_of` on the solver that
        takes the move: two local steps): a drag that bends the shape gains, while a
        shape that does not follow a move linearly (a small handle pulling a thin spike)
        would be thrown past where it goes.
        """
        moves = self._moves
        if moves is None:
            return
        older, last, shape = moves
        if _same_targets(last, PT):
            return
        Y = self._proxy_shape
        self._moves = (last, PT, Y)
        if not self.lead or older is None or shape is None:
            return
        step, prior = (PT - last).ravel(), (last - older).ravel()
        norm = float(prior @ prior)
        s = min(max(float(step @ prior) / norm, 0.0), LEAD_MAX) if norm > 0.0 else 0.0
        if s > 0.0:
            ahead = Y + s * (Y - shape)
            # a new move starts on the plain one-ring proxy where there is one
            solver = self._stiff if self._stiff is not None else self.proxy
            if solver.energy_of(ahead, PT) < solver.energy_of(Y, PT):
                self._proxy_shape = ahead

    def to_full(self, proxy: Result, targets) -> np.ndarray:
        """The full mesh's shape from a proxy result: skinned, handles at ``targets``, and
        the parts without a handle placed by the exact solve's own rule."""
        X = self._onto_full(self.binding, proxy, self.checked_targets(targets))
        self._place_free_parts(X)
        return X

    def _place_free_parts(self, X: np.ndarray) -> None:
        """Place the parts the proxy does not solve as the full solve does (in place).

        Skinned with its one nearest proxy vertex, a speck far off the surface (a scan's
        debris) turns with that vertex's rotation and lands, by the lever arm, up to 20 %
        of the diagonal from the exact solve's placement. Instead a part without a handle
        follows the rigid fit to its anchors (:class:`Followers`, the full problem's own
        rule) or stays at rest (``free_components="fix"``), and a speck with a handle
        moves rigidly with its handled vertices (exact for the editor's rigid moves). The
        full solve ignores the first two in its start, so :meth:`fine_start` skips this.
        """
        if self._parts is None:  # found once per handle set
            self._parts = self._free_parts(self.binding.covered)
        fixed, followers, riders = self._parts
        X[fixed] = self.mesh.vertices[fixed]  # where a part follows nothing: at rest
        for rule in (followers, riders):
            if rule is not None:
                rule.apply(X)

    def _free_parts(self, covered: np.ndarray | None
                    ) -> tuple[np.ndarray, Followers | None, Followers | None]:
        """The full mesh's parts without a handle, their rule, and the handled specks'
        (``covered``: :attr:`Binding.covered`, the vertices the proxy was made from)."""
        policy = self._options.get("free_components", "follow")
        fixed = anchor_components(self.mesh, self.handles, policy)[0]
        followers = Followers.of(self.mesh, fixed) if policy == "follow" else None
        riders = None
        if covered is not None and not covered[self.handles].all():
            # each handled speck's other vertices follow the fit to its own handled ones
            free = ~covered
            free[self.handles] = False
            riders = Followers.on_own_anchors(self.mesh, free,
                                              self.handles[~covered[self.handles]])
        return fixed, followers, riders

    def _onto_full(self, binding: Binding, coarse: Result, T: np.ndarray) -> np.ndarray:
        X = binding.skin(coarse.vertices, coarse.rotations)
        X[self.handles] = T
        return X

    def coarse_start(self, targets, callback=None) -> tuple[np.ndarray, Result]:
        """The exact solve's first stage: the proxy solved from rest to :data:`PROXY_TOL`.

        Returns the proxy's solution skinned onto the full mesh (the editor shows it as the
        settled preview) and the proxy's result, which :meth:`fine_start` takes on from:
        ``solve(targets)`` is ``full.solve(targets, init=fine_start(targets, proxy)[0])``
        with ``proxy = coarse_start(targets)[1]``. ``callback`` is the proxy solve's (as
        for :meth:`preview`); a start it stopped early is not the solve's.
        """
        res = self._proxy_from_rest(self.checked_targets(targets), callback)
        return self.to_full(res, targets), res

    def _proxy_onwards(self, T: np.ndarray, callback, tol: float, max_iter: int) -> Result:
        """The proxy from its last shape, for a preview. Where it is blended, new targets
        are first followed by the plain one-ring proxy, whose iterations cost half as much
        and spread a move faster (halfway through the bench's drag at 437K its shape was
        4.3 % (p95) of the diagonal from the exact solve for its targets, the blended
        proxy's 6.8 %); once that has converged, the blended proxy takes over from there."""
        PT = self._proxy_targets(T)
        start = self._proxy_shape
        # equal targets in a new array (a pose submitted again) go on with the blended proxy
        if self._stiff is not None and not _same_targets(self._stiff_done_for, T):
            stiff = self._stiff.solve(PT, init=start, tol=tol, max_iter=max_iter,
                                      callback=callback)
            if not stiff.converged:
                return stiff
            self._stiff_done_for, start = T, stiff.vertices
        return self.proxy.solve(PT, init=start, tol=tol, max_iter=max_iter, callback=callback)

    def _proxy_from_rest(self, T: np.ndarray, callback=None, tol: float = PROXY_TOL,
                         max_iter: int = PROXY_MAX_ITER) -> Result:
        """The proxy solved from rest: through the plain one-ring proxy where it is
        blended (:data:`STIFF_TOL`); ``iterations`` counts both. A first stage that ends
        unconverged (stopped by ``callback``, or at ``max_iter``) is returned as it is."""
        PT = self._proxy_targets(T)
        start, before = "identity", 0
        if self._stiff is not None:
            stiff = self._stiff.solve(PT, init="identity", tol=STIFF_TOL, max_iter=max_iter,
                                      callback=callback)
            if not stiff.converged:
                return stiff
            start, before = stiff.vertices, stiff.iterations
        res = self.proxy.solve(PT, init=start, tol=tol, max_iter=max_iter, callback=callback)
        res.iterations += before
        return res

    def fine_start(self, targets, proxy: Result,
                   stop=None) -> tuple[np.ndarray | None, int]:
        """The full solve's start from the proxy's: through :attr:`levels`, then skinned.

        Each level starts from the coarser solution skinned onto it (handles at their
        region's fitted motion) and is solved to :data:`LEVEL_TOL`. Waits for the full
        problem (the levels are built with it). Without levels this is
        ``to_full(proxy, targets)``, :meth:`coarse_start`'s first value.

        Parameters
        ----------
        targets : (h, 3)
            The full handles' targets.
        proxy : Result
            The proxy's solution, :meth:`coarse_start`'s second value.
        stop : callable() -> bool, optional
            Asked after every level iteration; when it says True the start is abandoned
            (the editor: a newer request came) and None returned.

        Returns
        -------
        start : (n, 3) or None
        iterations : int
            The levels' iterations.
        """
        T = self.checked_targets(targets)
        _ = self.full
        coarse, its = proxy, 0
        for level in self.levels:
            X = level.up.skin(coarse.vertices, coarse.rotations)
            LT = self._moved(T, level.mesh.vertices[level.handles], level.region)
            coarse = level.solver.solve(LT, init=X, tol=LEVEL_TOL, max_iter=PROXY_MAX_ITER,
                                        callback=None if stop is None else (lambda *_: stop()))
            its += coarse.iterations
            if stop is not None and not coarse.converged and stop():
                return None, its
        binding = self.levels[-1].full if self.levels else self.binding
        return self._onto_full(binding, coarse, T), its

    def solve(self, targets, init=None, tol: float | None = None,
              max_iter: int | None = None, callback=None,
              accelerate: bool | None = None, progress=None) -> Result:
        """Deform so that the handles reach ``targets``; see :meth:`arapkit.Deformer.solve`.

        With ``init=None`` the full solve starts from the skinned proxy solution (coarse to
        fine); an array or ``"identity"``/``"laplacian"`` starts it there instead, as for
        :class:`arapkit.Deformer`. ``timings`` gains ``proxy_s``, ``proxy_iterations``,
        ``level_s`` and ``level_iterations``. ``callback`` and ``progress`` see the full
        solve's iterations (the proxy's are :meth:`coarse_start`'s).
        """
        t0 = time.perf_counter()
        proxy_its = level_its = 0
        t_proxy = t_levels = 0.0
        pres = None
        if init is None:
            pres = self._proxy_from_rest(self.checked_targets(targets))
            proxy_its = pres.iterations
            t_proxy = time.perf_counter() - t0
        full = self.full  # built (or waited for) before the levels' clock starts
        if pres is not None:
            t1 = time.perf_counter()
            init, level_its = self.fine_start(targets, pres)
            t_levels = time.perf_counter() - t1
        res = full.solve(targets, init=init, tol=tol, max_iter=max_iter,
                         callback=callback, accelerate=accelerate, progress=progress)
        res.timings.update(proxy_s=t_proxy, proxy_iterations=proxy_its, level_s=t_levels,
                           level_iterations=level_its, total_s=time.perf_counter() - t0)
        return res


register_variant("multires", MultiresDeformer)
