"""arapkit: as-rigid-as-possible surface deformation with controllable rigidity.

Implements r-ring ARAP (Chen, Gao, Lai, Xia 2017), standard ARAP (Sorkine & Alexa 2007)
as its r = 1 case, and Laplacian surface editing.

Examples
--------
>>> import arapkit
>>> from arapkit.mesh.shapes import bar, bar_bend
>>> mesh = bar()
>>> handles, targets = bar_bend(mesh, 180)
>>> res = arapkit.Deformer(mesh, handles, rings=3).solve(targets)
>>> res.converged
True
"""

import os as _os

# Parallel regions in the kernels are short and frequent. GNU OpenMP's default busy-wait
# makes idle workers spin; on a machine shared with other processes that steals the cores
# the working threads need (measured: 2-3x slower iterations). It must be set before numba
# starts its OpenMP pool (at the first parallel call); an explicit user setting wins.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from . import _compat  # noqa: E402
from .errors import InputError  # noqa: E402
from .io import (
    HandleGroup,
    HandleSet,
    load_groups,
    load_handles,
    load_mesh,
    load_points,
    load_rings,
    parse_handles,
    save_def,
    save_handles,
    save_mesh,
    save_points,
    save_rings,
    save_sel,
    select_box,
    select_nearest,
    select_sphere,
)
from .learn.fit import LearnedRings, learn_rings
from .mesh.cloud import Graph, PointCloud
from .mesh.groups import VertexGroups
from .mesh.model import Mesh
from .mesh.orientation import BoundingBox, UpGuess, bounding_box, guess_up
from .methods.deformer import Deformer, Result
from .methods.dynamics import Simulator, simulate
from .methods.fit import FitResult, Fitter, fit
from .methods.laplacian import LaplacianEditor, laplacian_edit


def _installed_version() -> str:
    # the one source is pyproject.toml, read back from the installed package's metadata
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("arapkit")
    except PackageNotFoundError:  # a source tree that was never installed
        return "0+unknown"


__version__ = _installed_version()
del _installed_version

# the public names: classes, then functions (submodules such as arapkit.plots.figures are public
# too)
__all__ = [
    "BoundingBox",
    "Deformer",
    "FitResult",
    "Fitter",
    "HandleGroup",
    "HandleSet",
    "InputError",
    "Graph",
    "LaplacianEditor",
    "LearnedRings",
    "Mesh",
    "PointCloud",
    "Result",
    "Simulator",
    "UpGuess",
    "VertexGroups",
    "__version__",
    "bounding_box",
    "fit",
    "guess_up",
    "laplacian_edit",
    "learn_rings",
    "load_groups",
    "load_handles",
    "load_mesh",
    "load_points",
    "load_rings",
    "parse_handles",
    "save_def",
    "save_handles",
    "save_mesh",
    "save_points",
    "save_rings",
    "save_sel",
    "select_box",
    "select_nearest",
    "select_sphere",
    "simulate",
]
del _os  # only needed above; keeps arapkit.os / arapkit._os out of the namespace

_compat.install()


def __getattr__(name: str):
    # ``arapkit.methods.deformer`` after a plain ``import arapkit``: old flat paths, for one release
    return _compat.old_module(name)
