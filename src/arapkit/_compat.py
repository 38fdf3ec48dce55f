"""Old module paths (``arapkit.solver``, ``arapkit.volume`` ...) as aliases, for one release.

arapkit 0.1 kept every module flat in ``arapkit/``; the modules now live in layered
subpackages. ``import arapkit.solver`` still works: a finder on ``sys.meta_path`` answers
for the old names with a module that hands every attribute on to the new one, and warns
once with a :class:`DeprecationWarning` naming the new path.

Examples
--------
>>> import warnings
>>> with warnings.catch_warnings():
...     warnings.simplefilter("ignore", DeprecationWarning)
...     from arapkit.solver import Deformer
>>> from arapkit.methods.deformer import Deformer as New
>>> Deformer is New
True
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import types
import warnings
from typing import Any

#: old module path -> new module path
MOVED = {
    "arapkit.accel": "arapkit.arap.accel",
    "arapkit.attributes": "arapkit.mesh.attributes",
    "arapkit.backend": "arapkit.arap.backends.cpu",
    "arapkit.batch": "arapkit.workflows.batch",
    "arapkit.colors": "arapkit.plots.colors",
    "arapkit.compare": "arapkit.workflows.compare",
    "arapkit.constraints": "arapkit.arap.constraints",
    "arapkit.embedded": "arapkit.methods.embedded",
    "arapkit.energy": "arapkit.arap.energies",
    "arapkit.fileio": "arapkit.io",
    "arapkit.handles": "arapkit.io",
    "arapkit.jobs": "arapkit.workflows.jobs",
    "arapkit.laplacian": "arapkit.methods.laplacian",
    "arapkit.loop": "arapkit.arap.loop",
    # methods/multires.py became a package (its old import path is the package itself)
    "arapkit.methods.decimation_child": "arapkit.methods.multires.decimation_child",
    "arapkit.meshwriters": "arapkit.io",
    "arapkit.orientation": "arapkit.mesh.orientation",
    "arapkit.problem": "arapkit.arap.problem",
    "arapkit.quality": "arapkit.mesh.quality",
    "arapkit.rings": "arapkit.arap.rings",
    "arapkit.rotations": "arapkit.arap.rotations",
    "arapkit.shapes": "arapkit.mesh.shapes",
    "arapkit.solver": "arapkit.methods.deformer",
    "arapkit.spokes_rims": "arapkit.arap.energies.spokes_rims",
    "arapkit.sr_arap": "arapkit.arap.energies.sr_arap",
    "arapkit.torch_backend": "arapkit.arap.backends.torch_backend",
    "arapkit.volume": "arapkit.methods.volumetric",
    "arapkit.weights": "arapkit.mesh.weights",
    "arapkit.welding": "arapkit.mesh.welding",
}


def _registry() -> types.ModuleType:
    return importlib.import_module("arapkit.methods.registry")


#: constants an old module had that the method registry now derives (read on access)
DERIVED = {
    "arapkit.energy": {
        "ENERGIES": lambda: _registry().method_names("cli"),
        "LOCAL_GLOBAL": lambda: tuple(m.name for m in _registry().methods() if m.local_global),
    },
}


class _Alias(types.ModuleType):
    """A module that reads and writes through to the module it stands for."""

    def __init__(self, name: str, target: types.ModuleType) -> None:
        super().__init__(name, target.__doc__)
        object.__setattr__(self, "_target", target)

    def __getattr__(self, name: str) -> Any:
        derived = DERIVED.get(object.__getattribute__(self, "__name__"), {})
        if name in derived:
            return derived[name]()
        return getattr(object.__getattribute__(self, "_target"), name)

    def __setattr__(self, name: str, value: Any) -> None:
        if name.startswith("__"):
            object.__setattr__(self, name, value)
        else:  # monkeypatching the old path patches the real module
            setattr(object.__getattribute__(self, "_target"), name, value)

    def __delattr__(self, name: str) -> None:
        delattr(object.__getattribute__(self, "_target"), name)

    def __dir__(self) -> list[str]:
        return dir(object.__getattribute__(self, "_target"))


class _AliasLoader(importlib.abc.Loader):
    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType:
        new = MOVED[spec.name]
        warnings.warn(f"{spec.name} moved to {new}; the old path goes in the next release",
                      DeprecationWarning, stacklevel=2)  # warnings skips importlib's frames
        return _Alias(spec.name, importlib.import_module(new))

    def exec_module(self, module: types.ModuleType) -> None:
        pass


class _AliasFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path=None, target=None):
        if fullname in MOVED:
            return importlib.machinery.ModuleSpec(fullname, _AliasLoader())
        return None


def install() -> None:
    """Put the finder on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _AliasFinder) for f in sys.meta_path):
        sys.meta_path.append(_AliasFinder())


def old_module(name: str) -> types.ModuleType:
    """``arapkit.<name>`` for an old flat module name (``arapkit.solver`` after ``import arapkit``).

    Raises AttributeError for a name that is no old module.
    """
    full = f"arapkit.{name}"
    if full not in MOVED:
        raise AttributeError(f"module 'arapkit' has no attribute {name!r}")
    return importlib.import_module(full)
