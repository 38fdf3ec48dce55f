"""The kinds of shape the solver runs on, and what each can do, as data.

A *domain* is a model class (a triangle :class:`~arapkit.mesh.model.Mesh`, a
:class:`~arapkit.mesh.cloud.PointCloud`) with how to make its edge graph and its edge
weights, its weight kinds and default, and whether it has triangles. The problem
(:meth:`arapkit.arap.problem.ARAPProblem.from_mesh`), the methods and every door ask this
table instead of testing what a shape is: a new domain is its model's modules plus one
:func:`register_domain` call.

Examples
--------
>>> import numpy as np
>>> from arapkit.mesh.cloud import PointCloud
>>> d = domain_of(PointCloud(np.eye(3)))
>>> d.name, d.has_faces, d.default_weights
('cloud', False, 'gaussian')
>>> domain("mesh").weight_kinds
('cotan', 'cotan-clamped', 'cotan-clamped-each', 'uniform')
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from ..mesh.cloud import PointCloud
from ..mesh.cloud_weights import CLOUD_WEIGHT_KINDS, DEFAULT_CLOUD_WEIGHTS, graph_weights
from ..mesh.model import Mesh
from ..mesh.weights import DEFAULT_WEIGHTS, WEIGHT_KINDS, edge_weights, given_weights
from .graph import EdgeGraph

__all__ = ["Domain", "all_weight_kinds", "domain", "domain_of", "domains", "register_domain"]


@dataclass(frozen=True)
class Domain:
    """One kind of shape and what the solver can do with it.

    Attributes
    ----------
    name : str
        ``"mesh"``, ``"cloud"``: the key other tables (a method's ``needs_faces``, the
        coarse-to-fine proxies of :mod:`arapkit.methods.multires`) are read by.
    label : str
        What a person reads ("triangle mesh", "point cloud").
    model : type
        The class of its shapes.
    has_faces : bool
        Whether its shapes have triangles (methods with ``needs_faces`` refuse the others).
    weight_kinds : tuple of str
        The edge weightings it takes by name.
    default_weights : str
        The weighting used unless the user names another.
    graph : callable(shape) -> EdgeGraph
        The solver's edge graph of a shape (edge ids are ``shape.edges``' rows).
    weights : callable(shape, kind) -> (m,) float
        The weights of a named kind (a one-line InputError for a kind it does not take).
    """

    name: str
    label: str
    model: type
    has_faces: bool
    weight_kinds: tuple[str, ...]
    default_weights: str
    graph: Callable[[Any], EdgeGraph]
    weights: Callable[[Any, str], np.ndarray]

    def edge_weights(self, shape, kind=None) -> tuple[np.ndarray, str | None]:
        """The weights of ``shape``'s edges and the kind's name (None for explicit ones).

        ``kind`` None: the shape's own weights where it carries them (a
        :class:`~arapkit.mesh.cloud.Graph` given weights), else :attr:`default_weights`;
        an array: explicit per-edge weights (finite, > 0).
        """
        if kind is None:
            own = getattr(shape, "weights", None)
            if isinstance(own, np.ndarray):
                return own, None
            kind = self.default_weights
        if not isinstance(kind, str):
            return given_weights(shape, kind), None
        return self.weights(shape, kind), kind


_DOMAINS: dict[str, Domain] = {}


def register_domain(info: Domain) -> Domain:
    """Add a domain to the table (once, at import)."""
    _DOMAINS[info.name] = info
    return info


def domains() -> tuple[Domain, ...]:
    """The registered domains, in registration order."""
    return tuple(_DOMAINS.values())


def domain(name: str) -> Domain:
    """The domain called ``name``."""
    return _DOMAINS[name]


def domain_of(shape) -> Domain:
    """The domain of ``shape`` (the most derived registered model it is an instance of).

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> domain_of(bar()).name
    'mesh'
    """
    best = None
    for info in _DOMAINS.values():
        if isinstance(shape, info.model) and (best is None or issubclass(info.model,
                                                                         best.model)):
            best = info
    if best is None:
        raise InputError(f"expected a mesh or a point cloud, got {type(shape).__name__}")
    return best


def all_weight_kinds() -> tuple[str, ...]:
    """Every weighting some domain takes by name, each once (the CLI's choices).

    Examples
    --------
    >>> all_weight_kinds()
    ('cotan', 'cotan-clamped', 'cotan-clamped-each', 'uniform', 'gaussian', 'laplacian')
    """
    return tuple(dict.fromkeys(k for d in _DOMAINS.values() for k in d.weight_kinds))


def _cloud_weights(cloud: PointCloud, kind: str) -> np.ndarray:
    return graph_weights(cloud.points, cloud.edges, kind, cloud.neighbours or 10, cloud.name)


register_domain(Domain("mesh", "triangle mesh", Mesh, True, WEIGHT_KINDS, DEFAULT_WEIGHTS,
                       EdgeGraph.from_mesh, edge_weights))
register_domain(Domain("cloud", "point cloud", PointCloud, False, CLOUD_WEIGHT_KINDS,
                       DEFAULT_CLOUD_WEIGHTS, EdgeGraph.from_cloud, _cloud_weights))
