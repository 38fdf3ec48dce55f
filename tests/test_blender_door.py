"""The Blender door without Blender: handle groups, painted r and the live solver thread.

What the add-on reads from Blender arrives in :mod:`arapkit.blender` as arrays; these tests
feed it arrays and hold every answer against the library's own ``Deformer`` solve or a hand
computation. ``tests/test_blender_addon.py`` runs the add-on itself in Blender (bpy).
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from arapkit import Deformer
from arapkit.blender import (
    GroupHandle,
    LiveDeformer,
    make_rig,
    method_items,
    rings_from_weights,
    takes_rigidity_map,
)
from arapkit.errors import InputError
from arapkit.mesh.selection import rotation_matrix
from arapkit.mesh.shapes import bar, bar_bend, bar_two_materials
from arapkit.methods.registry import method, methods

#: the add-on's result is the library's solve: round-off of the diagonal apart
SAME = 1e-9


def _motion(axis, degrees, center, shift=(0.0, 0.0, 0.0)) -> np.ndarray:
    M = np.eye(4)
    R = rotation_matrix(np.asarray(axis, float), np.radians(degrees))
    M[:3, :3] = R
    M[:3, 3] = np.asarray(center) - R @ np.asarray(center) + np.asarray(shift)
    return M


def _bar_groups(mesh):
    x = mesh.vertices[:, 0]
    pin = (x <= x.min() + 1e-9).astype(float)
    tip = (x >= x.max() - 1e-9).astype(float) * 0.5  # any weight above 0 counts
    return [GroupHandle("Pin", "fixed", pin), GroupHandle("Tip", "moving", tip)]


# ------------------------------------------------------------------------------ the rig
def test_rig_handles_and_targets_follow_each_groups_motion():
    mesh = bar()
    rig = make_rig(mesh.n_vertices, _bar_groups(mesh), "Bar")
    x = mesh.vertices[:, 0]
    pin, tip = np.flatnonzero(x <= x.min() + 1e-9), np.flatnonzero(x >= x.max() - 1e-9)
    assert rig.handles.tolist() == sorted([*pin, *tip])
    assert rig.moving_names == ("Tip",)
    M = _motion([0, 1, 0], 40.0, [x.max(), 0, 0], shift=[0.1, 0.2, 0.3])
    T = rig.targets(mesh.vertices, [M])
    by_vertex = dict(zip(rig.handles.tolist(), T))
    for v in pin:  # fixed: at rest
        np.testing.assert_array_equal(by_vertex[v], mesh.vertices[v])
    for v in tip:  # moving: the affine map, computed by hand
        p = mesh.vertices[v]
        np.testing.assert_allclose(by_vertex[v], M[:3, :3] @ p + M[:3, 3], atol=1e-15)


def test_a_moving_group_takes_vertices_from_a_fixed_one():
    w_fixed = np.array([1.0, 1.0, 1.0, 0.0])
    w_move = np.array([0.0, 0.0, 0.2, 1.0])
    rig = make_rig(4, [GroupHandle("Pin", "fixed", w_fixed),
                       GroupHandle("Hook", "moving", w_move)])
    assert rig.handles.tolist() == [0, 1, 2, 3]
    assert rig.owner.tolist() == [-1, -1, 0, 0]


@pytest.mark.parametrize("groups, words", [
    ([], "no handle groups"),
    ([GroupHandle("Tip", "moving", np.ones(3))], "no fixed group"),
    ([GroupHandle("Pin", "fixed", np.zeros(3))], "vertex group 'Pin' is empty"),
    ([GroupHandle("Pin", "fixed", np.ones(2))], "vertex group 'Pin': expected one weight"),
    ([GroupHandle("Pin", "pinned", np.ones(3))], "kind must be one of fixed, moving"),
    ([GroupHandle("Pin", "fixed", [1.0, 0, 0]), GroupHandle("A", "moving", [0, 1.0, 1]),
      GroupHandle("B", "moving", [0, 0, 1.0])],
     "vertex 2 is in two moving groups, 'A' and 'B'"),
])
def test_bad_groups_get_one_line_naming_the_group(groups, words):
    with pytest.raises(InputError) as exc:
        make_rig(3, groups, "Suzanne")
    msg = str(exc.value)
    assert msg.startswith("Suzanne: ") and words in msg and "\n" not in msg


def test_a_motion_that_is_not_finite_names_its_group():
    rig = make_rig(3, [GroupHandle("Pin", "fixed", [1.0, 0, 0]),
                       GroupHandle("Hand", "moving", [0, 0, 1.0])])
    M = np.eye(4)
    M[0, 3] = np.inf
    with pytest.raises(InputError, match="moving group 'Hand'"):
        rig.targets(np.zeros((3, 3)), [M])
    with pytest.raises(InputError, match="expected 1 matrices"):
        rig.targets(np.zeros((3, 3)), [])


def test_painted_weights_map_to_r_in_the_panels_range():
    w = np.array([0.0, 0.1, 0.25, 0.5, 0.9, 1.0, 1.7, -3.0, np.nan])
    r = rings_from_weights(w, 2, 6)
    assert r.dtype == np.int32
    # by hand: rint(2 + 4 w), w clipped to [0, 1], nan = not painted
    assert r.tolist() == [2, 2, 3, 4, 6, 6, 6, 2, 2]
    assert rings_from_weights(w, 5, 1).tolist()[0] == 5  # an upside-down range paints down
    with pytest.raises(InputError, match="r at weight 1"):
        rings_from_weights(w, 1, 1000)


# --------------------------------------------------------------------------- the panel
def test_the_panel_offers_the_registrys_blender_methods():
    assert [name for name, _, _ in method_items()] == [m.name for m in methods("blender")]
    assert all(method(m.name).local_global for m in methods("blender"))
    for m in methods("blender"):
        assert takes_rigidity_map(m.name) == m.rigidity_map
    with pytest.raises(InputError, match="unknown method 'laplacian' in blender"):
        takes_rigidity_map("laplacian")


# ------------------------------------------------------------------------- the solver
def _case(rings=True):
    mesh = bar()
    h, t = bar_bend(mesh, 70)
    r = bar_two_materials(mesh) if rings else 1
    return mesh, h, t, r


def test_the_exact_solve_is_the_librarys_solve():
    mesh, h, t, r = _case()
    live = LiveDeformer(mesh, h, r, weights="cotan-clamped", tol=1e-4)
    try:
        live.request(t, exact=True)
        shape = live.wait(300)
    finally:
        live.close()
    want = Deformer(mesh, h, rings=r, weights="cotan-clamped", tol=1e-4).solve(t)
    diag = mesh.bounding_box_diagonal
    assert shape.exact and shape.converged and shape.error is None
    assert np.abs(shape.vertices - want.vertices).max() <= SAME * diag
    assert shape.iterations == want.iterations
    # and it is a deformation: the free vertices moved, the handles are on their targets
    assert np.abs(shape.vertices[h] - t).max() <= SAME * diag
    assert np.abs(shape.vertices - mesh.vertices).max() > 0.1 * diag


class _Recording(LiveDeformer):
    """A LiveDeformer that keeps every shape it sends (poll() keeps only the newest)."""

    def __init__(self, *args, **kwargs):
        self.shapes = []
        super().__init__(*args, **kwargs)

    def _publish(self, shape):
        self.shapes.append(shape)
        super()._publish(shape)


def test_a_pose_after_a_quiet_frame_shows_after_its_first_iteration():
    """The frame is counted from the last shape sent: a new pose that comes after a quiet
    frame is shown after one iteration, not after a whole frame of iterations."""
    mesh, h, t, r = _case()
    live = _Recording(mesh, h, r, frame_ms=200.0, tol=1e-9, max_iter=400)
    try:
        live.request(t, exact=True)
        live.wait(300)
        time.sleep(0.25)  # more than a frame since the exact shape was sent
        _, t_end = bar_bend(mesh, 110)
        live.request(t_end)
        live.wait(300)
    finally:
        live.close()
    first_live = next(s for s in live.shapes if not s.exact)
    assert first_live.iterations == 1 and not first_live.converged
    # and later shapes wait a frame from it: the solve ran on to convergence
    assert live.shapes[-1].converged and live.shapes[-1].iterations > 1


def test_a_drag_sends_live_shapes_and_converges_warm_started():
    """A drag: live shapes while it moves, then the last pose solved on to convergence from
    the last shape (the stopping test's distance from the exact solve, not a restart)."""
    mesh, h, t, r = _case()
    live = LiveDeformer(mesh, h, r, frame_ms=5.0, tol=1e-6)
    got = []
    try:
        live.request(t, exact=True)
        first = live.wait(300)
        _, t_end = bar_bend(mesh, 110)
        for k in range(1, 13):  # twelve poses, a little further each time, no waiting
            live.request(t + (t_end - t) * k / 12)
            time.sleep(0.01)
            shape = live.poll()
            if shape is not None:
                got.append(shape)
        final = live.wait(300)
    finally:
        live.close()
    diag = mesh.bounding_box_diagonal
    assert got and not any(s.exact for s in got), "no live shape was sent during the drag"
    assert not final.exact and final.converged
    assert np.abs(final.vertices[h] - t_end).max() <= SAME * diag
    want = Deformer(mesh, h, rings=r, tol=1e-6).solve(t_end).vertices
    assert np.abs(final.vertices - want).max() <= 1e-3 * diag
    # it followed: far from where the first pose left it
    assert np.abs(final.vertices - first.vertices).max() > 0.05 * diag


def test_methods_without_a_rigidity_map_ignore_the_painted_one():
    mesh, h, t, r = _case()
    live = LiveDeformer(mesh, h, r, method="spokes-and-rims")
    try:
        live.request(t, exact=True)
        shape = live.wait(300)
    finally:
        live.close()
    want = Deformer(mesh, h, energy="spokes-and-rims").solve(t)
    assert np.abs(shape.vertices - want.vertices).max() <= SAME * mesh.bounding_box_diagonal


def test_a_method_blender_does_not_offer_is_refused():
    mesh, h, _, _ = _case()
    with pytest.raises(InputError, match="unknown method 'embedded' in blender"):
        LiveDeformer(mesh, h, method="embedded")


def test_a_failed_solve_sends_its_message_and_the_thread_lives_on():
    mesh, h, t, _ = _case(rings=False)
    live = LiveDeformer(mesh, h)
    try:
        live.request(t[:-1], exact=True)  # one target short
        bad = live.wait(300)
        live.request(t, exact=True)
        good = live.wait(300)
    finally:
        live.close()
    assert bad.vertices is None and "\n" not in bad.error and "targets" in bad.error
    assert good.error is None and good.converged


def test_coarse_to_fine_sessions_preview_then_solve_exactly():
    mesh = bar(segments=(60, 8, 8))
    h, t = bar_bend(mesh, 60)
    live = LiveDeformer(mesh, h, multires=True, frame_ms=5.0, settle_s=0.05)
    try:
        live.request(t)  # live: proxy previews, then the settled exact solve
        shape = live.wait(600)
        assert type(live.deformer).__name__ == "MultiresDeformer"
    finally:
        live.close()
    want = Deformer(mesh, h, multires=True).solve(t)
    assert shape.exact and live.sent >= 2
    assert np.abs(shape.vertices - want.vertices).max() <= SAME * mesh.bounding_box_diagonal


def test_the_callers_thread_never_waits_for_a_solve():
    """request() and poll() hold the lock only to swap a reference: while the solver thread
    factorises and iterates, each call returns at once."""
    mesh = bar(segments=(80, 10, 10))
    h, t = bar_bend(mesh, 90)
    live = LiveDeformer(mesh, h, rings=3, tol=1e-8, settle_s=None)
    worst = 0.0
    try:
        live.request(t, exact=True)
        stop = time.monotonic() + 2.0
        while time.monotonic() < stop and live.busy:
            t0 = time.perf_counter()
            live.poll()
            live.request(t)
            worst = max(worst, time.perf_counter() - t0)
            time.sleep(0.005)
    finally:
        live.close()
    assert worst < 0.25, f"a call waited {worst:.3f} s"


def test_every_new_shape_is_polled_once():
    """poll() hands each new shape over exactly once, and never one wait() returned."""
    mesh, h, t, _ = _case(rings=False)
    live = LiveDeformer(mesh, h)
    try:
        for k in range(20):
            live.request(t * (1.0 + 1e-3 * k), exact=True)
            assert live.wait(300).error is None
            assert live.poll() is None, f"round {k}: the shape wait() returned came again"
            before = live.sent
            live.request(t * (1.0 - 1e-3 * k), exact=True)
            deadline = time.monotonic() + 60
            while (got := live.poll()) is None and time.monotonic() < deadline:
                time.sleep(0.001)
            assert got is not None and live.sent == before + 1, f"round {k}: missed"
            assert live.poll() is None
    finally:
        live.close()
