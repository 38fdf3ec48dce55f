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

from .errors import InputError
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
