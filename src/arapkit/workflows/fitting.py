"""One template fit from files: what ``arapkit fit`` runs, as a library function.

:class:`FitJob` names the files and options; :func:`load_fit_inputs` reads them (every bad
input is one :class:`~arapkit.errors.InputError` line naming its file, before any work),
:func:`run_fit` fits, and :func:`save_fit` / :func:`fit_report` write the fitted template
(with the template file's own vertex order, faces and attributes) and the JSON report.

The target is a mesh file (any format :func:`arapkit.load_mesh` reads), or a point cloud
(any file :func:`arapkit.load_points` reads: ``.npy``, ``.xyz`` / ``.txt`` / ``.pts``,
``.xyzn``, ``.xyzrgb``, a PLY, OBJ or OFF without faces), read by
:func:`arapkit.io.load_shape` as every door reads a shape.

Examples
--------
>>> import tempfile, pathlib
>>> import numpy as np
>>> from arapkit.io import save_mesh
>>> from arapkit.mesh.shapes import bar
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> m = bar()
>>> _ = save_mesh(d / "bar.off", m.vertices, m.faces)
>>> np.save(d / "scan.npy", m.vertices + [0.0, 0.0, 0.1])
>>> inputs = load_fit_inputs(FitJob(str(d / "bar.off"), str(d / "scan.npy")))
>>> res = run_fit(inputs)
>>> save_fit(d / "fitted.ply", inputs, res)
[]
>>> round(fit_report(inputs, res)["report"]["residual"]["p95"], 4)
0.0
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from .. import __version__
from ..errors import InputError
from ..io import load_mesh, load_rings, load_shape, save_mesh
from ..io.landmarks import load_landmarks
from ..mesh.model import Mesh
from ..mesh.weights import DEFAULT_WEIGHTS
from ..methods.fit import DEFAULT_SCHEDULE, FitResult, FitTarget, Fitter

__all__ = ["FitInputs", "FitJob", "fit_report", "load_fit_inputs", "load_target", "run_fit",
           "save_fit"]


@dataclass
class FitJob:
    """The files and options of one fit, as ``arapkit fit`` takes them.

    Attributes
    ----------
    template, target : str
        The template mesh file; the target mesh or point-cloud file.
    landmarks : str or None
        A landmarks JSON file (``[{"vertex": i, "target": [x, y, z]}, ...]``).
    rings : int
        r for every vertex (ignored when ``rings_file`` is given).
    rings_file : str or None
        A rigidity map, one r per template vertex (:func:`arapkit.load_rings`).
    scale, schedule, weights :
        As for :class:`arapkit.methods.fit.Fitter`.
    """

    template: str
    target: str
    landmarks: str | None = None
    rings: int = 1
    rings_file: str | None = None
    scale: bool | None = None
    schedule: tuple[float, ...] = DEFAULT_SCHEDULE
    weights: str = DEFAULT_WEIGHTS

    def input_files(self) -> list[str]:
        """The files this job reads."""
        return [os.fspath(f) for f in (self.template, self.target, self.landmarks,
                                       self.rings_file) if f is not None]


@dataclass
class FitInputs:
    """A fit's files read and checked."""

    job: FitJob
    template: Mesh
    target: FitTarget
    landmarks: tuple[np.ndarray, np.ndarray] | None
    rings: np.ndarray | int
    notes: list[str] = field(default_factory=list)


def load_target(path: str | os.PathLike) -> FitTarget:
    """A target file as a :class:`~arapkit.methods.fit.FitTarget`: a mesh where the file
    has faces, else a point cloud with its normals where it has them
    (:func:`arapkit.io.load_shape`)."""
    shape = load_shape(path)
    if isinstance(shape, Mesh):
        return FitTarget.from_mesh(shape)
    return FitTarget.from_points(shape.points, shape.normals, shape.name)


def load_fit_inputs(job: FitJob) -> FitInputs:
    """Read and check the template, target, landmarks and rigidity map of ``job``."""
    template = load_mesh(job.template)
    notes = list(template.notes)
    target = load_target(job.target)
    landmarks = (load_landmarks(job.landmarks, template.n_vertices)
                 if job.landmarks is not None else None)
    if landmarks is not None and not len(landmarks[0]):
        raise InputError(f"{job.landmarks}: no landmarks in the file")
    rings: np.ndarray | int = job.rings
    if job.rings_file is not None:
        rings = load_rings(job.rings_file, template.n_vertices)
    return FitInputs(job, template, target, landmarks, rings, notes)


def run_fit(inputs: FitInputs) -> FitResult:
    """Fit the template of ``inputs`` to its target."""
    job = inputs.job
    fitter = Fitter(inputs.template, inputs.rings, weights=job.weights, schedule=job.schedule,
                    scale=job.scale)
    return fitter.fit(inputs.target, inputs.landmarks)


def save_fit(output: str | os.PathLike, inputs: FitInputs, result: FitResult) -> list[str]:
    """Write the fitted template with the template file's attributes; returns warnings
    (what the output format cannot keep)."""
    return save_mesh(output, result.vertices, like=inputs.template)


def fit_report(inputs: FitInputs, result: FitResult,
               outputs: dict[str, Any] | None = None) -> dict[str, Any]:
    """The JSON report of a fit: inputs, parameters and :class:`FitReport`'s fields."""
    job = inputs.job
    r = np.asarray(inputs.rings)
    rings = int(r) if r.ndim == 0 else {"file": job.rings_file, "min": int(r.min()),
                                        "max": int(r.max())}
    return {
        "arapkit": __version__,
        "inputs": {"template": job.template, "target": job.target,
                   "landmarks": job.landmarks},
        "parameters": {"rings": rings, "scale": job.scale, "schedule": list(job.schedule),
                       "weights": job.weights},
        "outputs": outputs or {},
        "report": asdict(result.report),
        "notes": inputs.notes,
    }
