"""No flipped triangles (issue 48, part 1): the extreme-drag suite frame by frame, the line
search's quadratic against brute force, the barrier's gradient against finite differences,
and the fold count where the pins admit no fold-free map."""

from __future__ import annotations

import numpy as np
import pytest
from drag_suite import scenarios

from arapkit import Deformer
from arapkit.arap.flips import ZONE, barrier, count_folds, max_step
from arapkit.mesh.planar import signed_areas
from arapkit.mesh.shapes2d import strip, strip_ends

SUITE = scenarios()


def run(sc, flips: str):
    """Every frame warm from the last; per frame (folds, largest pin error, result)."""
    V2 = np.ascontiguousarray(sc.mesh.vertices[:, :2])
    d = Deformer((V2, sc.mesh.faces), sc.handles, flips=flips)
    P, out = V2.copy(), []
    for i, T in enumerate(sc.frames):
        res = d.solve(T, init=P, angles=sc.angle(i), tol=1e-4, max_iter=1000)
        P = res.vertices
        folds = int((signed_areas(P, sc.mesh.faces) <= 0).sum())  # counted here, not trusted
        out.append((folds, float(np.abs(P[sc.handles] - T).max()), res))
    return out


@pytest.mark.parametrize("sc", SUITE, ids=[s.name for s in SUITE])
def test_no_triangle_turns_over_in_any_frame(sc):
    for i, (folds, pin_error, res) in enumerate(run(sc, "prevent")):
        assert folds == 0 == res.folds, f"{sc.name} frame {i}: {folds} folded"
        assert pin_error == 0.0, f"{sc.name} frame {i}: pins {pin_error} off"  # exact
        assert "flip_guard_released" not in res.timings


def test_the_suite_is_extreme_plain_arap_folds():
    """Plain ARAP (the guard off) turns triangles over in most of the suite: the suite
    tests the guard, not an easy case."""
    folded = [sc.name for sc in SUITE if max(f for f, _, _ in run(sc, "allow")) > 0]
    assert len(folded) >= 4, folded


def test_pins_that_admit_no_fold_free_map_are_met_and_the_folds_counted():
    """The right end's two pinned columns mirrored: the triangles between them must turn
    over. The pins are still met exactly and the result says how many folded."""
    m = strip(segments=(20, 4))
    left, right = strip_ends(m)
    h = np.concatenate([left, right])
    V = m.vertices[:, :2]
    T = V[h].copy()
    T[len(left):, 1] *= -1.0  # a mirror of the right end: no rotation does that
    res = Deformer(m, h).solve(T, max_iter=400)
    assert np.abs(res.vertices[h, :2] - T).max() == 0.0
    forced = int(count_folds(res.vertices[:, :2], m.faces, np.ones(m.n_faces)))
    assert res.folds == forced >= 8  # the two mirrored columns' triangles at least
    assert res.timings["flip_guard_released"] == 1


def test_the_largest_step_is_where_the_area_meets_its_floor():
    rng = np.random.default_rng(3)
    F = np.array([[0, 1, 2]])
    for _ in range(200):
        P = rng.normal(size=(3, 2))
        if signed_areas(P, F)[0] < 0:
            P = P[[0, 2, 1]]
        Q = P + rng.normal(scale=2.0, size=(3, 2))
        A0 = signed_areas(P, F)[0]
        floor = np.array([0.3 * A0])
        a = max_step(P, Q, F, np.ones(1), floor)
        ts = np.linspace(0, min(a, 50.0), 2001)
        areas = np.array([signed_areas(P + t * (Q - P), F)[0] for t in ts])
        assert (areas >= floor[0] - 1e-9 * A0).all()  # never below the floor before a
        if np.isfinite(a):
            assert signed_areas(P + a * (Q - P), F)[0] == pytest.approx(floor[0], rel=1e-8)


def test_barrier_gradient_matches_finite_differences():
    m = strip(segments=(3, 2))
    F = m.faces
    V = m.vertices[:, :2]
    A0 = np.abs(signed_areas(V, F))
    sign = np.sign(signed_areas(V, F))
    rng = np.random.default_rng(5)
    P = V.copy()
    P[5, 1] = V[1, 1] + 0.03  # squeeze the triangles between into the barrier's zone
    P += rng.normal(scale=0.002, size=P.shape)
    s = signed_areas(P, F) * sign / A0
    assert (s > 0).all() and ((s > 0) & (s < ZONE)).sum() >= 2
    G = np.zeros_like(P)
    E = barrier(P, F, sign, A0, ZONE, 30.0, G)
    assert E > 0
    h = 1e-7
    for v in range(len(P)):
        for c in range(2):
            Pp, Pm = P.copy(), P.copy()
            Pp[v, c] += h
            Pm[v, c] -= h
            fd = (barrier(Pp, F, sign, A0, ZONE, 30.0, np.zeros((0, 2)))
                  - barrier(Pm, F, sign, A0, ZONE, 30.0, np.zeros((0, 2)))) / (2 * h)
            assert G[v, c] == pytest.approx(fd, rel=1e-5, abs=1e-6 * abs(E))
    assert barrier(V, F, sign, A0, ZONE, 30.0, np.zeros((0, 2))) == 0.0  # rest: off
