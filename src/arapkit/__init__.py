"""arapkit: as-rigid-as-possible surface deformation with controllable rigidity.

Implements r-ring ARAP (Chen, Gao, Lai, Xia 2017), standard ARAP (Sorkine & Alexa 2007)
as its r = 1 case, and Laplacian surface editing.

Examples
--------
>>> import arapkit
>>> from arapkit.shapes import bar, bar_bend
>>> mesh = bar()
>>> handles, targets = bar_bend(mesh, 180)
>>> res = arapkit.Deformer(mesh, handles, rings=3).solve(targets)
>>> res.converged
True
"""

import os

# Parallel regions in the kernels are short and frequent. GNU OpenMP's default busy-wait
# makes idle workers spin; on a machine shared with other processes that steals the cores
# the working threads need (measured: 2-3x slower iterations). It must be set before numba
# starts its OpenMP pool (at the first parallel call); an explicit user setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from .errors import InputError  # noqa: E402
from .laplacian import LaplacianEditor, laplacian_edit
from .learn import LearnedRings, learn_rings
from .mesh import Mesh, load_mesh
from .solver import Deformer, Result

__version__ = "0.1.0"

__all__ = [
    "Deformer",
    "InputError",
    "LaplacianEditor",
    "LearnedRings",
    "Mesh",
    "Result",
    "__version__",
    "laplacian_edit",
    "learn_rings",
    "load_mesh",
]
