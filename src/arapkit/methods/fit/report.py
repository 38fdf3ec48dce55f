"""What a template fit reports: residual distances, matches, iterations and time.

Residuals are the distances from each fitted template vertex to the target surface (the
triangles of a mesh target; the oriented disks of a cloud, see
:mod:`arapkit.methods.fit.target`), given as fractions of the diagonal of the target's
bounding box, so that "1 %" means the same on a face scan in millimetres and a body in metres.

Examples
--------
>>> import numpy as np
>>> r = residual_stats(np.array([0.0, 0.01, 0.02, 0.5]), 1.0)
>>> r["mean"], r["within_1pct"]
(0.1325, 0.5)
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

__all__ = ["FitReport", "StageReport", "residual_stats"]


def residual_stats(residuals: np.ndarray, diagonal: float) -> dict[str, float]:
    """Mean, 95th percentile and max of ``residuals / diagonal``, and the fraction of them
    within 1 % (inclusive)."""
    r = np.asarray(residuals, dtype=np.float64) / diagonal
    if not len(r):
        return {"mean": 0.0, "p95": 0.0, "max": 0.0, "within_1pct": 1.0}
    return {"mean": float(r.mean()), "p95": float(np.percentile(r, 95)),
            "max": float(r.max()), "within_1pct": float((r <= 0.01).mean())}


@dataclass
class StageReport:
    """One stage of the schedule.

    Attributes
    ----------
    name : str, ``"rigid"``, ``"landmarks"`` or ``"stiffness 0.03"``.
    stiffness : float or None, the stage's stiffness length (fraction of the template's
        diagonal); None for the rigid and landmark stages.
    iterations : int
    energy : list of float, the energy after each iteration (it never rises within a stage).
    accepted : float, the fraction of vertices whose match was used at the stage's end.
    threshold : float or None, the distance beyond which a match is rejected (fraction of
        the template's diagonal).
    factorisations : int, Cholesky factorisations made in the stage (0 when a factor of
        an earlier fit of the same template was reused).
    time_s : float
    """

    name: str
    stiffness: float | None
    iterations: int
    energy: list[float] = field(default_factory=list)
    accepted: float = 0.0
    threshold: float | None = None
    factorisations: int = 0
    time_s: float = 0.0


@dataclass
class FitReport:
    """The report of one fit (:attr:`arapkit.methods.fit.FitResult.report`).

    Attributes
    ----------
    template, target : str, names.
    n_vertices, n_target : int, template vertices, target points (or vertices).
    target_kind : ``"mesh"`` or ``"points"``.
    diagonal : float, the target's bounding-box diagonal (the unit of the residuals).
    residual : dict, mean / p95 / max residual as fractions of ``diagonal`` and
        ``within_1pct``, the fraction of vertices within 1 % of it.
    matched : float, the fraction of vertices whose match was used at the end (the rest
        were rejected: beyond the threshold, on the scan's border, or facing away).
    landmarks : int, number of landmarks; ``landmark_error`` the largest distance of a
        landmark vertex from its target (fraction of ``diagonal``).
    scale : float, the template's scale in the fit (1: its own size); ``scale_fitted``
        whether it was fitted.
    iterations : int, over all stages; ``time_s`` the whole fit's wall time.
    stages : list of StageReport.
    timings : dict of seconds by part (matching, local, solve, factorisation, landmarks).
    factorisations : int, Cholesky factorisations this fit made (0 when a :class:`Fitter`
        reuses the factors of an earlier fit).
    """

    template: str
    target: str
    n_vertices: int
    n_target: int
    target_kind: str
    diagonal: float
    residual: dict[str, float]
    matched: float
    landmarks: int
    landmark_error: float
    scale: float
    iterations: int
    time_s: float
    stages: list[StageReport] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    factorisations: int = 0
    scale_fitted: bool = False

    def to_dict(self) -> dict:
        """A JSON-ready dict (what ``arapkit fit --report`` writes)."""
        return asdict(self)

    def summary(self) -> list[str]:
        """A few lines for a terminal.

        Examples
        --------
        >>> rep = FitReport("t", "s", 10, 20, "points", 1.0,
        ...                 residual_stats(np.zeros(10), 1.0), 1.0, 0, 0.0, 1.0, 12, 0.5)
        >>> rep.summary()[0]
        'fitted t (10 vertices) to s (20 points) in 12 iterations, 0.50 s'
        """
        r = self.residual
        unit = "points" if self.target_kind == "points" else "vertices"
        lines = [f"fitted {self.template} ({self.n_vertices} vertices) to {self.target} "
                 f"({self.n_target} {unit}) in {self.iterations} iterations, "
                 f"{self.time_s:.2f} s",
                 f"residual (of the target's diagonal {self.diagonal:.4g}): mean "
                 f"{100 * r['mean']:.3f} %, p95 {100 * r['p95']:.3f} %, max "
                 f"{100 * r['max']:.3f} %; {100 * r['within_1pct']:.1f} % of vertices within "
                 f"1 %",
                 f"matched {100 * self.matched:.1f} % of vertices; scale {self.scale:.4g} "
                 f"({'fitted' if self.scale_fitted else 'kept'})"]
        if self.landmarks:
            lines[-1] += (f"; {self.landmarks} landmarks, largest error "
                          f"{100 * self.landmark_error:.2g} %")
        return lines
