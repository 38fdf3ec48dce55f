"""Headless figures (arapkit.plots.figures and its renderer, arapkit.plots.render)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import matplotlib.image as mpimg
import matplotlib.pyplot as plt
import numpy as np
import pytest
import trimesh

from arapkit.errors import InputError
from arapkit.plots.colors import ENERGY_CMAP, RING_COLORS
from arapkit.plots.figures import (
    cluster_simplify,
    deformation_figure,
    energy_curves_figure,
    iterations_figure,
    render_mesh,
    rings_colormap,
    save_figure,
    series_figure,
    view_basis,
)
from arapkit.plots.render import MOVED_COLOR, mark, new_figure


def _image(path):
    img = mpimg.imread(path)[..., :3]
    return img


def _assert_not_blank(path):
    img = _image(path)
    # a blank (single-colour) image has zero variance; a drawn mesh has plenty
    assert img.std() > 0.05, f"{path} looks blank (std {img.std():.4f})"
    return img


@pytest.fixture(scope="module")
def sphere():
    s = trimesh.creation.icosphere(subdivisions=3)
    return np.asarray(s.vertices, dtype=np.float64), np.asarray(s.faces, dtype=np.int64)


def test_view_basis_is_a_rotation_looking_along_the_thin_axis():
    pts = np.random.default_rng(3).normal(size=(400, 3)) * [0.1, 6.0, 2.0]
    B = view_basis(pts, elev=0, azim=0)
    np.testing.assert_allclose(B @ B.T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(B), 1.0)
    assert abs(B[2, 0]) > 0.99  # towards the viewer = x, the thinnest direction
    assert abs(B[0, 1]) > 0.99  # screen right = y, the longest direction
    B2 = view_basis(pts, elev=0, azim=0, right=[0, 0, 1])
    assert abs(B2[0, 2]) > 0.99


def test_cluster_simplify_respects_budget_and_shape(sphere):
    big = trimesh.creation.icosphere(subdivisions=6)  # 81,920 faces
    V, F = np.asarray(big.vertices), np.asarray(big.faces)
    values = V[:, 2].copy()
    Vs, Fs, vals = cluster_simplify(V, F, 5_000, values)
    assert 1_000 < len(Fs) <= 5_000
    # the simplified vertices still lie (nearly) on the unit sphere
    assert np.all(np.abs(np.linalg.norm(Vs, axis=1) - 1) < 0.05)
    # averaged values follow their cells: value = z stays consistent with position
    np.testing.assert_allclose(vals, Vs[:, 2], atol=1e-12)
    # small meshes are untouched
    V0, F0 = sphere
    same = cluster_simplify(V0, F0, 10**6)
    assert same[0] is V0 and same[1] is F0


def test_render_colours_faces_by_value(tmp_path):
    # two triangles side by side: left value 0, right value 1; the energy map's ends differ
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [3, 0, 0], [3, 1, 0]], float)
    F = np.array([[0, 1, 2], [3, 4, 5]])
    fig, ax = plt.subplots(figsize=(4, 2), dpi=50)
    norm = render_mesh(ax, V, F, np.array([0, 0, 0, 1, 1, 1.0]), basis=np.eye(3))
    # default range: 0 to the 99th percentile of the face values {0, 1}
    assert norm.vmin == 0.0 and norm.vmax == pytest.approx(0.99)
    save_figure(fig, tmp_path / "two.png")
    img = _assert_not_blank(tmp_path / "two.png")
    cmap = plt.get_cmap(ENERGY_CMAP)
    lo, hi = np.array(cmap(0.0)[:3]), np.array(cmap(1.0)[:3])
    # flat faces seen head-on get full light, so the pixel colours are the colour-map ends
    near = lambda c: np.any(np.all(np.abs(img - c) < 0.03, axis=-1))  # noqa: E731
    assert near(lo) and near(hi)


def test_rings_colormap_gives_each_r_its_one_colour_everywhere(tmp_path):
    cmap, norm, levels = rings_colormap(np.array([2, 2, 6]))
    assert levels.tolist() == [2, 6]
    # the same r has the same colour in every figure and in the editor
    for r in (2, 6):
        np.testing.assert_allclose(np.array(cmap(norm(r))[:3]) * 255, RING_COLORS[r - 1],
                                   atol=1e-9)
    cmap3, norm3, levels3 = rings_colormap(np.array([1, 3, 5, 3]))
    assert len({tuple(cmap3(norm3(v))) for v in levels3}) == 3
    np.testing.assert_allclose(np.array(cmap3(norm3(3))[:3]) * 255, RING_COLORS[2], atol=1e-9)
    # r above 6 takes the last colour, as in the editor's legend (6+)
    cmap9, norm9, _ = rings_colormap(np.array([9]))
    np.testing.assert_allclose(np.array(cmap9(norm9(9))[:3]) * 255, RING_COLORS[5], atol=1e-9)


def test_energy_colour_map_is_light_at_zero():
    # low energies must not turn a shape into a black silhouette (the shading then
    # darkens it by at most 0.35): the map's low end is light
    lo = np.array(plt.get_cmap(ENERGY_CMAP)(0.0)[:3])
    assert lo.mean() > 0.85


def test_deformation_figure_large_mesh_is_fast_and_not_blank(tmp_path):
    big = trimesh.creation.icosphere(subdivisions=6)  # 81,920 faces: the ~100K case
    V, F = np.asarray(big.vertices), np.asarray(big.faces)
    D = V * [1.3, 1.0, 0.8]
    energy = np.linalg.norm(D - V, axis=1)
    rings = np.where(V[:, 0] > 0, 2, 6)
    handles = np.flatnonzero(np.abs(V[:, 2]) > 0.95)
    t0 = time.perf_counter()
    fig = deformation_figure(
        V,
        F,
        D,
        energy,
        handles,
        [5.0, 2.0, 1.5, 1.4],
        rings=rings,
        fixed_mask=V[handles, 2] < 0,
        title="sphere",
    )
    save_figure(fig, tmp_path / "big.png")
    elapsed = time.perf_counter() - t0
    assert elapsed < 30, f"figure of 82K faces took {elapsed:.1f} s"
    img = _assert_not_blank(tmp_path / "big.png")
    assert img.shape[1] > 3 * img.shape[0]  # four panels side by side
    assert len(fig.axes) >= 4  # rest, energy, rings, curve (+ colour bars)


def test_uniform_rings_give_three_panels(sphere):
    V, F = sphere
    fig = deformation_figure(
        V, F, V, np.zeros(len(V)), np.array([0]), [1.0], rings=np.full(len(V), 3)
    )
    titles = [a.get_title() for a in fig.axes]
    assert "deformed: rigidity r" not in titles and "energy per iteration" in titles
    plt.close(fig)


def test_curves_and_iterations(tmp_path):
    fig = energy_curves_figure({"r = 1": [4.0, 2.0, 1.0], "r = 2": [3.0, 2.5]})
    assert fig.axes[0].get_yscale() == "log"
    assert [ln.get_label() for ln in fig.axes[0].lines] == ["r = 1", "r = 2"]
    save_figure(fig, tmp_path / "curves.svg")
    assert (tmp_path / "curves.svg").read_text().lstrip().startswith("<?xml")
    fig = iterations_figure([1, 2, 4], [300, 60, 30])
    np.testing.assert_array_equal(fig.axes[0].lines[0].get_ydata(), [300, 60, 30])
    save_figure(fig, tmp_path / "it.pdf")
    assert (tmp_path / "it.pdf").read_bytes()[:4] == b"%PDF"
    # an energy that reaches zero cannot go on a log axis
    fig = energy_curves_figure({"": [1.0, 0.0]})
    assert fig.axes[0].get_yscale() == "linear"
    plt.close(fig)


def test_series_figure_shared_norm(tmp_path, sphere):
    V, F = sphere
    cmap, norm, _ = rings_colormap(np.array([2, 6]))
    r = np.where(V[:, 0] > 0, 2, 6)
    fig = series_figure(
        F, [("a", V, r), ("b", V * 2, r), ("c", V, None)], cmap=cmap, norm=norm, ncols=2
    )
    save_figure(fig, tmp_path / "series.png")
    _assert_not_blank(tmp_path / "series.png")


def test_save_figure_rejects_unknown_format(tmp_path):
    open_before = plt.get_fignums()
    fig = energy_curves_figure({"a": [1.0]})
    with pytest.raises(InputError, match=r"fig.xyz: unsupported figure format"):
        save_figure(fig, tmp_path / "fig.xyz")
    # arapkit's figures are never pyplot's: nothing is left open in pyplot
    assert plt.get_fignums() == open_before
    # a figure the caller made with pyplot is closed, also on an error
    fig, _ = plt.subplots()
    with pytest.raises(InputError, match=r"fig.xyz: unsupported figure format"):
        save_figure(fig, tmp_path / "fig.xyz")
    assert not plt.fignum_exists(fig.number)
    with pytest.raises(InputError, match="does not exist"):
        save_figure(energy_curves_figure({"a": [1.0]}), tmp_path / "no" / "f.png")


def test_handles_are_painted_on_the_rest_panel(tmp_path, sphere):
    V, F = sphere
    V = V * [3.0, 2.0, 0.3]  # a flat ellipsoid is viewed face-on, so both ends show
    moved = np.flatnonzero(V[:, 0] > 2.4)
    fixed = np.flatnonzero(V[:, 0] < -2.4)
    handles = np.r_[fixed, moved]
    mask = np.r_[np.ones(len(fixed), bool), np.zeros(len(moved), bool)]
    fig = deformation_figure(V, F, V, np.zeros(len(V)), handles, [1.0], fixed_mask=mask)
    save_figure(fig, tmp_path / "h.png")
    img = _image(tmp_path / "h.png")
    panel = img[:, : img.shape[1] // 3]  # the rest-shape panel
    r, g, b = panel[..., 0], panel[..., 1], panel[..., 2]
    red = (r > 0.3) & (r > 2.5 * g) & (r > 2.5 * b)
    blue = (b > 0.15) & (b > 1.6 * r) & (b > 1.6 * g)
    assert red.sum() > 50 and blue.sum() > 50


def test_figures_leave_matplotlibs_backend_and_pyplot_alone(tmp_path):
    # a notebook's or an application's backend must survive importing and using the figures:
    # run in a fresh interpreter whose backend is not Agg, and draw and save every kind
    code = """
import sys, matplotlib
before = matplotlib.get_backend()
import numpy as np
from arapkit.plots import figures, render
from arapkit.mesh.shapes import bar
m = bar()
V, F = m.vertices, m.faces
fig = figures.deformation_figure(V, F, V * 1.1, np.ones(len(V)), np.array([0, 1]), [2.0, 1.0],
                                 rings=np.where(V[:, 0] > 0, 2, 6))
figures.save_figure(fig, sys.argv[1])
figures.save_figure(figures.groups_figure(V, F, [("a", [0, 1])]), sys.argv[1])
print(before, matplotlib.get_backend(), "matplotlib.pyplot" in sys.modules)
"""
    src = str(Path(__file__).resolve().parents[1] / "src")
    env = {**os.environ, "MPLBACKEND": "svg",
           "PYTHONPATH": os.pathsep.join(p for p in (src, os.environ.get("PYTHONPATH")) if p)}
    out = tmp_path / "f.png"
    proc = subprocess.run([sys.executable, "-c", code, str(out)], capture_output=True, text=True,
                          env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["svg", "svg", "False"]
    _assert_not_blank(out)


def test_renderer_draws_outside_pyplot(tmp_path):
    open_before = plt.get_fignums()
    fig = new_figure(figsize=(3, 3), dpi=60)
    ax = fig.subplots()
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    render_mesh(ax, V, np.array([[0, 1, 2]]), basis=np.eye(3))
    mark(ax, V[:1], np.eye(3), MOVED_COLOR, "moved")
    save_figure(fig, tmp_path / "t.png")
    _assert_not_blank(tmp_path / "t.png")
    assert plt.get_fignums() == open_before
