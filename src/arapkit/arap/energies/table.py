"""The table of local/global energies: each energy module registers its builder here.

An energy is one module with a builder and one :func:`register_energy` call at import;
:func:`make_energy` looks the name up, applies the checks every energy shares (its options,
its rigidity map, whether it needs triangles) and calls the builder. Importing
:mod:`arapkit.arap.energies` imports every energy module, so the table is full.

Examples
--------
>>> from arapkit.arap.energies import energy_info
>>> energy_info("sr-arap").descent, energy_info("rring").rigidity_map
(False, True)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ...errors import InputError

if TYPE_CHECKING:
    from ..graph import EdgeGraph
    from .base import NeighbourhoodEnergy

__all__ = ["EnergyInfo", "energy_info", "energy_names", "make_energy", "register_energy"]


@dataclass(frozen=True)
class EnergyInfo:
    """One local/global energy: how to build it and the facts its form fixes.

    Attributes
    ----------
    name : str
    build : callable(graph, w, weights_kind, rings, perm, **options) -> NeighbourhoodEnergy
        ``rings`` is r per vertex in the graph's numbering (None without a rigidity map);
        ``perm`` (internal -> caller, or None) maps per-vertex options given in the caller's
        numbering.
    descent : bool
        Each local and global step minimises the energy exactly over its block, so the
        energy never rises (and Anderson acceleration's energy safeguard applies).
    rigidity_map : bool
        Takes r per vertex.
    needs_faces : bool or callable(options) -> bool
        Defined on triangles (refused on a plain edge graph); a callable says so for the
        given options (r-ring ARAP reads triangles only with a ring scale below 1).
    options : tuple of str
        The builder's keyword options.
    without_faces : bool
        Where ``needs_faces`` holds it reads the triangles when the graph has them, and is
        built without them otherwise (r-ring ARAP's ring-scale blend takes a rotation per
        edge on a point cloud's graph): not refused there.
    """

    name: str
    build: Callable[..., NeighbourhoodEnergy]
    descent: bool = True
    rigidity_map: bool = False
    needs_faces: bool | Callable[[dict], bool] = False
    options: tuple[str, ...] = ()
    without_faces: bool = False

    def faces_needed(self, options: dict) -> bool:
        """Whether the energy, with these options, reads the triangles."""
        return bool(self.needs_faces(options) if callable(self.needs_faces)
                    else self.needs_faces)


_ENERGIES: dict[str, EnergyInfo] = {}


def register_energy(info: EnergyInfo) -> EnergyInfo:
    """Add an energy to the table (its module calls this once, at import)."""
    _ENERGIES[info.name] = info
    return info


def energy_names() -> tuple[str, ...]:
    """The registered energies, in registration order (r-ring first)."""
    return tuple(_ENERGIES)


def energy_info(name: str) -> EnergyInfo:
    """The registered energy ``name``, or a one-line InputError listing the others."""
    info = _ENERGIES.get(name)
    if info is None:
        raise InputError(f"unknown energy '{name}' (use one of {', '.join(_ENERGIES)})")
    return info


def make_energy(name: str, graph: EdgeGraph, w: np.ndarray, weights_kind: str | None, *,
                rings=1, perm: np.ndarray | None = None, **options) -> NeighbourhoodEnergy:
    """Build the named local/global energy on ``graph`` (internal numbering).

    ``rings`` is a checked int32 array (:func:`arapkit.arap.rings.check_rings`) in the caller's
    numbering; ``perm`` (internal -> caller) maps it.

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.arap.graph import EdgeGraph
    >>> g = EdgeGraph(np.eye(3), np.array([[0, 1], [1, 2]]))
    >>> make_energy("rring", g, np.ones(2), None, rings=np.ones(3, dtype=np.int32)).name
    'rring'
    """
    info = energy_info(name)
    unknown = sorted(set(options) - set(info.options))
    if unknown:
        raise InputError(f"energy '{name}' takes no option {unknown[0]!r}")
    r = None
    if info.rigidity_map:
        r = np.asarray(rings, dtype=np.int32)
        r = r if perm is None else r[perm]
    elif not np.all(np.asarray(rings) == 1):
        raise InputError(f"energy '{name}' has no rigidity map (rings must be 1)")
    if info.faces_needed(options) and graph.faces is None and not info.without_faces:
        raise InputError(f"{graph.name}: energy '{name}' needs a triangle mesh")
    return info.build(graph, w, weights_kind, r, perm, **options)
