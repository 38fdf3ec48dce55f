"""The full mesh's parts the proxy does not solve, placed by the exact solve's own rule.

Skinned with its one nearest proxy vertex, a speck far off the surface (a scan's debris)
turns with that vertex's rotation and lands, by the lever arm, up to 20 % of the diagonal
from the exact solve's placement. Instead a part without a handle follows the rigid fit to
its anchors (:class:`~arapkit.arap.constraints.Followers`, the full problem's own rule) or
stays at rest (``free_components="fix"``), and a speck with a handle moves rigidly with its
handled vertices (exact for the editor's rigid moves).

Examples
--------
>>> import numpy as np
>>> from arapkit.mesh.model import Mesh
>>> two = Mesh(np.vstack([np.eye(3), np.eye(3) + 5]), [[0, 1, 2], [3, 4, 5]])
>>> X = two.vertices + 1.0  # the first triangle (the handled part) moved by 1
>>> FreeParts(two, np.array([0, 1, 2]), "fix", None).apply(X)
>>> X[3:].tolist() == two.vertices[3:].tolist()  # the free part stays at rest
True
"""

from __future__ import annotations

import numpy as np

from ...arap.constraints import Followers, anchor_components
from ...mesh.model import Mesh

__all__ = ["FreeParts"]


class FreeParts:
    """The parts of ``mesh`` without a handle, their rule, and the handled specks'.

    Parameters
    ----------
    mesh : Mesh
        The full mesh.
    handles : (h,) int
        Its handle vertices.
    policy : str
        ``free_components`` (``"follow"``, ``"fix"``, ``"error"``).
    covered : (n,) bool or None
        :attr:`Binding.covered`: the vertices the proxy was made from (None: all).
    """

    def __init__(self, mesh: Mesh, handles: np.ndarray, policy: str,
                 covered: np.ndarray | None) -> None:
        self._rest = mesh.vertices
        self.fixed = anchor_components(mesh, handles, policy)[0]
        self.followers = Followers.of(mesh, self.fixed) if policy == "follow" else None
        self.riders = None
        if covered is not None and not covered[handles].all():
            # each handled speck's other vertices follow the fit to its own handled ones
            free = ~covered
            free[handles] = False
            self.riders = Followers.on_own_anchors(mesh, free, handles[~covered[handles]])

    def apply(self, X: np.ndarray) -> None:
        """Place the parts in ``X`` (the full mesh's shape, changed in place)."""
        X[self.fixed] = self._rest[self.fixed]  # where a part follows nothing: at rest
        for rule in (self.followers, self.riders):
            if rule is not None:
                rule.apply(X)
