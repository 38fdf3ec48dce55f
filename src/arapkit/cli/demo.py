"""``arapkit demo``: the paper's bar experiments on the built-in bar (no data files needed).

* Fig. 3 / Table 1: the bar bent by 180 degrees with r = 1, 2, 4, 6, 10, with timings.
* Fig. 4 / Fig. 5: energy per iteration and iterations against r.
* Fig. 8: a two-material bar, soft middle third r = 2, the rest r = 6.
* Figs. 9-12 style: ARAP, SR-ARAP, embedded deformation, r = 4 and the two-material map
  side by side on the same bend (``compare.png``, ``compare.csv``).

Examples
--------
::

    arapkit demo --out demo-output
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from arapkit.cli.common import (
    Progress,
    add_example_epilog,
    add_view_options,
    note,
    positive_int,
)
from arapkit.errors import InputError, require_extra

__all__ = ["PAPER_RINGS", "add_parser", "format_table", "run"]

#: The ring sizes of the paper's Table 1.
PAPER_RINGS = (1, 2, 4, 6, 10)
#: the paper's own weights: the bar experiments reproduce its setting, not the default
PAPER_WEIGHTS = "cotan"
_COLUMNS = (
    ("r", "{}"),
    ("neighbourhood ms", "{:.2f}"),
    ("factorisation ms", "{:.2f}"),
    ("global ms/iter", "{:.2f}"),
    ("local ms/iter", "{:.2f}"),
    ("iterations", "{:d}"),
    ("total s", "{:.2f}"),
)


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``demo``."""
    p = subparsers.add_parser(
        "demo",
        help="reproduce the paper's bar experiments (Fig. 3, 4, 5, 8 and Table 1)",
        description="Bend the built-in bar (1,154 vertices) by 180 degrees with r = 1, 2, 4, "
        "6, 10 and bend a two-material bar (soft middle r = 2, rest r = 6). Prints a "
        "Table-1-style timing table on stdout and writes meshes (.ply with energy and rings), "
        "figures (.png) and demo-report.json into DIR.",
        **add_example_epilog(["arapkit demo", "arapkit demo --out /tmp/arap-demo --quiet"]),
    )
    p.add_argument(
        "--out",
        default="demo-output",
        metavar="DIR",
        help="output folder, created if missing (default demo-output)",
    )
    p.add_argument(
        "--rings",
        type=positive_int,
        nargs="+",
        default=list(PAPER_RINGS),
        metavar="R",
        help="ring sizes to run (default 1 2 4 6 10)",
    )
    p.add_argument(
        "--degrees", type=float, default=180.0, help="bending angle in degrees (default 180)"
    )
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bars or notes")
    add_view_options(p)
    return p


def format_table(rows: list[dict[str, Any]]) -> str:
    """Fixed-width text table of timing rows (keys as in ``Result.timings`` plus ``r``).

    Examples
    --------
    >>> table = format_table([{"r": 1, "neighbourhood_ms": 1.0, "factorisation_ms": 2.0,
    ...     "global_ms_per_iter": 3.0, "local_ms_per_iter": 4.0, "iterations": 5,
    ...     "total_s": 0.5}])
    >>> table.splitlines()[1].split()
    ['1', '1.00', '2.00', '3.00', '4.00', '5', '0.50']
    """
    keys = (
        "r",
        "neighbourhood_ms",
        "factorisation_ms",
        "global_ms_per_iter",
        "local_ms_per_iter",
        "iterations",
        "total_s",
    )
    cells = [
        [fmt.format(row[k]) for k, (_, fmt) in zip(keys, _COLUMNS, strict=True)] for row in rows
    ]
    headers = [h for h, _ in _COLUMNS]
    widths = [max(len(h), *(len(c[i]) for c in cells)) for i, h in enumerate(headers)]
    if not rows:
        widths = [len(h) for h in headers]
    lines = ["  ".join(h.rjust(w) for h, w in zip(headers, widths, strict=True))]
    lines += ["  ".join(c.rjust(w) for c, w in zip(cell, widths, strict=True)) for cell in cells]
    return "\n".join(lines)


def _prepare_out(path: str) -> Path:
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")
    if not out.parent.is_dir() and str(out.parent):
        raise InputError(f"{out}: parent folder {str(out.parent)!r} does not exist")
    try:
        out.mkdir(exist_ok=True)
    except OSError as e:
        raise InputError(f"{out}: cannot create the output folder ({e.strerror or e})") from None
    from arapkit.io import check_output_path

    # before any solve: the folder must really take files (read-only or immutable ones don't)
    check_output_path(out / "demo-report.json", what="demo output")
    return out


def _warm_up() -> None:
    """Run a tiny solve so that JIT compilation is not charged to the r = 1 row."""
    from arapkit import Deformer
    from arapkit.mesh.shapes import bar, bar_bend

    small = bar(length=2.0, segments=(6, 2, 2))
    h, t = bar_bend(small, 30)
    Deformer(small, h, rings=2, weights=PAPER_WEIGHTS).solve(t, max_iter=2)


def _solve(mesh, handles, targets, rings, quiet: bool, label: str):
    from arapkit import Deformer

    deformer = Deformer(mesh, handles, rings=rings, weights=PAPER_WEIGHTS)
    with Progress(disable=quiet, desc=label) as progress:
        res = deformer.solve(targets, callback=progress)
    if not res.converged:
        note(f"{label}: stopped after {res.iterations} iterations without converging", quiet)
    return res


def _row(label: Any, res) -> dict[str, Any]:
    t = res.timings
    return {
        "r": label,
        "neighbourhood_ms": float(t.get("neighbourhood_ms", float("nan"))),
        "factorisation_ms": float(t.get("factorisation_ms", float("nan"))),
        "global_ms_per_iter": float(t.get("global_ms_per_iter", float("nan"))),
        "local_ms_per_iter": float(t.get("local_ms_per_iter", float("nan"))),
        "iterations": int(res.iterations),
        "total_s": float(t.get("total_s", float("nan"))),
        "converged": bool(res.converged),
        "energy": float(res.energy),
    }


def run(args: argparse.Namespace) -> int:
    """Execute ``arapkit demo``; returns the exit status."""
    require_extra("matplotlib", "plots", "arapkit demo")  # before any solving: it draws figures
    from arapkit.io import save_mesh, write_json
    from arapkit.mesh.shapes import bar, bar_bend, bar_two_materials
    from arapkit.plots import figures as plots

    t_start = time.perf_counter()
    out = _prepare_out(args.out)
    rings_list = sorted(set(args.rings))
    mesh = bar()
    handles, targets = bar_bend(mesh, args.degrees)
    _warm_up()

    rows, results = [], {}
    for r in rings_list:
        res = _solve(mesh, handles, targets, r, args.quiet, f"r = {r}")
        results[r] = res
        rows.append(_row(r, res))
        save_mesh(
            out / f"bar_r{r}.ply",
            res.vertices,
            mesh.faces,
            {"energy": res.vertex_energy, "rings": np.full(mesh.n_vertices, r, np.int32)},
        )

    soft_hard = bar_two_materials(mesh, soft=2, hard=6)
    mixed = _solve(mesh, handles, targets, soft_hard, args.quiet, "r = 2/6")
    rows.append(_row("2/6", mixed))
    save_mesh(out / "bar_rest.ply", mesh.vertices, mesh.faces, {"rings": soft_hard})
    save_mesh(
        out / "bar_two_materials.ply",
        mixed.vertices,
        mesh.faces,
        {"energy": mixed.vertex_energy, "rings": soft_hard},
    )

    camera = {"view": args.view, "up": args.up}
    figures = _figures(out, mesh, handles, targets, rings_list, results, soft_hard, mixed, plots,
                       camera)
    comparison = _comparison(out, mesh, handles, targets, soft_hard, plots, camera)
    figures.append("compare.png")
    report = {
        "mesh": {"name": "bar", "vertices": mesh.n_vertices, "faces": mesh.n_faces},
        "degrees": args.degrees,
        "handles": len(handles),
        "tol": 1e-3,
        "table": rows,
        "energy_history": {str(r): results[r].history for r in rings_list},
        "two_materials": {
            "soft_r": 2,
            "hard_r": 6,
            "soft_vertices": int((soft_hard == 2).sum()),
            "energy_history": mixed.history,
        },
        "comparison": comparison,
        "figures": figures,
        "wall_s": time.perf_counter() - t_start,
    }
    write_json(out / "demo-report.json", report)

    print(
        f"Bar bent {args.degrees:g} degrees, {mesh.n_vertices} vertices, "
        f"{len(handles)} handles, tol 1e-3 (times after a JIT warm-up)"
    )
    print(format_table(rows))
    from arapkit.workflows.compare import format_rows

    print("\nMethods on the same bend (own energies are not comparable across methods):")
    print(format_rows(comparison))
    print(
        f"wrote {len(figures)} figures, {len(rings_list) + 2} meshes, compare.csv and "
        f"demo-report.json to {out}"
    )
    return 0


def _comparison(out: Path, mesh, handles, targets, soft_hard, plots,
                camera: dict[str, Any]) -> list[dict[str, Any]]:
    """ARAP, SR-ARAP, embedded deformation, r = 4 and the two-material map on one bend."""
    from arapkit.workflows.compare import (
        comparison_figure,
        comparison_rows,
        run_comparison,
        write_csv,
    )

    runs = run_comparison(mesh, handles, targets, rings=4, rings_map=soft_hard,
                          weights=PAPER_WEIGHTS)
    rows = comparison_rows(runs)
    write_csv(out / "compare.csv", rows)
    fixed = np.all(targets == mesh.vertices[handles], axis=1)
    fig = comparison_figure(mesh, runs, handles, targets, fixed,
                            title="bar bent 180 degrees: methods side by side", **camera)
    plots.save_figure(fig, out / "compare.png")
    return rows


def _figures(out, mesh, handles, targets, rings_list, results, soft_hard, mixed, plots,
             camera) -> list:
    """Write the paper-style figures; returns their file names."""
    F = mesh.faces
    names = []

    panels = [("rest", mesh.vertices, None)]
    panels += [
        (f"r = {r} ({results[r].iterations} it.)", results[r].vertices, results[r].vertex_energy)
        for r in rings_list
    ]
    fig = plots.series_figure(F, panels, colorbar_label="per-vertex energy",
                              ncols=min(len(panels), 3), **camera)
    plots.save_figure(fig, out / "fig3_bar_bend.png")
    names.append("fig3_bar_bend.png")

    fig = plots.energy_curves_figure({f"r = {r}": results[r].history for r in rings_list})
    plots.save_figure(fig, out / "fig4_energy_curves.png")
    names.append("fig4_energy_curves.png")

    fig = plots.iterations_figure(rings_list, [results[r].iterations for r in rings_list])
    plots.save_figure(fig, out / "fig5_iterations.png")
    names.append("fig5_iterations.png")

    cmap, norm, _ = plots.rings_colormap(soft_hard, levels=(2, 6))
    panels = [("rest: soft middle r = 2, rest r = 6", mesh.vertices, soft_hard)]
    for r in (2, 6):
        if r in results:
            panels.append((f"uniform r = {r}", results[r].vertices, np.full(len(soft_hard), r)))
    panels.insert(2 if len(panels) > 1 else 1, ("mixed r = 2 / 6", mixed.vertices, soft_hard))
    fig = plots.series_figure(
        F, panels, cmap=cmap, norm=norm, colorbar_label="r (rings)", ncols=len(panels), **camera
    )
    plots.save_figure(fig, out / "fig8_two_materials.png")
    names.append("fig8_two_materials.png")

    rfull = np.broadcast_to(soft_hard, (mesh.n_vertices,))
    fig = plots.deformation_figure(
        mesh.vertices,
        F,
        mixed.vertices,
        mixed.vertex_energy,
        handles,
        mixed.history,
        targets=targets,
        rings=rfull,
        fixed_mask=np.all(targets == mesh.vertices[handles], axis=1),
        title="two-material bar (r = 2 middle, 6 elsewhere)",
        **camera,
    )
    plots.save_figure(fig, out / "two_materials_summary.png")
    names.append("two_materials_summary.png")
    return names
