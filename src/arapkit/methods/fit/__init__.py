"""Fitting a template mesh to a scan: non-rigid ICP regularised by the r-ring ARAP energy.

Modules
-------
solver   :class:`Fitter` (keeps the template's precomputation) and the one-shot :func:`fit`
stages   the non-rigid stages: the energy, each step's derivation, the decrease check
target   :class:`FitTarget`: a mesh or a point cloud prepared for closest-point queries
closest  the compiled closest-point kernels (triangles, oriented disks) and border points
system   :class:`StageSystems`: the global step's matrix per stage, factorised once
align    :func:`similarity`: the initial placement (Umeyama)
report   :class:`FitReport`: residuals, matches, iterations, time

Examples
--------
>>> from arapkit.methods.fit import Fitter, fit
>>> fit.__module__
'arapkit.methods.fit.solver'
"""

from .align import similarity
from .report import FitReport, StageReport, residual_stats
from .solver import DEFAULT_SCHEDULE, FitResult, Fitter, fit
from .target import FitTarget, Matches

__all__ = ["DEFAULT_SCHEDULE", "FitReport", "FitResult", "FitTarget", "Fitter", "Matches",
           "StageReport", "fit", "residual_stats", "similarity"]
