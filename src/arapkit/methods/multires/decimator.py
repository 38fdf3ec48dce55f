"""The proxy of a large mesh: quadric decimation (``fast-simplification``, MIT) in a child
process, each full vertex's home on the proxy, and a cache by content.

The decimator holds the GIL for seconds, so :func:`start_decimation` runs it in a child
Python (:mod:`.decimation_child`, which imports NumPy and fast-simplification only) while
the caller does other work; :func:`decimation` collects it, or decimates here. A scan's
specks (parts smaller than one proxy vertex stands for) are left out of the decimator's
input (:func:`specks`).

Examples
--------
>>> from arapkit.mesh.shapes import bar
>>> m = bar(segments=(60, 8, 8))
>>> p, home = decimation(m, 300)
>>> 200 < p.n_vertices < 400 and home.shape == (m.n_vertices,)
True
"""

from __future__ import annotations

import io
import subprocess
import sys
import threading
from collections import OrderedDict
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from ...arap.childfactor import child_env
from ...mesh.model import Mesh
from ...validate import integer
from . import decimation_child
from .coarsening import Coarsening, register_coarsening
from .decimation_child import simplify as simplify_with_homes

__all__ = ["DEFAULT_PROXY_VERTICES", "decimate", "decimation", "specks", "start_decimation"]

#: proxy size: its iteration (5–8 ms on two cores) leaves room for a 30 Hz frame
DEFAULT_PROXY_VERTICES = 20_000
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
                          input=buf.getvalue(), capture_output=True, check=True, timeout=600,
                          env=child_env())
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


register_coarsening("mesh", Coarsening("decimate", decimation, start_decimation, specks))
