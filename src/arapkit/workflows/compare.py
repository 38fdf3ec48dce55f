"""Run several deformation methods on the same handles and compare them (paper Figs. 9-12).

:func:`run_comparison` runs ARAP (r = 1), SR-ARAP, embedded deformation, r-ring ARAP at a
chosen r and, when a rigidity map is given, r-ring ARAP with that map; each row of
:func:`comparison_rows` has iterations, wall time (set-up and solve), the energy of the
method's own objective (not comparable across methods), the fraction of folded edges
(dihedral change > 60 degrees, :mod:`arapkit.mesh.quality`), the volume change (closed meshes)
and the largest handle error. :func:`comparison_figure` draws all results side by side with
one camera and the handles marked.

Self-intersecting faces are not counted: no dependency of arapkit counts them.
"""

from __future__ import annotations

import time
from contextlib import nullcontext
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..mesh.cloud import PointCloud
from ..mesh.model import Mesh
from ..mesh.orientation import view_frame
from ..mesh.quality import folded_edge_fraction, volume_change
from ..plots.colors import ENERGY_CMAP

__all__ = ["MethodRun", "comparison_figure", "comparison_rows", "format_rows",
           "method_list", "run_comparison", "write_csv"]

#: compare's labels of the methods it runs at r = 1 (others are labelled by their name)
LABELS = {"rring": "ARAP", "sr-arap": "SR-ARAP", "smooth-arap": "Smooth ARAP"}
#: the method compare also runs at the chosen r and with the rigidity map (the paper's
#: comparison); every other method with a rigidity map runs at r = 1 only
RINGS_METHOD = "rring"

CSV_COLUMNS = ("method", "energy_kind", "iterations", "converged", "time_s", "own_energy",
               "folded_edge_fraction", "volume_change", "max_handle_error")


@dataclass
class MethodRun:
    """One method's result in a comparison."""

    label: str
    energy: str
    options: dict[str, Any]
    result: Any
    seconds: float
    folded: float = 0.0
    volume_change: float = float("nan")
    handle_error: float = 0.0
    notes: list[str] = field(default_factory=list)


def method_list(rings: int = 3, rings_map: np.ndarray | None = None,
                volumetric: bool = False,
                has_faces: bool = True) -> list[tuple[str, dict[str, Any]]]:
    """The methods of a comparison as (label, Deformer keyword arguments).

    ``volumetric`` adds volumetric ARAP (the course report's inner edges) at r = 1, and
    with the rigidity map when one is given. ``has_faces=False`` (a point cloud) leaves
    out the methods defined on triangles (the registry's ``needs_faces``).

    Examples
    --------
    >>> [label for label, _ in method_list(4)]
    ['ARAP', 'SR-ARAP', 'Smooth ARAP', 'embedded', 'r-ring r=4']
    >>> [label for label, _ in method_list(4, volumetric=True)][-1]
    'volumetric ARAP'
    >>> [label for label, _ in method_list(4, has_faces=False)]
    ['ARAP', 'embedded', 'r-ring r=4']
    """
    from ..methods.registry import methods as registered

    # every method registered for compare that applies, at r = 1 where it has a rigidity map
    methods: list[tuple[str, dict[str, Any]]] = [
        (LABELS.get(m.name, m.name),
         {"energy": m.name, **({"rings": 1} if m.rigidity_map else {})})
        for m in registered("compare") if m.applies_to(has_faces)
    ]
    if rings != 1:
        methods.append((f"r-ring r={rings}", {"energy": RINGS_METHOD, "rings": rings}))
    if rings_map is not None:
        methods.append(("r-ring mixed r", {"energy": RINGS_METHOD, "rings": rings_map}))
    if volumetric:
        from ..methods.volumetric import VOLUME_SOLVE_DEFAULTS

        # volumetric ARAP at its own (converged) tolerance, with acceleration
        methods.append(("volumetric ARAP", {"energy": "rring", "volumetric": True,
                                            "rings": 1 if rings_map is None else rings_map,
                                            **VOLUME_SOLVE_DEFAULTS}))
    return methods


def run_comparison(mesh: Mesh | PointCloud, handles, targets, *, rings: int = 3,
                   rings_map: np.ndarray | None = None, weights: str | None = None,
                   tol: float = 1e-3, max_iter: int = 1000, sr_alpha: float | None = None,
                   nodes: int | None = None, volumetric: bool = False,
                   progress=None) -> list[MethodRun]:
    """Run every method of :func:`method_list` with the same handles and targets.

    ``progress(label)``, if given, returns a context manager that yields a solve callback
    (e.g. :class:`arapkit.cli.common.Progress`).

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar, bar_bend
    >>> m = bar(length=2.0, segments=(8, 2, 2))
    >>> h, t = bar_bend(m, 60)
    >>> runs = run_comparison(m, h, t, rings=2, nodes=20)
    >>> [r.label for r in runs], all(r.folded == 0 for r in runs)
    (['ARAP', 'SR-ARAP', 'Smooth ARAP', 'embedded', 'r-ring r=2'], True)
    """
    from ..methods.deformer import Deformer, check_domain
    from ..methods.registry import method

    targets = np.asarray(targets, dtype=np.float64)
    runs = []
    if volumetric:
        check_domain(mesh, volumetric=True)
    for label, kw in method_list(rings, rings_map, volumetric, mesh.faces is not None):
        kw = dict(kw)
        info = method(kw["energy"])
        given = {"sr_alpha": sr_alpha, "nodes": nodes}
        kw.update({k: v for k, v in given.items() if k in info.options and v is not None})
        if not info.local_global:
            kw["tol"] = min(tol, 1e-6)  # its own solver's steps (Gauss-Newton): cheap to tighten
        # only the local/global energies take edge weights; the volume's edges have their own
        weights_kw = {"weights": weights} if info.local_global and not kw.get("volumetric") \
            else {}
        t0 = time.perf_counter()
        d = Deformer(mesh, handles, max_iter=max_iter, **({"tol": tol} | kw), **weights_kw)
        with progress(label) if progress is not None else nullcontext() as cb:
            res = d.solve(targets, callback=cb)
        seconds = time.perf_counter() - t0
        run = MethodRun(label, kw["energy"],
                        {k: v for k, v in kw.items() if k not in ("energy", "tol", "volumetric")},
                        res, seconds, notes=list(d.notes))
        if mesh.faces is not None:  # folds and volume are a surface's
            run.folded = folded_edge_fraction(mesh, res.vertices)
            run.volume_change = volume_change(mesh, res.vertices)
        else:
            run.folded = float("nan")
        run.handle_error = float(np.linalg.norm(res.vertices[d.handles] - targets,
                                                axis=1).max())
        runs.append(run)
    return runs


def comparison_rows(runs: list[MethodRun]) -> list[dict[str, Any]]:
    """One row per method with the :data:`CSV_COLUMNS`."""
    return [{
        "method": r.label,
        "energy_kind": r.energy,
        "iterations": int(r.result.iterations),
        "converged": bool(r.result.converged),
        "time_s": float(r.seconds),
        "own_energy": float(r.result.energy),
        "folded_edge_fraction": float(r.folded),
        "volume_change": float(r.volume_change),
        "max_handle_error": float(r.handle_error),
    } for r in runs]


def write_csv(path, rows: list[dict[str, Any]]) -> None:
    """Write :func:`comparison_rows` to ``path`` atomically (one header line)."""
    import csv
    import io

    from ..io import atomic_write

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(CSV_COLUMNS), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    atomic_write(path, buf.getvalue())


def format_rows(rows: list[dict[str, Any]]) -> str:
    """Fixed-width table of :func:`comparison_rows` (volume change and folds in %).

    Examples
    --------
    >>> print(format_rows([{"method": "ARAP", "energy_kind": "rring", "iterations": 3,
    ...     "converged": True, "time_s": 0.5, "own_energy": 1.0, "folded_edge_fraction": 0.0,
    ...     "volume_change": -0.01, "max_handle_error": 0.0}]).splitlines()[1].split())
    ['ARAP', '3', 'yes', '0.50', '1', '0.000', '-1.00', '0']
    """
    head = ["method", "iterations", "converged", "time s", "own energy", "folded %",
            "volume %", "handle err"]
    cells = [[r["method"], str(r["iterations"]), "yes" if r["converged"] else "no",
              f"{r['time_s']:.2f}", f"{r['own_energy']:.4g}",
              "n/a" if np.isnan(r["folded_edge_fraction"])
              else f"{100 * r['folded_edge_fraction']:.3f}",
              "n/a" if np.isnan(r["volume_change"]) else f"{100 * r['volume_change']:.2f}",
              f"{r['max_handle_error']:.2g}"] for r in rows]
    widths = [max(len(h), *(len(c[i]) for c in cells)) if cells else len(h)
              for i, h in enumerate(head)]
    lines = ["  ".join(h.ljust(w) if i == 0 else h.rjust(w)
                       for i, (h, w) in enumerate(zip(head, widths)))]
    lines += ["  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                        for i, (c, w) in enumerate(zip(cell, widths))) for cell in cells]
    return "\n".join(lines)


def comparison_figure(mesh: Mesh, runs: list[MethodRun], handles, targets=None,
                      fixed_mask=None, title: str | None = None, ncols: int | None = None,
                      view: str = "front", up: str | None = None):
    """The rest shape and every method's result, one camera, handles marked (Figs. 9-12).

    The camera is upright and set from the rest shape (``view``, ``up``: see
    :func:`arapkit.mesh.orientation.view_frame`).

    Each deformed panel is coloured by the largest dihedral-angle change at each vertex
    (degrees, 0-60, pale to dark red like energy everywhere), so that folds and creases
    stand out; handles are dots (dark: fixed,
    red: moved), their faces painted on the rest panel.
    """
    from matplotlib.colors import BoundaryNorm, ListedColormap, Normalize

    from ..mesh.quality import dihedral_angles
    from ..plots import render as plots

    h = np.asarray(handles, dtype=np.int64)
    fixed = np.zeros(len(h), bool) if fixed_mask is None else np.asarray(fixed_mask, bool)
    V, F = mesh.vertices, mesh.faces
    shapes = [V] + [r.result.vertices for r in runs]
    basis = view_frame(V, view, up)[0]
    n = len(shapes)
    ncols = ncols or min(n, 3)
    nrows = (n + ncols - 1) // ncols
    fig = plots.new_figure(figsize=(3.6 * ncols, 3.4 * nrows + 0.6), dpi=110,
                           layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols)).ravel()
    labels = np.zeros(len(V))
    labels[h[fixed]] = 1.0
    labels[h[~fixed]] = 2.0
    hcmap = ListedColormap([plots.REST_COLOR, plots.FIXED_COLOR, plots.MOVED_COLOR])
    hnorm = BoundaryNorm([-0.5, 0.5, 1.5, 2.5], 3)
    plots.render_mesh(axes[0], V, F, labels, basis=basis, cmap=hcmap, norm=hnorm, reduce="max")
    axes[0].set_title("rest shape and handles", fontsize=9)
    surface = F is not None
    if surface:
        e, a0 = dihedral_angles(mesh, V)
        dnorm = Normalize(0.0, 60.0)
        what = "dihedral-angle change (degrees, clipped at 60)"
    else:  # a point cloud: how much its graph's edges stretched or shrank
        E = mesh.edges
        l0 = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
        dnorm = Normalize(0.0, 20.0)
        what = "edge-length change at each point (%, clipped at 20)"
    for ax, run in zip(axes[1:], runs):
        P = run.result.vertices
        per_vertex = np.zeros(len(V))
        if surface:
            _, a1 = dihedral_angles(mesh, P)
            change = np.degrees(np.abs(np.angle(np.exp(1j * (a1 - a0)))))
            E = mesh.edges[e]
        else:
            l1 = np.linalg.norm(P[E[:, 0]] - P[E[:, 1]], axis=1)
            change = 100 * np.abs(l1 / np.where(l0 > 0, l0, 1.0) - 1.0) * (l0 > 0)
        np.maximum.at(per_vertex, E[:, 0], change)
        np.maximum.at(per_vertex, E[:, 1], change)
        plots.render_mesh(ax, P, F, per_vertex, basis=basis, cmap=ENERGY_CMAP, norm=dnorm)
        # handles as dots (subsampled for large sets) on every panel
        plots.mark(ax, P[h[fixed]], basis, plots.FIXED_COLOR, "fixed")
        plots.mark(ax, P[h[~fixed]], basis, plots.MOVED_COLOR, "moved")
        vol = "" if np.isnan(run.volume_change) else f", vol {100 * run.volume_change:+.1f}%"
        fold = "" if np.isnan(run.folded) else f"folded {100 * run.folded:.2f}%"
        ax.set_title(f"{run.label}: {run.result.iterations} it., {run.seconds:.2f} s\n"
                     f"{fold}{vol}", fontsize=8)
    # one camera: the same view basis and the same frame in every panel
    xy = np.concatenate(shapes) @ basis[:2].T
    for ax in axes[:n]:
        plots.frame(ax, xy)
    for ax in axes[n:]:
        ax.set_axis_off()
    plots.colorbar(fig, list(axes[1:n]), dnorm, ENERGY_CMAP, what)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig
