"""The deformation methods arapkit offers, with what each can do, as data.

Every door (``Deformer``, ``arapkit deform`` / ``compare`` / ``batch``, the editor, the
PyTorch layer) asks this table what a method accepts instead of comparing names: a new
method is one module plus one :func:`register` call, and the doors and the method x interface
tests pick it up from here.

Examples
--------
>>> from arapkit.methods.registry import method, methods
>>> method("sr-arap").rigidity_map
False
>>> [m.name for m in methods("torch")]
['rring', 'spokes-and-rims', 'smooth-arap']
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ..errors import InputError

__all__ = ["INTERFACES", "VOLUMETRIC_INTERFACES", "MethodInfo", "MethodOption", "method",
           "method_names", "methods", "register"]

#: the doors a method can be offered through: :class:`arapkit.Deformer` ("library"),
#: ``arapkit deform`` ("cli"), ``arapkit compare``, ``arapkit batch``, the editor's solver,
#: :class:`arapkit.torch.ARAPLayer` ("torch") and the Blender add-on's ARAP Deform panel
#: ("blender", :mod:`arapkit.blender`)
INTERFACES = ("library", "cli", "compare", "batch", "editor", "torch", "blender")
#: the doors that offer volumetric ARAP (``volumetric=True``) to a method that runs on a
#: volume: batch jobs and the torch layer have no volume
VOLUMETRIC_INTERFACES = ("library", "cli", "compare", "editor")


@dataclass(frozen=True)
class MethodOption:
    """A method's own keyword option.

    Attributes
    ----------
    key : str
        The keyword the method's builder takes (``sr_alpha`` is SR-ARAP's ``alpha``).
    default : object
        The value used when the option is not given.
    check : callable(value) -> value
        Validates a given value (a one-line InputError otherwise).
    describe : str, optional
        How reports and figure titles show the value (``"alpha = {:g}"``); None: not shown.
    """

    key: str
    default: Any
    check: Callable[[Any], Any]
    describe: str | None = None


@dataclass(frozen=True)
class MethodInfo:
    """One deformation method and its capabilities.

    Attributes
    ----------
    name : str
        The one name of the method everywhere: ``Deformer(energy=...)``, ``--energy``,
        batch jobs, editor sessions, reports.
    label : str
        What a person reads (editor selector, compare tables).
    local_global : bool
        Solved by the local/global loop on an energy of :mod:`arapkit.arap.energies`.
    descent : bool
        Every iteration lowers the energy (its history is monotone).
    rigidity_map : bool
        Takes r per vertex (``rings``).
    accelerate : bool
        Takes Anderson acceleration.
    volumetric : bool
        Runs on a tetrahedralised volume too (``volumetric=True``).
    multires : bool
        Can be solved coarse to fine on a decimated proxy (``multires=True``,
        :mod:`arapkit.methods.multires`): a local/global descent method.
    needs_faces : bool
        Defined on triangles: refused on a point cloud or graph (a shape whose domain,
        :func:`arapkit.arap.domains.domain_of`, has no faces), in every door.
    planar : bool
        Runs in the plane on a planar shape (2 x 2 rotations, no folded triangles:
        :mod:`arapkit.methods.planar`); a method without it solves planar shapes in 3D.
    groups : bool
        Takes vertex groups (``groups=``): shared-rotation groups and rigid parts
        (:mod:`arapkit.arap.grouped`): a local/global method with one rotation per vertex
        and no coupling between rotations.
    handle_tol : float
        How far a handle may end from its target, relative to the bounding-box diagonal:
        0 for hard constraints (eliminated, met to round-off), the soft constraints'
        residual bound otherwise.
    options : dict of str to MethodOption
        Method-specific keyword options by their public name (``sr_alpha``, ``nodes``).
    interfaces : frozenset of str
        The doors of :data:`INTERFACES` that offer the method.
    why_not : dict of str to str
        For a door of :data:`INTERFACES` that does not offer the method, why (the refusal
        says so); the default reason otherwise.
    """

    name: str
    label: str
    local_global: bool
    descent: bool
    rigidity_map: bool = False
    accelerate: bool = False
    volumetric: bool = False
    multires: bool = False
    needs_faces: bool = False
    planar: bool = False
    groups: bool = False
    handle_tol: float = 0.0
    options: dict[str, MethodOption] = field(default_factory=dict, hash=False)
    interfaces: frozenset[str] = field(default_factory=lambda: frozenset(INTERFACES))
    why_not: dict[str, str] = field(default_factory=dict, hash=False, compare=False)

    def applies_to(self, has_faces: bool) -> bool:
        """Whether the method runs on a shape with (or without) triangles.

        Examples
        --------
        >>> method("spokes-and-rims").applies_to(False), method("rring").applies_to(False)
        (False, True)
        """
        return has_faces or not self.needs_faces

    @property
    def exact_handles(self) -> bool:
        """Handles are met exactly (eliminated); False for soft constraints."""
        return self.handle_tol == 0.0


_METHODS: dict[str, MethodInfo] = {}
#: names that editor sessions and reports of arapkit 0.1 used, mapped to the one name
_ALIASES = {"arap": "rring"}


def register(info: MethodInfo) -> MethodInfo:
    """Add a method to the table (its module calls this once, at import)."""
    unknown = (set(info.interfaces) | set(info.why_not)) - set(INTERFACES)
    if unknown:
        raise ValueError(f"method {info.name!r}: unknown interfaces {sorted(unknown)}")
    _METHODS[info.name] = info
    return info


def methods(interface: str | None = None) -> tuple[MethodInfo, ...]:
    """The registered methods, in registration order; only those ``interface`` offers.

    Importing :mod:`arapkit.methods` registers every method.
    """
    return tuple(m for m in _METHODS.values() if interface is None or interface in m.interfaces)


def method_names(interface: str | None = None) -> tuple[str, ...]:
    """Names of :func:`methods`."""
    return tuple(m.name for m in methods(interface))


def method(name: str, interface: str | None = None) -> MethodInfo:
    """The method called ``name`` (old aliases accepted); a one-line InputError otherwise.

    ``interface`` also checks that the door offers it.

    Examples
    --------
    >>> method("arap").name
    'rring'
    """
    key = _ALIASES.get(str(name), str(name))
    info = _METHODS.get(key)
    if info is None or (interface is not None and interface not in info.interfaces):
        where = f" in {interface}" if interface else ""
        raise InputError(f"unknown method '{name}'{where} "
                         f"(use one of {', '.join(method_names(interface))})")
    return info
