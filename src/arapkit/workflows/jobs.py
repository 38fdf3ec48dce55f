"""One deformation job from files: what ``arapkit deform`` runs, as a library function.

``arapkit deform`` and ``arapkit batch`` both go through :func:`prepare_job`,
:func:`save_result` and :func:`job_report`, so a batch job gives the same output file and
report as the single command with the same parameters (and the same numba thread count:
the solver's parallel sums are taken per chunk, and the chunking follows the thread count).

Examples
--------
>>> import tempfile, pathlib, json
>>> from arapkit.io import save_mesh
>>> from arapkit.mesh.shapes import bar
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> m = bar()
>>> _ = save_mesh(d / "bar.off", m.vertices, m.faces)
>>> _ = (d / "h.json").write_text(json.dumps([
...     {"box": {"min": [-1, -1, -1], "max": [0.01, 1, 1]}},
...     {"box": {"min": [6.99, -1, -1], "max": [8, 1, 1]}, "translate": [0, 1, 0]}]))
>>> job = DeformJob(mesh=str(d / "bar.off"), handles=str(d / "h.json"), rings=2)
>>> prepared = prepare_job(job)
>>> res = prepared.solve()
>>> save_result(d / "out.ply", prepared, res)   # warnings: none for PLY
[]
>>> bool(res.converged), job_report(job, prepared, res, 0.0)["result"]["iterations"] > 0
(True, True)
"""

from __future__ import annotations

import inspect
import os
from collections.abc import Callable
from dataclasses import MISSING, dataclass, field, fields
from typing import Any

import numpy as np

from .. import __version__
from ..arap.domains import domain_of
from ..errors import Advice, InputError, worded_for
from ..mesh.cloud import counted
from ..methods.deformer import Deformer
from ..methods.registry import method_names

__all__ = ["DEFAULT_ENERGY", "ENERGIES", "JOB_DEFAULTS", "DeformJob", "JobInputs", "PreparedJob",
           "describe_groups", "describe_rings", "error_message", "job_report", "load_job_inputs",
           "method_description", "prepare_job", "save_result", "weights_used"]


def _solver_defaults() -> dict[str, Any]:
    """The :class:`arapkit.Deformer`'s own defaults: a job that leaves a parameter out
    solves as the library does, with no second copy of the values to drift."""
    params = inspect.signature(Deformer.__init__).parameters
    names = ("rings", "weights", "energy", "sr_alpha", "nodes", "smooth_lambda", "tol",
             "max_iter", "init", "accelerate")
    return {name: params[name].default for name in names}


_SOLVER = _solver_defaults()

#: the methods of ``arapkit deform`` and its jobs (those the registry offers to the command line)
ENERGIES = method_names("cli")
#: r-ring ARAP, the default method (one of :data:`ENERGIES`, the methods this build can run)
DEFAULT_ENERGY: str = _SOLVER["energy"]


@dataclass
class DeformJob:
    """Parameters of one deformation, as ``arapkit deform`` takes them.

    Attributes
    ----------
    mesh : str
        Input mesh file, or a point cloud file (:func:`arapkit.io.clouds.load_shape`).
    handles : str, list or dict
        Handle file (``.json`` groups or ``.sel``), or the handle groups themselves (the
        JSON schema of ``docs/handles.md``, already parsed).
    transform : str or None
        ``.def`` matrix for a ``.sel`` file.
    rings : int
        Ring size for every vertex (ignored when ``rings_file`` is given).
    rings_file : str or None
        Per-vertex ring sizes (see :func:`arapkit.io.rigidity.load_rings`).
    weights, tol, max_iter, init, accelerate
        As for :class:`arapkit.Deformer` (``weights`` None: the shape's default,
        ``cotan-clamped`` on a mesh and ``gaussian`` on a point cloud).
    energy : str
        One of :data:`ENERGIES`.
    sr_alpha, nodes, smooth_lambda : optional
        Options of ``energy="sr-arap"``, ``energy="embedded"`` and ``energy="smooth-arap"``.
    weld : float or None
        Merge vertices closer than this fraction of the bounding-box diagonal for the solve
        (:func:`arapkit.mesh.welding.weld`); handles, rings and the output refer to the input's
        own vertices.
    volumetric, interior_density
        Volumetric ARAP (:class:`arapkit.methods.volumetric.VolumetricDeformer`) and its interior
        density.
    neighbours, radius : optional
        A point cloud's graph (:class:`arapkit.PointCloud`): k nearest neighbours (default
        10) or every pair closer than ``radius``; refused for a mesh file.
    groups : str, list, dict or None
        A groups file (rigid parts and shared-rotation groups, :func:`arapkit.io.load_groups`)
        or its JSON entries already parsed; None for none.
    """

    mesh: str
    handles: str | list | dict
    transform: str | None = None
    rings: int = _SOLVER["rings"]
    rings_file: str | None = None
    weights: str | None = _SOLVER["weights"]
    tol: float = _SOLVER["tol"]
    max_iter: int = _SOLVER["max_iter"]
    init: str = _SOLVER["init"]
    accelerate: bool | None = _SOLVER["accelerate"]
    energy: str = DEFAULT_ENERGY
    sr_alpha: float | None = _SOLVER["sr_alpha"]
    nodes: int | None = _SOLVER["nodes"]
    smooth_lambda: float | None = _SOLVER["smooth_lambda"]
    weld: float | None = None
    volumetric: bool = False
    interior_density: float | None = None
    neighbours: int | None = None
    radius: float | None = None
    groups: str | list | dict | None = None

    def input_files(self) -> list[str]:
        """The files this job reads."""
        files = [self.mesh, self.transform, self.rings_file]
        if isinstance(self.groups, (str, os.PathLike)):
            files.append(self.groups)
        if isinstance(self.handles, (str, os.PathLike)):
            files.append(self.handles)
            if self.transform is None and os.fspath(self.handles).lower().endswith(".sel"):
                # the .def beside the .sel is read when no transform is named
                files.append(os.path.splitext(os.fspath(self.handles))[0] + ".def")
        return [os.fspath(f) for f in files if f is not None]


#: every optional parameter of :class:`DeformJob` and its default (the library's own)
JOB_DEFAULTS: dict[str, Any] = {f.name: f.default for f in fields(DeformJob)
                                if f.default is not MISSING}


@dataclass
class PreparedJob:
    """A job's inputs loaded and its :class:`arapkit.Deformer` built, ready to solve."""

    job: DeformJob
    mesh: Any
    handles: Any
    deformer: Any
    notes: list[str] = field(default_factory=list)
    #: the vertex groups solved with (None for none)
    groups: Any = None

    @property
    def rings(self) -> np.ndarray:
        """r per vertex, (n,) int."""
        return np.broadcast_to(np.asarray(self.deformer.rings), (self.mesh.n_vertices,))

    def solve(self, callback: Callable | None = None):
        """Run the deformer on the handle targets; returns :class:`arapkit.Result`."""
        return self.deformer.solve(self.handles.targets, callback=callback)


def _load_handles(job: DeformJob, source: Any, mesh: Any):
    """The job's handles on ``mesh`` (``source`` welded, or ``source`` itself)."""
    from ..io import load_handles, parse_handles

    welded = None if mesh is source else mesh
    if isinstance(job.handles, (str, os.PathLike)):
        return load_handles(job.handles, source.vertices, job.transform, welded=welded)
    if job.transform is not None:
        raise InputError(f"{job.transform}: a .def transform only applies to .sel handle files")
    return parse_handles(job.handles, source.vertices, source="<handles>", welded=welded)


@dataclass
class JobInputs:
    """A job's files read: the mesh solved (welded when asked), handles and rings on it."""

    source: Any
    mesh: Any
    handles: Any
    rings: np.ndarray | int
    notes: list[str] = field(default_factory=list)
    #: records a further note (e.g. the deformer's) like the loader's
    tell: Callable[[str], None] | None = field(default=None, repr=False)
    #: the job's vertex groups on ``mesh`` (None for none)
    groups: Any = None


def load_job_inputs(job: DeformJob, note: Callable[[str], None] | None = None) -> JobInputs:
    """Read the mesh, handles and rings of ``job`` (what a dry run shows; no solver built).

    Parameters
    ----------
    job : DeformJob
    note : callable, optional
        Called with each note about the input (loader repairs, welding ...), prefixed with
        the mesh file name.

    Raises
    ------
    InputError
        Any bad input, with a one-line message naming the file.
    """
    from ..io import load_shape

    if job.energy not in ENERGIES:
        raise InputError(f"energy {job.energy} is not available in this build "
                         f"(available: {', '.join(ENERGIES)})")
    notes: list[str] = []

    def tell(msg: str) -> None:
        notes.append(msg)
        if note is not None:
            # Advice keeps its interface wording through the prefix
            note(msg.after(f"{job.mesh}: ") if isinstance(msg, Advice) else f"{job.mesh}: {msg}")

    source = load_shape(job.mesh, neighbours=job.neighbours, radius=job.radius)
    if job.weld is None:
        mesh = source
    elif source.faces is None:
        raise InputError(f"{job.mesh}: weld merges a mesh's split vertices; a point cloud has "
                         "none (coincident points stay two points of the graph)")
    else:
        from ..mesh.welding import weld

        mesh = weld(source, job.weld)
    for msg in mesh.notes if mesh is source else source.notes + mesh.notes:
        tell(msg)
    # vertex numbers in handles and a rings map are the input's: mapped onto a welded mesh
    hs = _load_handles(job, source, mesh)
    if job.rings_file:
        from ..io import load_rings

        rings: np.ndarray | int = load_rings(job.rings_file, source.n_vertices)
        if mesh is not source:
            from ..mesh.welding import weld_values

            rings = weld_values(mesh, np.asarray(rings))
    else:
        rings = int(job.rings)
    return JobInputs(source, mesh, hs, rings, notes, tell, _load_groups(job, source, mesh))


def _load_groups(job: DeformJob, source: Any, mesh: Any):
    """The job's vertex groups on ``mesh`` (None without), read like its handles."""
    if job.groups is None:
        return None
    from ..io import load_groups, parse_groups

    welded = None if mesh is source else mesh
    if isinstance(job.groups, (str, os.PathLike)):
        return load_groups(job.groups, source.vertices, welded=welded)
    return parse_groups(job.groups, source.vertices, source="<groups>", welded=welded)


def prepare_job(job: DeformJob, note: Callable[[str], None] | None = None) -> PreparedJob:
    """Load the mesh, handles and rings of ``job`` and build its deformer.

    Parameters
    ----------
    job : DeformJob
    note : callable, optional
        Called with each note about the input (loader repairs, fixed components ...),
        prefixed with the mesh file name.

    Raises
    ------
    InputError
        Any bad input, with a one-line message naming the file.
    """
    inputs = load_job_inputs(job, note)
    deformer = Deformer(
        inputs.mesh,
        inputs.handles.indices,
        rings=inputs.rings,
        weights=job.weights,
        tol=job.tol,
        max_iter=job.max_iter,
        init=job.init,
        accelerate=job.accelerate,
        energy=job.energy,
        sr_alpha=job.sr_alpha,
        nodes=job.nodes,
        smooth_lambda=job.smooth_lambda,
        **({"volumetric": True, "density": job.interior_density} if job.volumetric else {}),
        **({} if inputs.groups is None else {"groups": inputs.groups}),
    )
    for msg in deformer.notes:
        inputs.tell(msg)
    return PreparedJob(job, inputs.mesh, inputs.handles, deformer, inputs.notes,
                       inputs.groups)


def save_result(output: str | os.PathLike, prepared: PreparedJob, res) -> list[str]:
    """Write the deformed mesh or point cloud (atomically), with per-vertex energy and
    rings for PLY.

    Everything the input file carried (polygons, UVs, normals, materials, colours, PLY
    properties; a cloud's normals turned by the solve's rotations) comes out again, and a
    welded solve is written to the input's own vertices. Returns warning lines for what
    the output format cannot carry.
    """
    from ..io import save_mesh

    # the result itself: a point cloud's normals turn by its rotations. Energy and rings
    # go to PLY only, which has room for them: a mesh's other formats drop them silently,
    # and a cloud's writer would warn about values the caller never asked for
    name = os.fspath(output).lower()
    ply = name.removesuffix(".gz").endswith(".ply")
    return save_mesh(
        output,
        res,
        vertex_properties={"energy": res.vertex_energy,
                           "rings": prepared.rings.astype(np.int32)} if ply else None,
        like=prepared.mesh,
    )


def weights_used(job: DeformJob, prepared: PreparedJob) -> str | None:
    """The edge weighting the job's solve used: as given, else the shape's default
    (``cotan-clamped`` on a mesh, ``gaussian`` on a point cloud)."""
    kind = getattr(prepared.deformer, "weights_kind", None)
    if kind is None:
        kind = job.weights if job.weights is not None else domain_of(prepared.mesh).default_weights
    return kind if isinstance(kind, str) else None


def _volume_parameters(job: DeformJob) -> dict[str, Any]:
    """Report parameters of a volumetric job (none for surface ARAP)."""
    if not job.volumetric:
        return {}
    from ..methods.volumetric import DEFAULT_DENSITY, DEFAULT_VOLUME_WEIGHTS

    density = DEFAULT_DENSITY if job.interior_density is None else job.interior_density
    return {"volumetric": True, "interior_density": density,
            "volume_weights": DEFAULT_VOLUME_WEIGHTS}


def method_description(job: DeformJob) -> dict[str, Any]:
    """The job's method and its resolved options, as the report records them.

    Examples
    --------
    >>> method_description(DeformJob(mesh="m.off", handles=[], energy="sr-arap"))
    {'energy': 'sr-arap', 'sr_alpha': 0.02}
    """
    from ..methods.deformer import check_method

    options = check_method(job.energy, job.sr_alpha, job.nodes,
                           smooth_lambda=job.smooth_lambda)
    return {"energy": job.energy,
            **{("sr_alpha" if k == "alpha" else k): v for k, v in options.items()}}


def job_report(
    job: DeformJob,
    prepared: PreparedJob,
    res,
    wall_s: float,
    command: list[str] | None = None,
    outputs: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The JSON report of a solved job: inputs, parameters, handles, result, timings."""
    from ..arap.rings import rings_summary

    mesh, hs = prepared.mesh, prepared.handles
    r = prepared.rings
    return {
        "arapkit_version": __version__,
        "command": command,
        "input": {
            "mesh": job.mesh,
            "n_vertices": mesh.n_vertices,
            "n_faces": mesh.n_faces,
            **({} if mesh.faces is not None else {"graph": mesh.graph_description,
                                                  "n_edges": len(mesh.edges)}),
            "n_components": mesh.n_components,
            "n_boundary_loops": len(mesh.boundary_loops),
            "notes": list(mesh.notes),
            "handles": job.handles,
            "transform": job.transform,
            "rings_file": job.rings_file,
            "weld": None if mesh.welded_from is None else {
                "tol": mesh.welded_from.tol,
                "input_vertices": mesh.welded_from.source.n_vertices,
                "welded_vertices": mesh.n_vertices,
            },
        },
        "method": method_description(job),
        "parameters": {
            "rings": int(job.rings) if not job.rings_file else rings_summary(r),
            "weights": weights_used(job, prepared),
            "tol": job.tol,
            "max_iter": job.max_iter,
            "init": job.init,
            # as used: None leaves it to the method (coarse to fine and volumetric: on)
            "accelerate": bool(prepared.deformer.accelerate),
            **_volume_parameters(job),
        },
        "handles": {
            "count": len(hs.indices),
            "groups": [
                {"name": g.name, "count": len(g.indices), "kind": g.kind} for g in hs.groups
            ],
        },
        **_groups_report(job, prepared),
        "result": {
            "iterations": res.iterations,
            "converged": res.converged,
            "energy": res.energy,
            # False only for raw cotangent weights with negative values (obtuse triangles)
            "energy_is_sum_of_squares": prepared.deformer.energy_is_sum_of_squares,
            **({} if prepared.deformer.energy_is_sum_of_squares else {"energy_note": (
                "raw cotangent weights have negative values on this mesh: the energy is not "
                "a sum of squares and can be negative")}),
            "energy_history": list(res.history),
            "max_handle_error": float(
                np.max(np.linalg.norm(res.vertices[hs.indices] - hs.targets, axis=1))
            ),
        },
        "timings": {**res.timings, "wall_s": wall_s},
        "outputs": dict(outputs or {}),
    }


def _groups_report(job: DeformJob, prepared: PreparedJob) -> dict[str, Any]:
    """The report's ``vertex_groups`` section (none without groups): each part or group,
    its size and kind, and for rigid parts how far their edges moved from their rest length
    (0 to round-off: the parts are solved exactly)."""
    g = prepared.groups
    if g is None:
        return {}
    sizes = g.sizes
    return {"vertex_groups": {
        "file": job.groups if isinstance(job.groups, str) else "<groups>",
        "summary": g.summary(),
        "groups": [{"name": name, "count": int(sizes[i]), "rigid": bool(g.rigid[i])}
                   for i, name in enumerate(g.names)],
    }}


def describe_groups(vertices: np.ndarray, hs, points: bool = False) -> list[str]:
    """One line per handle group: name, vertex count (``points``: of a point cloud, point
    count), motion (what a dry run prints).

    Examples
    --------
    >>> from arapkit.io import parse_handles
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    >>> hs = parse_handles([{"name": "a", "indices": [0]},
    ...                     {"name": "b", "indices": [2], "translate": [0, 1, 0]}], V)
    >>> print(chr(10).join(describe_groups(V, hs)))
    a: 1 vertex, fixed
    b: 1 vertex, moved: mean displacement [0, 1, 0], largest 1
    """
    lines = []
    for g in hs.groups:
        n = len(g.indices)
        head = f"{g.name}: {counted(n, points=points)}"
        d = np.asarray(g.targets) - vertices[g.indices]
        if g.kind == "fixed" or not np.any(d):
            lines.append(f"{head}, fixed")
            continue
        mean = ", ".join(f"{x:.4g}" for x in d.mean(axis=0) + 0.0)
        big = float(np.linalg.norm(d, axis=1).max())
        lines.append(f"{head}, moved: mean displacement [{mean}], largest {big:.4g}")
    return lines


def describe_rings(rings: np.ndarray) -> str:
    """A rigidity map in a few characters: ``3`` when uniform, ``1..6`` otherwise.

    Examples
    --------
    >>> describe_rings(np.array([2, 2])), describe_rings(np.array([1, 4, 2]))
    ('2', '1..4')
    """
    lo, hi = int(np.min(rings)), int(np.max(rings))
    return str(lo) if lo == hi else f"{lo}..{hi}"


def error_message(exc: BaseException) -> str:
    """The one line ``arapkit`` prints for ``exc``: bad input, a missing or unreadable
    file, or (for anything else) an internal error to report.

    Examples
    --------
    >>> error_message(InputError("m.off: not a mesh"))
    'm.off: not a mesh'
    >>> error_message(FileNotFoundError(2, "No such file", "h.json"))
    'h.json: file not found'
    """
    if isinstance(exc, InputError):
        msg = worded_for(exc.args[0] if exc.args else exc, "cli")
    elif isinstance(exc, FileNotFoundError):
        msg = f"{exc.filename}: file not found"
    elif isinstance(exc, IsADirectoryError):
        msg = f"{exc.filename}: is a folder, expected a file"
    elif isinstance(exc, PermissionError):
        msg = f"{exc.filename}: permission denied"
    else:
        msg = f"internal error ({type(exc).__name__}: {exc}); please report this"
    # a message may carry file content with newlines, which would break the one line
    return " ".join(str(msg).split())
