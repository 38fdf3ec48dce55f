"""Learning a rigidity map from files of frames: what ``arapkit learn`` runs.

The frames share one connectivity: mesh files (listed, as a glob, or a folder) or ``.npz``
files holding ``V`` (frames x vertices x 3) and ``F``. Each ``.npz``, folder or glob is a
sequence (:class:`Frames`); :func:`learn_from_frames` learns one map for the reference,
per sequence through any ``map`` (a Dask cluster's: :func:`arapkit.workflows.batch.dask_map`)
when there are several.

Examples
--------
>>> import numpy as np
>>> from arapkit.mesh.shapes import bar
>>> m = bar()
>>> frames = Frames([m.vertices, m.vertices * [1.0, 1.0, 1.3]], m.faces, ["rest", "tall"])
>>> learned = learn_from_frames(frames, 0, r_max=3)
>>> learned.result.rings.shape == (m.n_vertices,), learned.identical
(True, [])
"""

from __future__ import annotations

import glob
import os
import re
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..io import atomic_open, is_readable_mesh, load_mesh, load_numpy, readable_formats
from ..learn import LearnedRings, learn_rings, learn_rings_sequences
from ..mesh.model import Mesh
from ..mesh.weights import DEFAULT_WEIGHTS
from ..validate import real_array

__all__ = ["MESH_SUFFIXES", "Frames", "FramesLearned", "check_connectivity", "expand_frames",
           "learn_from_frames", "load_frames", "save_energies"]

#: mesh files a folder of frames is searched for (each may also be gzipped)
MESH_SUFFIXES = (".off", ".obj", ".ply", ".stl")
_GLOB_CHARS = re.compile(r"[*?\[]")


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
            found = sorted((os.path.join(item, f) for f in os.listdir(item) if is_readable_mesh(f)),
                           key=_natural_key)
            if not found:
                raise InputError(f"{item}: folder holds no mesh files ({readable_formats()})")
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
    meshes = [load_mesh(p) for p in paths]
    seqs, start = [], 0
    for g in groups:
        seqs.append(list(range(start, start + len(g))))
        start += len(g)
    return Frames([m.vertices for m in meshes], None, list(paths), meshes, seqs)


def check_connectivity(frames: Frames, ref: int) -> None:
    """Refuse frames without the reference's vertex count or (for mesh files) its faces.

    Examples
    --------
    >>> import numpy as np
    >>> check_connectivity(Frames([np.zeros((3, 3)), np.zeros((4, 3))], None, ["a", "b"]), 0)
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: b: has 4 vertices but the reference a has 3: all frames must \
share one mesh
    """
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


@dataclass
class FramesLearned:
    """A map learned from frames: the reference it is for, the result, and the frames that
    told nothing.

    Attributes
    ----------
    reference : Mesh
        The reference frame as solved (welded when asked; see
        :func:`arapkit.mesh.welding.to_source` for the input's own vertices).
    result : LearnedRings
    identical : list of str
        Names of the frames equal to the reference (they carry no information).
    all_identical : bool
        Every example equals the reference, so the map is ``r_max`` everywhere.
    """

    reference: Mesh
    result: LearnedRings
    identical: list[str] = field(default_factory=list)
    all_identical: bool = False


def _reference(frames: Frames, ref: int) -> Mesh:
    if frames.meshes is not None:
        return frames.meshes[ref]
    return Mesh(frames.vertices[ref], frames.faces, name=frames.names[ref])


def learn_from_frames(
    frames: Frames,
    ref: int = 0,
    r_min: int = 1,
    r_max: int = 6,
    omega: float | str = "auto",
    weights: str = DEFAULT_WEIGHTS,
    *,
    weld: float | None = None,
    map: Callable | None = None,  # noqa: A002 - the builtin's protocol, on purpose
) -> FramesLearned:
    """Learn r per vertex of frame ``ref`` from the other frames.

    With several sequences, or a ``map``, each sequence's energy table is computed on its
    own (:func:`arapkit.learn.learn_rings_sequences`); otherwise all frames at once
    (:func:`arapkit.learn.learn_rings`).

    Parameters
    ----------
    frames : Frames
        Checked with :func:`check_connectivity`.
    ref : int
        Index of the reference frame.
    r_min, r_max, omega, weights
        As for :func:`arapkit.learn_rings`.
    weld : float, optional
        Merge the reference's vertices closer than this fraction of its bounding-box
        diagonal (:func:`arapkit.mesh.welding.weld`); every frame follows the same map.
    map : callable, optional
        ``map(func, items)`` for the per-sequence tables.

    Raises
    ------
    InputError
        Bad parameters, or energies beyond double precision.
    """
    reference = _reference(frames, ref)
    if weld is not None:
        from ..mesh.welding import weld as weld_mesh
        from ..mesh.welding import weld_frame

        # every frame shares the reference's vertices, so one weld map serves them all
        reference = weld_mesh(reference, weld)

        def pose(i: int) -> np.ndarray:
            return weld_frame(reference, frames.vertices[i])
    else:
        def pose(i: int) -> np.ndarray:
            return frames.vertices[i]
    others = [i for i in range(len(frames)) if i != ref]
    with warnings.catch_warnings():
        # identical frames are reported by name instead (FramesLearned.identical)
        warnings.simplefilter("ignore", UserWarning)
        if len(frames.sequences) > 1 or map is not None:
            seqs = [[pose(i) for i in seq if i != ref] for seq in frames.sequences]
            res = learn_rings_sequences(reference, seqs, r_min, r_max, omega, weights,
                                        **({} if map is None else {"map": map}))
        else:
            res = learn_rings(reference, [pose(i) for i in others], r_min, r_max, omega,
                              weights)
    if not (np.isfinite(res.energies).all() and np.isfinite(res.omega)):
        # nothing non-finite is written (the energies file, the choice of r behind the map)
        raise InputError(f"{frames.names[ref]}: the ARAP energies overflow double precision "
                         "(coordinates too large); rescale the frames")
    return FramesLearned(reference, res, [frames.names[others[j]] for j in res.identical],
                         len(res.identical) == len(others))


def save_energies(path: str, reference: Mesh, res: LearnedRings) -> None:
    """Write the table ``E_ARAP(k, r)``, one row per input vertex: ``.npy``, else text.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar()
    >>> res = learn_from_frames(Frames([m.vertices, m.vertices * 1.1], m.faces, "ab"), 0,
    ...                         r_max=2).result
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "E.txt"
    >>> save_energies(str(p), m, res)
    >>> p.read_text().splitlines()[0]
    '# E_ARAP(k, r): r1 r2'
    """
    from ..mesh.welding import to_source

    energies = to_source(reference, res.energies)
    with atomic_open(path, "wb") as f:
        if path.lower().endswith(".npy"):
            np.save(f, energies)
        else:
            cols = " ".join(f"r{r}" for r in range(res.r_min, res.r_max + 1))
            np.savetxt(f, energies, fmt="%.9g", header=f"E_ARAP(k, r): {cols}")
