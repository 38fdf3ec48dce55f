"""Fitting a template mesh to a scan: non-rigid ICP with the r-ring ARAP energy as regulariser.

:class:`Fitter` keeps what one template's fits share (its r-ring neighbourhoods, the ARAP
matrix, the factors of the stages' matrices and of the landmark solve), as potpourri3d's
solver classes do; :func:`fit` is the one-shot call. A fit runs in three steps:

1. **placement**: a similarity of the whole template, from the landmarks (Umeyama;
   rigid unless ``scale=True``) or, without landmarks, by rigid ICP from where the
   template is; a target it does not overlap is refused (one line).
2. **landmarks**: with landmarks, an ARAP solve with them as handles bends the template
   into the target's pose (the engine's :func:`~arapkit.arap.solve.arap_solve`, Anderson
   accelerated).
3. **stages**: non-rigid ICP from stiff to soft (:mod:`arapkit.methods.fit.stages`, where
   the energy and each step's derivation are), landmarks held exactly.

Examples
--------
>>> import numpy as np
>>> from arapkit.mesh.shapes import bar
>>> fitter = Fitter(bar())
>>> res = fitter.fit(bar().vertices + [0.0, 0.05, 0.0])          # the template, moved
>>> bool(res.report.residual["max"] < 1e-3), res.report.target_kind
(True, 'points')
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from ...arap.backends import make_backend
from ...arap.problem import ARAPProblem
from ...arap.solve import arap_solve
from ...errors import InputError
from ...io.landmarks import parse_landmarks
from ...mesh.model import Mesh, as_mesh
from ...mesh.weights import voronoi_areas
from ...validate import iteration_cap, number, tolerance
from .align import Similarity, similarity
from .report import FitReport, StageReport, residual_stats
from .stages import StageLoop, eligible, threshold
from .system import StageSystems
from .target import FitTarget

__all__ = ["DEFAULT_SCHEDULE", "FitResult", "Fitter", "fit"]

#: stiffness lengths of the stages, as fractions of the template's bounding-box diagonal
DEFAULT_SCHEDULE = (0.3, 0.1, 0.03, 0.01, 0.003)
#: iterations per stage at most (20 cost 50 % more time for 1-2 % lower errors, measured)
STAGE_ITER = 10
#: the proximal weight keeping vertices without data definite, relative to the mean
#: diagonal of the ARAP matrix
PROX = 1e-4
#: iterations of the rigid placement without landmarks, and of the landmark ARAP solve
RIGID_ITER = 30
LANDMARK_ITER = 200
#: ``scale=None`` fits the size when the landmarks say the target is this many times larger
#: or smaller than the template (a unit or a generic template: a pose alone moves the
#: landmarks' own best scale by up to 25 %)
AUTO_SCALE = 2.0
#: "no overlap": fewer than this fraction of the template's vertices within 10 % of the
#: larger diagonal from the target after the placement
MIN_OVERLAP = 0.01
#: the overlap test asks every this-many-th vertex first (see ``Fitter._check_overlap``)
OVERLAP_STRIDE = 8


@dataclass
class FitResult:
    """The outcome of :func:`fit` / :meth:`Fitter.fit`.

    Attributes
    ----------
    vertices : (n, 3) fitted positions, in the template's vertex order.
    residuals : (n,) distance of each fitted vertex to the target surface.
    matched : (n,) bool, vertices whose match was used in the last iteration.
    report : FitReport
    similarity : (scale, R, t), the placement ``x -> scale R x + t``.
    template : Mesh, the template fitted.
    """

    vertices: np.ndarray
    residuals: np.ndarray
    matched: np.ndarray
    report: FitReport
    similarity: Similarity
    template: Mesh

    @cached_property
    def mesh(self) -> Mesh:
        """The template with the fitted positions (its faces and file attributes): save it
        with ``arapkit.save_mesh(path, result.vertices, like=template)``."""
        return Mesh(self.vertices, self.template.faces, name=self.template.name,
                    attributes=self.template.attributes)

    @property
    def history(self) -> list[list[float]]:
        """The energy after each iteration, stage by stage."""
        return [s.energy for s in self.report.stages]


def _laplacian(problem: ARAPProblem) -> sp.csr_matrix:
    """The ARAP global matrix, the Laplacian of ``D_e`` (internal numbering)."""
    E, D, n = problem.edges, problem.energy.system_w, problem.n_vertices
    a, b = E[:, 0], E[:, 1]
    deg = np.bincount(a, D, n) + np.bincount(b, D, n)
    return sp.csr_matrix((np.concatenate([-D, -D, deg]),
                          (np.concatenate([a, b, np.arange(n)]),
                           np.concatenate([b, a, np.arange(n)]))), shape=(n, n))


def vertex_normals(P: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (zero for vertices on no face).

    Examples
    --------
    >>> vertex_normals(np.eye(3), np.array([[0, 1, 2]]))[0].round(3).tolist()
    [0.577, 0.577, 0.577]
    """
    c = np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])
    N = np.stack([np.bincount(F.ravel(), np.repeat(c[:, k], 3), len(P)) for k in range(3)], 1)
    length = np.linalg.norm(N, axis=1, keepdims=True)
    return N / np.where(length > 0, length, 1.0)


class Fitter:
    """Fits one template to targets (scans, clouds, meshes), keeping what does not change.

    Parameters
    ----------
    template : Mesh (or anything :func:`arapkit.mesh.model.as_mesh` takes)
    rings : int or (n,) int
        r of the r-ring ARAP energy, per vertex: where the fit may bend (1) and where the
        template keeps its shape over larger patches (larger r): a painted map
        (:func:`arapkit.load_rings`) or a learned one (:func:`arapkit.learn_rings`).
    weights : str, optional
        Edge weights of the ARAP energy (default ``cotan-clamped``).
    schedule : sequence of float
        Stiffness lengths of the stages, stiff to soft, as fractions of the template's
        diagonal: below that length the template keeps its shape, above it it follows the
        scan.
    scale : bool or None
        True fits the template's size too (one global scale, from the landmarks at first,
        then with the pose): for a generic template of another size or unit. False keeps
        its size. None (default) fits it when the landmarks' best similarity scales the
        template by more than :data:`AUTO_SCALE` either way (another unit), and keeps it
        otherwise (and always without landmarks); the report says which.
    stage_iter : int
        Iterations per stage at most; a stage also ends when the energy's relative
        decrease falls below ``tol``.
    tol : float
    accelerate : bool
        Anderson acceleration of the stages (kept only where it lowers the energy).

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.mesh.shapes import bar
    >>> template = bar()
    >>> scan = template.vertices * [1.0, 1.0, 1.1]       # the target: 10 % thicker in z
    >>> res = Fitter(template).fit(scan)
    >>> bool(res.report.residual["p95"] < 0.002)
    True
    """

    def __init__(self, template, rings=1, *, weights: str | None = None,
                 schedule=DEFAULT_SCHEDULE, scale: bool | None = None,
                 stage_iter: int = STAGE_ITER, tol: float = 1e-3,
                 accelerate: bool = True) -> None:
        self.template = as_mesh(template, "template")
        if isinstance(schedule, (str, bytes)) or not np.ndim(schedule) == 1:
            raise InputError("schedule: expected a list of stiffness lengths, e.g. "
                             f"{list(DEFAULT_SCHEDULE)}")
        self.schedule = tuple(number(b, "schedule", lo=0.0, lo_open=True) for b in schedule)
        if not self.schedule:
            raise InputError("schedule: give at least one stiffness length")
        self.scale = None if scale is None else bool(scale)
        self.stage_iter = iteration_cap(stage_iter, "stage_iter")
        self.tol = tolerance(tol)
        self.accelerate = bool(accelerate)
        # the handle is a placeholder: a fit's landmarks come with each target
        p = self.problem = ARAPProblem.from_mesh(self.template, [0], rings=rings,
                                                 weights=weights)
        self.backend = make_backend(p, "cpu")
        self.L = _laplacian(p)
        unit = p.scale
        # the data weight of vertex i is a_i / L^2 times m_i, how many times its r-ring
        # energy counts its edges against the 1-ring energy (1 at r = 1): so the stiffness
        # length means the same at every r, and r sets the shape of what stays rigid
        deg1 = 2.0 * (np.bincount(p.edges[:, 0], p.w, p.n_vertices)
                      + np.bincount(p.edges[:, 1], p.w, p.n_vertices))
        multiplicity = np.where(deg1 > 0, self.L.diagonal() / np.where(deg1 > 0, deg1, 1.0),
                                1.0)
        self.weights = voronoi_areas(self.template)[p.perm] / unit ** 2 * multiplicity
        self.rest_normals = vertex_normals(p.vertices, p.iperm[self.template.faces])
        self.edge = self.template.mean_edge_length / unit
        V = self.template.vertices
        self.diagonal = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0))) / unit
        self.delta = PROX * float(self.L.diagonal().mean())
        self._systems: dict[bytes, StageSystems] = {}
        self._landmark_problems: dict[bytes, ARAPProblem] = {}

    # -- the parts a fit reuses ---------------------------------------------------------
    def _system(self, landmarks: np.ndarray) -> StageSystems:
        key = landmarks.tobytes()
        if key not in self._systems:
            self._systems[key] = StageSystems(self.L, self.problem.iperm[landmarks],
                                              self.template.name, self.delta)
        return self._systems[key]

    def _landmark_problem(self, landmarks: np.ndarray) -> ARAPProblem:
        key = landmarks.tobytes()
        if key not in self._landmark_problems:
            self._landmark_problems[key] = self.problem.with_handles(landmarks)
        return self._landmark_problems[key]

    # -- a fit ----------------------------------------------------------------------------
    def fit(self, target, landmarks=None, *, normals=None) -> FitResult:
        """Fit the template to ``target``.

        Parameters
        ----------
        target : Mesh, (n, 3) array, point cloud or FitTarget
            A mesh (its triangles), or points (read as oriented disks).
        landmarks : optional
            Template vertices and the positions they must reach: a list of
            ``{"vertex": i, "target": [x, y, z]}``, a ``{vertex: xyz}`` mapping or a
            ``(vertices, positions)`` pair. They are met exactly.
        normals : (n, 3), optional
            Normals of a point-cloud target (estimated from the points when absent).

        Returns
        -------
        FitResult
        """
        t_start = time.perf_counter()
        tgt = FitTarget.from_any(target, normals)
        V = self.template.vertices
        lv, lt = parse_landmarks(landmarks, len(V))
        timings = {"matching": 0.0, "local": 0.0, "solve": 0.0, "landmarks": 0.0}
        stages: list[StageReport] = []
        fit_scale = self._fits_scale(lv, lt)
        T = self._place(tgt, lv, lt, stages, timings, fit_scale)
        self._check_overlap(tgt, T)
        p, unit = self.problem, self.problem.scale
        s0, R0, t0 = T
        inner = tgt.moved(s0 * unit, R0, t0)  # the target in the template's frame and units
        L_tf = (lt - t0) @ R0 / s0  # the landmarks' targets in the template's frame
        X, found = V, None
        if len(lv):
            X, found = self._bend(lv, L_tf, T, fit_scale, inner, stages, timings)
        system = self._system(lv)
        f0, fs0 = system.factorisations, system.factor_s
        loop = StageLoop(self.backend, system, inner, np.ascontiguousarray(X[p.perm] / unit),
                         L_tf / unit, self.weights, self.rest_normals,
                         p.energy.rest_term, self.diagonal, self.edge, fit_scale,
                         self.accelerate, self.tol, self.stage_iter, timings)
        if found is not None:
            # the bend's matches were searched at these very positions: the first stage walks
            # from them instead of searching again (the same matches)
            loop.prev = found[p.perm]
        stages += loop.run(self.schedule)
        timings["factorisation"] = system.factor_s - fs0
        out = s0 * (loop.P[p.iperm] * unit) @ R0.T + t0
        if len(lv):
            out[lv] = lt  # exact, also after the round trip through the similarity
        t1 = time.perf_counter()
        residuals = np.sqrt(tgt.match(out).d2)
        timings["matching"] += time.perf_counter() - t1
        diag = tgt.diagonal
        matched = np.zeros(len(V), dtype=bool)
        matched[p.perm] = loop.accepted
        report = FitReport(
            self.template.name, tgt.name, len(V), tgt.n_points, tgt.kind, diag,
            residual_stats(residuals, diag), float(matched.mean()), len(lv),
            float(np.linalg.norm(out[lv] - lt, axis=1).max() / diag) if len(lv) else 0.0,
            float(s0 * loop.sigma), sum(s.iterations for s in stages),
            time.perf_counter() - t_start, stages, timings,
            factorisations=system.factorisations - f0, scale_fitted=fit_scale)
        return FitResult(out, residuals, matched, report, T, self.template)

    def _bend(self, lv, L_tf, T: Similarity, fit_scale: bool, inner: FitTarget, stages,
              timings) -> tuple[np.ndarray, np.ndarray]:
        """The template bent onto its landmarks by ARAP (template frame), and the target
        elements its vertices are closest to.

        ARAP with a few point handles has several minima, and the one the local/global
        iteration finds depends on its start. Two starts are tried: the template placed by
        the landmarks' best similarity, and (its size kept) the template where it is; the
        bent template nearer the target wins (mean squared distance, truncated at 5 % of
        the diagonal). The landmarks' best rigid motion can be far from the template's own
        orientation when the pose changed (three landmarks on a bent finger tilt it by
        half the bend), and the template's own placement is what a user usually gives.
        """
        t1 = time.perf_counter()
        problem = self._landmark_problem(lv)
        V = self.template.vertices
        starts = [V]
        if not fit_scale:
            s0, R0, t0 = T
            here = (V - t0) @ R0 / s0  # where the template is, in its own frame
            # the same start twice when the landmarks hardly move the template
            if np.sqrt(((here - V) ** 2).sum(axis=1).mean()) > 0.01 * self.diagonal * \
                    self.problem.scale:
                starts.append(here)
        best, best_d, found = None, np.inf, None
        cap = (0.05 * self.diagonal * self.problem.scale) ** 2
        for start in starts:
            # the Fitter's backend (the same energy): not another one built per solve
            res = arap_solve(problem, L_tf, init=start, backend=self.backend, accelerate=True,
                             max_iter=LANDMARK_ITER)
            m = inner.match(res.vertices / self.problem.scale)
            d = float(np.minimum(m.d2 * self.problem.scale ** 2, cap).mean())
            if d < best_d:
                best, best_d, found = res, d, m.element
        timings["landmarks"] = time.perf_counter() - t1
        stages.append(StageReport("landmarks", None, best.iterations, list(best.history),
                                  time_s=timings["landmarks"]))
        return best.vertices, found

    def _fits_scale(self, lv: np.ndarray, lt: np.ndarray) -> bool:
        """Whether this fit fits the template's size (see ``scale``)."""
        if self.scale is not None:
            return self.scale
        if len(lv) < 3:
            return False
        s = similarity(self.template.vertices[lv], lt, scale=True)[0]
        return not 1.0 / AUTO_SCALE <= s <= AUTO_SCALE

    def _place(self, tgt: FitTarget, lv, lt, stages, timings, fit_scale: bool) -> Similarity:
        """The initial similarity: from landmarks, or rigid ICP from the given placement.

        Rigid ICP minimises the area-weighted truncated squared distance over the
        similarity, with eligibility and threshold fixed after the first match: closest
        points then Umeyama, each lowering it.
        """
        V = self.template.vertices
        if len(lv):
            return similarity(V[lv], lt, scale=fit_scale)
        t0 = time.perf_counter()
        s, R, t = 1.0, np.eye(3), np.zeros(3)
        self._check_overlap(tgt, (s, R, t))
        areas = self.weights[self.problem.iperm]
        normals = vertex_normals(V, self.template.faces)
        prev = None
        rep = StageReport("rigid", None, 0)
        near = 0.5 * self.template.mean_edge_length
        acc = np.zeros(len(V), dtype=bool)
        memo = tgt.memo(len(V))
        for it in range(RIGID_ITER):
            m = tgt.match(s * V @ R.T + t, prev, search=prev is None, memo=memo)
            prev = m.element
            if it == 0:
                elig = eligible(m, normals @ R.T, tgt.oriented, near)
                tau = threshold(m, elig, tgt.diagonal)
            acc = elig & (m.d2 <= tau * tau)
            E = float((areas * np.where(elig, np.minimum(m.d2, tau * tau), 0.0)).sum())
            rep.energy.append(E)
            if len(rep.energy) > 1 and rep.energy[-2] - E <= self.tol * rep.energy[-2]:
                break
            if acc.sum() < 3:
                break
            rep.iterations += 1
            s, R, t = similarity(V[acc], m.point[acc], areas[acc], scale=fit_scale)
        rep.accepted = float(acc.mean())
        rep.threshold = tau / tgt.diagonal
        rep.time_s = time.perf_counter() - t0
        timings["matching"] += rep.time_s
        stages.append(rep)
        return s, R, t

    def _check_overlap(self, tgt: FitTarget, T: Similarity) -> None:
        """Refuse a target that the placed template does not overlap."""
        s, R, t = T
        V = self.template.vertices
        X = s * V @ R.T + t
        reach = 0.1 * max(tgt.diagonal, s * self.diagonal * self.problem.scale)
        need = max(3, MIN_OVERLAP * len(V))
        # the nearest element centre: at least as far as the element, so never an overlap
        # the surface does not have (and one k-d query, not a search and walk). Every
        # OVERLAP_STRIDE-th vertex first: on a target that overlaps, these alone usually
        # reach ``need``, and the rest is not asked (the same decision as counting all; a
        # k-d query of a far vertex is the slow kind)
        near = 0
        for part in range(OVERLAP_STRIDE):
            near += int(np.count_nonzero(tgt.nearest(X[part::OVERLAP_STRIDE], 1, reach)[0]
                                         <= reach))
            if near >= need:
                return
        if tgt.kind == "mesh":
            # large triangles have far centres: ask the triangles themselves
            near = int(np.count_nonzero(tgt.match(X).d2 <= reach * reach))
        if near < need:
            raise InputError(
                f"{tgt.name}: no overlap with the template {self.template.name} (only {near} "
                f"of {len(V)} vertices within 10 % of the diagonal after the initial "
                "placement); give landmarks or place the template over the target")


def fit(template, target, landmarks=None, rings=1, *, normals=None, weights: str | None = None,
        schedule=DEFAULT_SCHEDULE, scale: bool | None = None, stage_iter: int = STAGE_ITER,
        tol: float = 1e-3, accelerate: bool = True) -> FitResult:
    """Fit ``template`` to ``target`` (a one-shot :class:`Fitter`; see it and
    :meth:`Fitter.fit` for the parameters).

    Examples
    --------
    >>> import numpy as np
    >>> import arapkit
    >>> from arapkit.mesh.shapes import bar
    >>> template = bar()
    >>> scan = template.vertices + [0.0, 0.0, 0.05]               # the template, moved
    >>> res = arapkit.fit(template, scan, landmarks={0: scan[0]})
    >>> bool(np.abs(res.vertices - scan).max() < 1e-6)
    True
    """
    return Fitter(template, rings, weights=weights, schedule=schedule, scale=scale,
                  stage_iter=stage_iter, tol=tol,
                  accelerate=accelerate).fit(target, landmarks, normals=normals)
