"""Bounding box, up-axis guess and named camera views (arapkit.mesh.orientation)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import data_path

from arapkit import load_mesh
from arapkit.errors import InputError
from arapkit.mesh.orientation import VIEWS, bounding_box, guess_up, parse_axis, view_frame

#: Up axes read off axis-aligned renders of each model (a person looked at them); the
#: guess must agree. Models with no true up (knot, fist, half-cylinder, flat patch) are
#: not listed.
TRUE_UP = {
    "meshes/bunny00.off": "+y",
    "meshes/cow.off": "+y",
    "meshes/dragon_vrip.ply.gz": "+y",
    "meshes/elephant.off": "+y",
    "meshes/refined_elephant.off": "+y",
    "meshes/homer.off": "+y",
    "meshes/npm_snowden_lo.obj": "+y",
    "sequences/panda_walk_seq.npz": "+z",
    "sequences/anny_makehuman_pose_seq.npz": "+z",
}


def _standing_figure(up: int) -> np.ndarray:
    """A 'person': two thin legs under a wide body, standing on axis ``up`` (1 or 2)."""
    parts = []
    for x in (-0.3, 0.3):  # legs, 1 tall
        leg = trimesh.creation.cylinder(radius=0.1, height=1.0, sections=16)
        leg.apply_translation([x, 0, 0.5])
        parts.append(leg.vertices)
    body = trimesh.creation.box(extents=[1.2, 0.5, 1.2])
    body.apply_translation([0, 0, 1.6])
    parts.append(body.vertices)
    V = np.concatenate(parts)
    if up == 1:  # rotate z-up into y-up: (x, y, z) -> (x, z, -y)
        V = np.stack([V[:, 0], V[:, 2], -V[:, 1]], axis=1)
    return V


def test_bounding_box_matches_min_max():
    V = np.random.default_rng(0).normal(size=(100, 3))
    box = bounding_box(V)
    np.testing.assert_array_equal(box.min, V.min(0))
    np.testing.assert_array_equal(box.extents, V.max(0) - V.min(0))
    assert box.diagonal == pytest.approx(np.linalg.norm(V.max(0) - V.min(0)))


@pytest.mark.parametrize(("up", "name"), [(1, "+y"), (2, "+z")])
def test_guess_up_finds_the_feet(up, name):
    g = guess_up(_standing_figure(up))
    assert g.axis == name and g.confidence > 0.5 and "stands on" in g.reason


def test_guess_up_ties_go_to_z_with_no_confidence():
    box = trimesh.creation.box(extents=[4, 1, 1]).vertices  # stands on y and z alike
    g = guess_up(box)
    assert g.axis == "+z" and g.confidence == 0.0


def test_guess_up_lying_shape_falls_back_to_height():
    # a sphere stands on nothing (one contact point): the taller of y and z decides
    s = trimesh.creation.icosphere(subdivisions=3).vertices * [1, 2, 1]
    g = guess_up(s)
    assert g.axis == "+y" and g.confidence <= 0.5


@pytest.mark.parametrize("rel", sorted(TRUE_UP))
def test_guess_up_on_the_shared_meshes(rel):
    path = data_path(*rel.split("/"))
    V = np.load(path)["V"][0] if rel.endswith(".npz") else load_mesh(path).vertices
    assert guess_up(V).axis == TRUE_UP[rel]


def test_parse_axis():
    assert parse_axis("y").tolist() == [0, 1, 0]
    assert parse_axis(" -X ").tolist() == [-1, 0, 0]
    with pytest.raises(InputError, match="up axis 'w'"):
        parse_axis("w")


@pytest.mark.parametrize("view", VIEWS)
def test_views_are_rotations_and_upright(view):
    V = _standing_figure(1)  # y-up
    B, up = view_frame(V, view)
    assert up == "+y"
    np.testing.assert_allclose(B @ B.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(B) == pytest.approx(1.0)
    if view == "top":
        assert B[2] @ [0, 1, 0] == pytest.approx(1.0)  # looking straight down
    else:
        assert B[1] @ [0, 1, 0] > 0.85  # screen up is (nearly) +y
        assert abs(B[0] @ [0, 1, 0]) < 1e-12  # and the horizon stays level


def test_front_looks_along_the_thinner_horizontal_axis():
    V = _standing_figure(2)  # z-up, body 1.2 wide in x, 0.5 deep in y
    B, _ = view_frame(V, "front")
    assert abs(B[2, 1]) > 0.95  # towards the viewer is mostly +-y
    assert B[0, 0] > 0.95  # +x to the right
    B, _ = view_frame(V, "front", up="-z")  # upside down on request
    assert B[1] @ [0, 0, -1] > 0.95


def test_bad_view_is_an_input_error():
    with pytest.raises(InputError, match="view 'diagonal'"):
        view_frame(np.eye(3), "diagonal")
