"""How each kind of shape gets its coarse copy: the coarse-to-fine step, pluggable by domain.

Coarse to fine needs, of a shape, a coarser one with each full vertex's *home* on it (the
coarse vertex it follows first: :class:`~arapkit.methods.multires.binding.Binding`), a way
to start making it in the background, and the specks to leave out. A triangle mesh is
decimated (:mod:`.decimator`), a point cloud subsampled (:mod:`.subsampler`); each module
registers its :class:`Coarsening` under its domain's name
(:func:`arapkit.arap.domains.domain_of`), and the coarse-to-fine machinery asks
:func:`coarsening_of` instead of testing what a shape is.

Examples
--------
>>> import numpy as np
>>> from arapkit.mesh.cloud import PointCloud
>>> from arapkit.methods import multires  # fills the table
>>> coarsening_of(PointCloud(np.eye(3))).name
'subsample'
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...arap.domains import domain_of
from ...errors import InputError

__all__ = ["Coarsening", "coarsening_of", "register_coarsening"]


@dataclass(frozen=True)
class Coarsening:
    """A domain's coarse copies.

    Attributes
    ----------
    name : str
        What it does (``"decimate"``, ``"subsample"``), for notes.
    make : callable(shape, n_target) -> (coarse shape, home)
        A copy of about ``n_target`` vertices (the shape itself where it is at most twice
        that) and each full vertex's home on it (-1 where it has none).
    start : callable(shape, n_target) -> bool
        Begin making it in the background (False where nothing was started).
    specks : callable(shape, n_target) -> (n,) bool or None
        The vertices ``make`` leaves out (None: none).
    """

    name: str
    make: Callable[[Any, int], tuple[Any, np.ndarray]]
    start: Callable[[Any, int], bool]
    specks: Callable[[Any, int], np.ndarray | None]


_BY_DOMAIN: dict[str, Coarsening] = {}


def register_coarsening(domain: str, info: Coarsening) -> Coarsening:
    """Make ``info`` the coarse copies of the shapes of ``domain`` (its module, once)."""
    _BY_DOMAIN[domain] = info
    return info


def coarsening_of(shape) -> Coarsening:
    """The coarse copies of ``shape``'s domain, or a one-line error where it has none."""
    dom = domain_of(shape)
    info = _BY_DOMAIN.get(dom.name)
    if info is None:
        raise InputError(f"{shape.name}: a {dom.label} cannot be solved coarse to fine "
                         "(use multires=False)")
    return info
