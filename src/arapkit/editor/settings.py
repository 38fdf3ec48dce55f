"""The editor's solver panel: which methods it offers, and what the user chose there.

The methods, their labels and what each accepts (a rigidity map, a volumetric form) are
read from :mod:`arapkit.methods.registry`, so a method registered for the ``"editor"``
door appears in the panel without a change here.  Volumetric ARAP is not a method of its
own: it is a method whose registration says ``volumetric=True``, run on the
tetrahedralised inside, and the selector offers it as one more entry.

Examples
--------
>>> [c.method for c in solver_choices()][:2]
['rring', 'spokes-and-rims']
>>> s = SolverSettings(method="volumetric")  # the name of arapkit 0.1's sessions
>>> s.method, s.volumetric, s.label
('rring', True, 'volumetric r-ring ARAP')
"""

from __future__ import annotations

import contextlib
import dataclasses
from typing import Any

from arapkit import validate
from arapkit.arap.domains import all_weight_kinds
from arapkit.errors import InputError
from arapkit.mesh.weights import DEFAULT_WEIGHTS
from arapkit.methods.registry import MethodInfo, method, method_names, methods

__all__ = ["METHODS", "MULTIRES_CHOICES", "SolverChoice", "SolverSettings", "multires_label",
           "solver_choices"]

#: the Solver panel's *Coarse to fine* choices and the ``multires`` value each stands for
#: (``Deformer(..., multires=...)``: None decides by the mesh's size and the method)
MULTIRES_CHOICES = {"Auto": None, "On": True, "Off": False}


def multires_label(multires: bool | None) -> str:
    """The panel's label of a ``multires`` value.

    Examples
    --------
    >>> multires_label(None), multires_label(False)
    ('Auto', 'Off')
    """
    return next(k for k, v in MULTIRES_CHOICES.items() if v is multires)


#: the methods the editor offers, by their one name (the registry's order)
METHODS = method_names("editor")
#: sessions of arapkit 0.1 named volumetric ARAP as a method of its own: (method, volumetric)
_OLD_SELECTIONS = {"volumetric": ("rring", True)}


@dataclasses.dataclass(frozen=True)
class SolverChoice:
    """One entry of the method selector: a method, on the surface or on the volume.

    Examples
    --------
    >>> SolverChoice("SR-ARAP", "sr-arap").volumetric
    False
    """

    label: str
    method: str
    volumetric: bool = False


def solver_choices(has_faces: bool = True) -> tuple[SolverChoice, ...]:
    """The selector's entries: every editor method, then the volumetric form of those with one.

    ``has_faces=False`` (a point cloud): only the methods that apply to it (the registry's
    ``needs_faces``), and no volume.

    Examples
    --------
    >>> [c.label for c in solver_choices() if c.volumetric]
    ['volumetric r-ring ARAP']
    >>> [c.method for c in solver_choices(has_faces=False)]
    ['rring', 'embedded']
    """
    offered = tuple(m for m in methods("editor") if m.applies_to(has_faces))
    if not has_faces:
        return tuple(SolverChoice(m.label, m.name) for m in offered)
    return (*(SolverChoice(m.label, m.name) for m in offered),
            *(SolverChoice(f"volumetric {m.label}", m.name, True) for m in offered
              if m.volumetric))


@dataclasses.dataclass
class SolverSettings:
    """What the user chose in the solver panel.

    ``method`` is a name of :mod:`arapkit.methods.registry` (older names such as
    ``"arap"`` and ``"volumetric"`` are translated on construction); ``volumetric`` runs
    it on the tetrahedralised inside.  ``live_budget_ms`` and ``live_max_iter`` bound the
    work before the first update of a drag is sent; the solve then continues to ``tol`` /
    ``max_iter`` unless a newer drag supersedes it.

    Examples
    --------
    >>> SolverSettings(method="arap").method
    'rring'
    """

    method: str = "rring"
    weights: str = DEFAULT_WEIGHTS
    tol: float = 1e-3
    max_iter: int = 200
    live_max_iter: int = 8
    live_budget_ms: float = 60.0
    volumetric: bool = False
    #: coarse to fine (a proxy previews while dragging): None decides by the mesh's size
    #: (:func:`arapkit.methods.deformer.coarse_to_fine`)
    multires: bool | None = None
    #: secondary motion: drags move an elastic body that lags and settles
    #: (:mod:`arapkit.editor.motion`) instead of the static solve
    dynamics: bool = False
    #: its stiffness in N/m; None: scaled to the mesh (:func:`arapkit.editor.motion.
    #: editor_stiffness`), so that any mesh wobbles on the same time scale
    stiffness: float | None = None
    #: its mass damping rate in 1/s
    damping: float = 4.0

    def __post_init__(self) -> None:
        if not isinstance(self.method, str):
            return  # refused by from_dict, which names the field
        if self.method in _OLD_SELECTIONS:
            self.method, self.volumetric = _OLD_SELECTIONS[self.method]
        # an alias becomes the one name; an unknown name stays for from_dict to refuse
        with contextlib.suppress(InputError):
            self.method = method(self.method).name

    @property
    def info(self) -> MethodInfo:
        """The registry's entry for :attr:`method` (what it accepts)."""
        return method(self.method, "editor")

    @property
    def label(self) -> str:
        """What the selector shows for these settings."""
        return next((c.label for c in solver_choices()
                     if (c.method, c.volumetric) == (self.method, self.volumetric)),
                    self.method)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SolverSettings:
        """Settings from a session's ``solver`` object, each field checked.

        Examples
        --------
        >>> SolverSettings.from_dict({"tol": 1e-4}).tol
        0.0001
        >>> SolverSettings.from_dict({"method": "arap"}).method
        'rring'
        """
        known = [f.name for f in dataclasses.fields(cls)]
        validate.keys_of(d, known, "session solver")
        s = cls(**d)
        if not isinstance(s.method, str) or s.method not in METHODS:
            raise InputError(f"session solver: method {s.method!r:.40}: expected one of "
                             f"{', '.join(METHODS)}")
        if not isinstance(s.volumetric, bool):
            raise InputError(f"session solver: volumetric must be true or false, got "
                             f"{s.volumetric!r:.40}")
        if s.multires is not None and not isinstance(s.multires, bool):
            raise InputError(f"session solver: multires must be true, false or null, got "
                             f"{s.multires!r:.40}")
        if s.volumetric and not s.info.volumetric:
            raise InputError(f"session solver: method {s.method!r} has no volumetric form")
        kinds = all_weight_kinds()  # a mesh's or a point cloud's
        if not isinstance(s.weights, str) or s.weights not in kinds:
            raise InputError(f"session solver: weights {s.weights!r:.40}: expected one of "
                             f"{', '.join(kinds)}")
        s.tol = validate.tolerance(s.tol, "session solver: tol")
        s.max_iter = validate.iteration_cap(s.max_iter, "session solver: max_iter")
        s.live_max_iter = validate.iteration_cap(s.live_max_iter, "session solver: live_max_iter")
        s.live_budget_ms = validate.number(s.live_budget_ms, "session solver: live_budget_ms",
                                           lo=0.0, hi=3.6e6)
        if not isinstance(s.dynamics, bool):
            raise InputError(f"session solver: dynamics must be true or false, got "
                             f"{s.dynamics!r:.40}")
        if s.stiffness is not None:
            s.stiffness = validate.number(s.stiffness, "session solver: stiffness", lo=0.0,
                                          lo_open=True)
        s.damping = validate.number(s.damping, "session solver: damping", lo=0.0, hi=1e6)
        return s
