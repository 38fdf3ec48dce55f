"""A problem with vertex groups: shared rotations and rigid parts, on the unchanged loop.

:func:`with_groups` turns an :class:`~arapkit.arap.problem.ARAPProblem` and a
:class:`~arapkit.mesh.groups.VertexGroups` into a :class:`GroupedProblem`, and
:class:`GroupedBackend` wraps any backend of it. Together they run through
:func:`~arapkit.arap.loop.local_global` (and so :func:`~arapkit.arap.solve.arap_solve` and
:class:`arapkit.Deformer`) with no change to the loop:

* **shared-rotation groups** (libigl's ``G``) live in the energy: each group's
  neighbourhoods are pooled into one (:mod:`arapkit.arap.shared`). The backend copies the
  group's rotation to its members and reports each member's own term of the energy;
* **rigid parts** live in the elimination: its free rows are the free vertices and one
  per free part (its centre), and held parts are constrained (:mod:`arapkit.arap.parts`).
  The backend adds the parts' rotation fit to the local step, places each part's vertices
  when the loop scatters a global solution, and builds the reduced right-hand side.

The loop's three entry points stay consistent: a solve that starts from a shape
(``start_energy``: a local step first) fits the parts to it, and one that starts at rest
(its first call is a global solve) finds the parts at rest. The backend tells a new solve
by the loop's position array, a new one each solve.

Examples
--------
>>> from arapkit.arap.backends import make_backend
>>> from arapkit.arap.loop import local_global
>>> from arapkit.arap.problem import ARAPProblem
>>> from arapkit.mesh.groups import VertexGroups
>>> from arapkit.mesh.shapes import bar, bar_bend
>>> m = bar(segments=(16, 2, 2))
>>> h, t = bar_bend(m, 90)
>>> mid = np.flatnonzero(np.abs(m.vertices[:, 0] - 4) < 1.2)
>>> p = with_groups(ARAPProblem.from_mesh(m, h), VertexGroups.from_lists([("mid", mid, True)],
...                                                                        m.n_vertices))
>>> res = local_global(p, GroupedBackend(make_backend(p), p).bind(p), t, None, tol=1e-6,
...                    max_iter=500)
>>> E = m.edges[np.isin(m.edges, mid).all(axis=1)]
>>> stretch = np.abs(np.linalg.norm(res.vertices[E[:, 0]] - res.vertices[E[:, 1]], axis=1)
...                  - np.linalg.norm(m.vertices[E[:, 0]] - m.vertices[E[:, 1]], axis=1))
>>> bool(stretch.max() < 1e-9), bool(np.all(np.diff(res.history) <= 1e-12 * res.history[0]))
(True, True)
"""

from __future__ import annotations

import time
import weakref
from dataclasses import dataclass, fields, replace
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from ..errors import Advice, InputError
from ..mesh.groups import VertexGroups
from ..mesh.weights import SOUND_WEIGHTS
from .constraints import return_free_memory
from .parts import PartLayout, PartSystem
from .problem import ARAPProblem
from .shared import owner_terms, pool_rotations, representatives

if TYPE_CHECKING:
    from .energies.base import NeighbourhoodEnergy

__all__ = ["GroupedBackend", "GroupedProblem", "as_groups", "with_groups"]

_NO_ROT = np.zeros((0, 3, 3))


def as_groups(groups, n_vertices: int, what: str = "groups") -> VertexGroups:
    """``groups`` as :class:`VertexGroups`: itself, or one id per vertex (libigl's ``G``:
    shared rotations, -1 for none).

    Examples
    --------
    >>> as_groups([0, 0, -1], 3).names
    ('group 0',)
    """
    if isinstance(groups, VertexGroups):
        if groups.n_vertices != n_vertices:
            raise InputError(f"{groups.source}: groups of {groups.n_vertices} vertices for a "
                             f"mesh of {n_vertices}")
        return groups
    return VertexGroups.from_ids(groups, n_vertices, source=what)


@dataclass(frozen=True, eq=False)
class GroupedProblem(ARAPProblem):
    """An :class:`ARAPProblem` with shared-rotation groups and rigid parts.

    Build with :func:`with_groups`. Beyond the problem's own attributes:

    Attributes
    ----------
    groups : VertexGroups
        The groups, in the caller's numbering.
    base_energy : NeighbourhoodEnergy or None
        The energy before its groups' neighbourhoods were pooled (None: no shared groups).
    layout : PartLayout or None
        The rigid parts in the solver's numbering (None: no rigid parts).
    """

    groups: VertexGroups | None = None
    base_energy: NeighbourhoodEnergy | None = None
    layout: PartLayout | None = None

    @cached_property
    def shared_rep(self) -> np.ndarray | None:
        """(n,) the owner (solver numbering) whose rotation each vertex uses; None without
        shared groups."""
        if self.base_energy is None:
            return None
        return representatives(self.groups.of_kind(False)[self.perm])

    @cached_property
    def part_system(self) -> PartSystem | None:
        """The rigid parts' reduced system for this handle set (factorised on first use)."""
        if self.layout is None:
            return None
        base = self.iperm[ARAPProblem.constrained.func(self)]
        return PartSystem.build(self.layout, self.graph, self.energy.system_w, base, self.name,
                                self._remedy(), nbh=self.energy.nbh)

    def _remedy(self) -> Advice | str:
        """What a factorisation failure advises (as the plain problem's)."""
        if not (self.w < 0).any():
            return ""
        return Advice(" (obtuse triangles give negative cotangent weights); use {weights}",
                      weights=SOUND_WEIGHTS)

    @cached_property
    def elimination(self):
        """As :attr:`ARAPProblem.elimination`; with rigid parts, the merged system."""
        if self.layout is None:
            return ARAPProblem.elimination.func(self)
        t0 = time.perf_counter()
        el = self.part_system.elimination
        return_free_memory()
        self.timings["factorisation_ms"] = 1e3 * (time.perf_counter() - t0)
        return el

    def release_factor(self) -> None:
        """As :meth:`ARAPProblem.release_factor` (the parts' system goes too)."""
        self.__dict__.pop("part_system", None)
        ARAPProblem.release_factor(self)

    @cached_property
    def constrained(self) -> np.ndarray:
        """Handles then anchors outside parts, then every vertex of a held part (caller
        numbering)."""
        if self.layout is None:
            return ARAPProblem.constrained.func(self)
        return self.perm[self.part_system.elimination.constrained]

    def constrained_targets(self, targets: np.ndarray) -> np.ndarray:
        """Positions of :attr:`constrained`: held parts placed by their handles.

        Raises a one-line InputError naming the part when no rigid motion meets a part's
        handles.
        """
        base = ARAPProblem.constrained_targets(self, targets)
        if self.layout is None:
            return base
        known = np.zeros((self.n_vertices, 3))
        known[self.iperm[ARAPProblem.constrained.func(self)]] = base
        return self.part_system.constrained_positions(self.vertices, known, self.diagonal,
                                                      self.groups.source)

    @cached_property
    def diagonal(self) -> float:
        """The rest shape's bounding-box diagonal (solver units): a part's handles are
        met when the best rigid motion misses them by less than a fraction of it."""
        V = self.vertices
        return float(np.linalg.norm(V.max(axis=0) - V.min(axis=0))) if len(V) else 1.0

    @cached_property
    def b_rest(self) -> np.ndarray:
        """As :attr:`ARAPProblem.b_rest`; with rigid parts, the merged system's (its free
        rows hold it)."""
        b = ARAPProblem.b_rest.func(self)
        return b if self.layout is None else self.part_system.rest_rhs(b)

    def without_groups(self) -> ARAPProblem:
        """The same problem without its groups (the energy unpooled, the factor not kept)."""
        own = {f.name: getattr(self, f.name) for f in fields(ARAPProblem)}
        own["energy"] = self.base_energy or self.energy
        own["timings"] = {k: v for k, v in self.timings.items() if k != "factorisation_ms"}
        return ARAPProblem(**own)

    def with_rings(self, rings) -> GroupedProblem:
        """As :meth:`ARAPProblem.with_rings`, the groups kept."""
        plain = replace(self, energy=self.base_energy or self.energy, base_energy=None)
        return _pooled(ARAPProblem.with_rings(plain, rings))


def _pooled(p: GroupedProblem) -> GroupedProblem:
    """``p`` with its shared groups' neighbourhoods pooled (``p.energy`` unpooled)."""
    shared = p.groups.of_kind(False)
    if not (shared >= 0).any():
        return p
    pooled = pool_rotations(p.energy, p.graph, p.w, shared[p.perm], p.groups.source)
    return replace(p, energy=pooled, base_energy=p.energy)


def with_groups(problem: ARAPProblem, groups) -> ARAPProblem:
    """``problem`` with vertex groups (:class:`VertexGroups`, or libigl's ``G``: one id per
    vertex, shared rotations); ``problem`` itself when ``groups`` is None or empty.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> p = ARAPProblem.from_mesh(bar(segments=(6, 2, 2)), [0])
    >>> g = np.full(p.n_vertices, -1); g[:4] = 0
    >>> type(with_groups(p, g)).__name__, with_groups(p, None) is p
    ('GroupedProblem', True)
    """
    if groups is None:
        return problem
    if isinstance(problem, GroupedProblem):
        raise InputError("with_groups: the problem has groups already")
    g = as_groups(groups, problem.n_vertices)
    if not (g.ids >= 0).any():
        return problem
    own = {f.name: getattr(problem, f.name) for f in fields(ARAPProblem)}
    own["timings"] = dict(problem.timings)
    layout = None
    if g.rigid.any():
        layout = PartLayout.build(problem.graph, g.of_kind(True)[problem.perm],
                                  g.names_of_kind(True))
    return _pooled(GroupedProblem(**own, groups=g, layout=layout))


class GroupedBackend:
    """A backend of a :class:`GroupedProblem`: another backend plus the groups' steps.

    Parameters
    ----------
    inner : backend
        A backend of the problem's (pooled) energy (:func:`~arapkit.arap.backends.make_backend`).
    problem : GroupedProblem

    Rigid parts need the inner backend's ``vertex_rhs`` (both backends have it); the
    merged system is solved with the problem's CPU factor.
    """

    def __init__(self, inner, problem: GroupedProblem) -> None:
        self.inner = inner
        self.problem = problem
        self.name = inner.name
        self.rest_term = inner.rest_term
        self.nonneg = inner.nonneg
        self._ps: PartSystem | None = None
        self._seen = None  # the position array of the solve under way (a weak reference)
        self.R_cur = self.R_rhs = None
        self._b = None
        #: (n, 3) added to every vertex's right-hand side, solver numbering: a system whose
        #: matrix adds a mass term adds its share here (implicit Euler's ``b M y``); None
        #: for none
        self.extra_rhs: np.ndarray | None = None

    def bind(self, problem: GroupedProblem, elimination=None,
             parts: PartSystem | None = None) -> GroupedBackend:
        """Use ``problem`` (same energy and groups, possibly other handles).

        ``elimination`` and ``parts`` (another system's on the same vertices, e.g. a
        dynamics step's, whose matrix adds the masses: :mod:`arapkit.arap.dynamics`) replace
        the problem's own, which is then not factorised; with rigid parts, ``parts`` is
        that system (and its elimination the one used).
        """
        if parts is None and elimination is not None and problem.layout is not None:
            raise ValueError("GroupedBackend.bind: rigid parts need the system's parts")
        self.inner.bind(problem, elimination if parts is None else parts.elimination)
        self.problem = problem
        self._ps = parts if elimination is not None or parts is not None \
            else problem.part_system
        self._seen = None
        return self

    def _new_solve(self, P: np.ndarray) -> bool:
        """Whether ``P`` is another array than the current solve's (then remember it)."""
        if self._seen is not None and self._seen() is P:
            return False
        self._seen = weakref.ref(P)
        return True

    def local(self, P: np.ndarray, R: np.ndarray, R_prev: np.ndarray = _NO_ROT) -> float:
        """The inner local step, the shared rotations copied, the parts' rotations fitted."""
        ps = self._ps
        if ps is not None and self._new_solve(P):
            self.R_cur = ps.sync(P)
        E = self.inner.local(P, R, R_prev)
        rep = self.problem.shared_rep
        if rep is not None:
            R[:len(rep)] = R[rep]
        if ps is not None:
            if self._b is None or len(self._b) != len(P):
                self._b = np.empty((len(P), 3))
            self.inner.vertex_rhs(self._b)
            if self.extra_rhs is not None:
                self._b += self.extra_rhs
            E += ps.fit(P, self._b, self.R_cur, R)
            # with an extra term the fit's change is that of the whole objective, and the
            # sum is no energy of its own (the caller adds the term's value from before)
            if self.nonneg and self.extra_rhs is None:
                E = max(E, 0.0)
        return E

    @property
    def part_rows(self) -> int:
        """Rows of three the rigid parts' rotations add to an accelerated iterate (0
        without parts): :func:`~arapkit.arap.loop.local_global` extrapolates them with the
        positions, as the dynamics does (:mod:`arapkit.arap.dynamics`)."""
        return 0 if self._ps is None else 3 * self._ps.layout.n_parts

    def placed_rotations(self) -> np.ndarray | None:
        """(parts, 3, 3) the rotations the parts are placed with at the next scatter (those
        of the last right-hand side); None before the solve's first local step."""
        return self.R_rhs if self._ps is not None else None

    def extrapolated_rotations(self, A: np.ndarray, plain: np.ndarray) -> np.ndarray:
        """The parts' rotations of an extrapolated iterate
        (:meth:`~arapkit.arap.parts.PartSystem.extrapolated`)."""
        return self._ps.extrapolated(A, plain)

    def rhs(self, fixed_rhs: np.ndarray, rhs: np.ndarray) -> None:
        """The reduced right-hand side from the last local step."""
        ps = self._ps
        if ps is None:
            self.inner.rhs(fixed_rhs, rhs)
            return
        self.R_rhs = self.R_cur.copy()
        ps.rhs(self._b, self._seen(), self.R_rhs, rhs)

    def solve(self, rhs: np.ndarray, out: np.ndarray) -> np.ndarray:
        """The global step (the problem's factor: the merged one with rigid parts)."""
        if self._ps is None:
            return self.inner.solve(rhs, out)
        return self._ps.elimination.solve(rhs, out)

    def scatter(self, X: np.ndarray, idx: np.ndarray, P: np.ndarray,
                R: np.ndarray | None = None) -> None:
        """``P[idx] = X``, and every moving part placed about its centre: with its rotation
        of the last right-hand side, or ``R`` (rotations extrapolated with ``X``)."""
        ps = self._ps
        new = ps is not None and self._new_solve(P)
        if R is not None:
            self.R_rhs = np.array(R)
        elif new:
            # a solve from rest: the loop solved before any local step, at the parts' rest
            # (free) and start (held) rotations
            self.R_rhs = ps.sync(P)
        self.inner.scatter(X, idx, P)
        if ps is not None:
            ps.place(P, self.R_rhs)
            self.R_cur = self.R_rhs.copy()

    def gather(self, P: np.ndarray, idx: np.ndarray, scale: float) -> np.ndarray:
        """``P[idx] * scale``."""
        return self.inner.gather(P, idx, scale)

    def vertex_energy(self, P: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Each vertex's term of the energy; a group member's with the group's rotation."""
        p = self.problem
        if p.base_energy is None:
            return self.inner.vertex_energy(P, R)
        return owner_terms(p.base_energy, p.graph, p.w, P, R)
