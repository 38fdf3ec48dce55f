"""Which method and which solver a :class:`~arapkit.methods.deformer.Deformer` call means.

The local/global methods are registered here from their energies (what an energy's form
fixes, descent, a rigidity map, acceleration, coarse to fine, the planar backend, comes
from the energy table), with their options; :func:`check_method` validates a method name
and its options for every door; the variants ``Deformer(..., volumetric=True)`` and
``multires=`` return register themselves with :func:`register_variant`, and
:func:`coarse_to_fine` says when the latter applies.

Examples
--------
>>> check_method("rring")
{}
>>> from arapkit.mesh.shapes import bar
>>> coarse_to_fine(bar(), None, {})
False
"""

from __future__ import annotations

from typing import Any

from ..arap.domains import domain_of
from ..arap.energies import energy_info
from ..arap.energies.smooth_arap import DEFAULT_LAMBDA, check_smooth_lambda
from ..arap.energies.sr_arap import DEFAULT_ALPHA, check_alpha
from ..errors import Advice, InputError
from ..mesh.model import Mesh
from .registry import INTERFACES, MethodInfo, MethodOption, method, method_names, methods, register

__all__ = ["INITS", "MULTIRES_AUTO_VERTICES", "check_domain", "check_method", "coarse_to_fine",
           "refuse_acceleration", "register_variant", "variant"]

INITS = ("identity", "laplacian")
#: ``multires=None`` (the default) solves coarse to fine from this many vertices: below it
#: a plain solve is already interactive, above it hundreds of full iterations are not
MULTIRES_AUTO_VERTICES = 100_000


def _local_global_method(name: str, label: str, **kw: Any) -> MethodInfo:
    """A method of the local/global loop: what its energy's form fixes comes from the energy.

    Anderson acceleration keeps an extrapolation only when it lowers the energy, a safeguard
    that holds for descent methods alone.
    """
    en = energy_info(name)
    # every energy of the loop is a neighbourhood energy, which the planar backend runs
    facts = {"descent": en.descent, "rigidity_map": en.rigidity_map,
             "accelerate": en.descent, "multires": en.descent, "planar": True,
             "needs_faces": en.faces_needed({})}
    return MethodInfo(name, label, local_global=True, **(facts | kw))


register(_local_global_method("rring", "r-ring ARAP", volumetric=True, groups=True))
# compare runs the paper's comparison set, which has no spokes-and-rims
register(_local_global_method("spokes-and-rims", "spokes-and-rims ARAP", groups=True,
                              interfaces=frozenset(INTERFACES) - {"compare"}))
register(_local_global_method(
    "sr-arap", "SR-ARAP",
    # sr_roi's vertex ids are checked where the mesh is known (make_energy)
    options={"sr_alpha": MethodOption("alpha", DEFAULT_ALPHA, check_alpha, "alpha = {:g}"),
             "sr_roi": MethodOption("roi", None, lambda roi: roi)},
    interfaces=frozenset(INTERFACES) - {"torch"},
    why_not={"torch": "its rotation coupling has no per-step fixed point"}))
register(_local_global_method(
    "smooth-arap", "Smooth ARAP",
    options={"smooth_lambda": MethodOption("smooth_lambda", DEFAULT_LAMBDA,
                                           check_smooth_lambda, "lambda = {:g}")},
    # coarse to fine counts r on the proxy with a ring scale, which this energy lacks,
    # and the tetrahedra have no Laplacian term (it needs the surface's triangles)
    multires=False))


def check_method(energy: str, sr_alpha=None, nodes=None, sr_roi=None,
                 smooth_lambda=None) -> dict:
    """Validate a method name and its options; return the method's options.

    Examples
    --------
    >>> check_method("sr-arap", "0.1")
    {'alpha': 0.1}
    >>> check_method("smooth-arap")
    {'smooth_lambda': 0.99}
    """
    names = method_names("library")
    if energy not in names:
        raise InputError(f"unknown energy '{energy}' (use one of {', '.join(names)})")
    info = method(energy)
    given = {"sr_alpha": sr_alpha, "nodes": nodes, "sr_roi": sr_roi,
             "smooth_lambda": smooth_lambda}
    for name, value in given.items():
        if value is not None and name not in info.options:
            owner = next(m.name for m in methods("library") if name in m.options)
            raise InputError(f"{name} is an option of energy '{owner}', not '{energy}'")
    options = {opt.key: opt.check(opt.default if given.get(name) is None else given[name])
               for name, opt in info.options.items()}
    # an option without a default is left out unless given
    return {key: value for key, value in options.items() if value is not None}


def check_domain(shape, energy: str = "rring", *, volumetric: bool = False,
                 init="identity") -> None:
    """Refuse, in one line, what ``shape``'s domain cannot do: a method defined on
    triangles (the registry's ``needs_faces``), a volume or a Laplacian start on a point
    cloud.

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.mesh.cloud import PointCloud
    >>> check_domain(PointCloud(np.eye(3), name="c.ply"), "sr-arap")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: c.ply: energy='sr-arap' needs a triangle mesh and c.ply is ...
    """
    dom = domain_of(shape)
    if dom.has_faces:
        return
    name = shape.name
    what = f" and {name} is a {dom.label}"
    if energy in method_names("library") and not method(energy).applies_to(False):
        fits = [m.name for m in methods("library") if m.applies_to(False)]
        raise InputError(Advice("{energy} needs a triangle mesh", energy=energy).after(
            f"{name}: ").before(f"{what} (methods for point clouds: {', '.join(fits)})"))
    if volumetric:
        raise InputError(f"{name}: volumetric ARAP fills a closed triangle surface{what}")
    if isinstance(init, str) and init == "laplacian":
        raise InputError(Advice("{init} (Laplacian editing) needs a triangle mesh",
                                init="laplacian").after(f"{name}: ").before(what))


def refuse_acceleration(info: MethodInfo, remedy: str = "") -> None:
    if not info.accelerate:
        raise InputError(f"accelerate: Anderson acceleration is for the local/global "
                         f"descent methods; energy '{info.name}' is not one{remedy}")


#: the classes ``Deformer(..., <name>=True)`` returns instead (``volumetric``, ``multires``),
#: registered by their own modules (:mod:`arapkit.methods.volumetric` and
#: :mod:`arapkit.methods.multires` register themselves)
_VARIANTS: dict[str, type] = {}


def register_variant(flag: str, cls: type) -> type:
    """Make ``Deformer(..., <flag>=True)`` return ``cls(mesh, handles, rings, **options)``.

    ``cls`` takes the Deformer's keyword options, less the method's (``energy``,
    ``sr_alpha``, ``sr_roi``, ``nodes``, ``smooth_lambda``), which :class:`Deformer`
    checks first.

    Examples
    --------
    >>> from arapkit.methods.volumetric import VolumetricDeformer
    >>> register_variant("volumetric", VolumetricDeformer) is VolumetricDeformer
    True
    """
    _VARIANTS[flag] = cls
    return cls


def coarse_to_fine(mesh: Mesh, multires: bool | None, options: dict) -> bool:
    """Whether ``Deformer(..., multires=...)`` solves coarse to fine.

    ``None`` (the default) means: for a method that can, on a mesh of at least
    :data:`MULTIRES_AUTO_VERTICES` vertices, unless the caller asked for a start of its own
    (``init``) or a partial SR-ARAP region.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> coarse_to_fine(bar(), None, {}), coarse_to_fine(bar(), True, {})
    (False, True)
    """
    energy = options.get("energy", "rring")
    if energy not in method_names("library"):
        return False  # Deformer itself says which names there are
    info = method(energy)
    if multires is None:
        # vertex groups have no proxy yet: a mesh with them is solved at full resolution
        return (info.multires and mesh.n_vertices >= MULTIRES_AUTO_VERTICES
                and options.get("init", "identity") == "identity"
                and options.get("sr_roi") is None and options.get("groups") is None)
    if multires and not info.multires:
        raise InputError(f"multires=True: energy '{info.name}' cannot be solved coarse to "
                         "fine (a local/global descent method can)")
    if multires and options.get("groups") is not None:
        raise InputError("multires=True: vertex groups are solved at full resolution only "
                         "(use multires=False)")
    return bool(multires)


def variant(flag: str) -> type:
    """The class registered for ``Deformer(..., <flag>=True)`` (:func:`register_variant`)."""
    return _VARIANTS[flag]
