"""Images (issue 48, part 2): meshing with holes and density, the rasteriser against the
picture and against an independent rigid resampling, depth order, animation files, and
one-line refusals of bad input by ``arapkit warp``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("PIL", reason="the image extra (Pillow) is not installed")
pytest.importorskip("skimage", reason="the image extra (scikit-image) is not installed")
pytest.importorskip("pythoncdt", reason="the image extra (PythonCDT) is not installed")

from PIL import Image  # noqa: E402

from arapkit import InputError  # noqa: E402
from arapkit.image.meshing import mesh_mask, shape_mask  # noqa: E402
from arapkit.image.pins import load_keyframes  # noqa: E402
from arapkit.image.sprite import puppet_pins, puppet_sprite  # noqa: E402
from arapkit.image.warp import ImageWarp, warp_image  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SRC = str(ROOT / "src")


@pytest.fixture(scope="module")
def sprite():
    return puppet_sprite(160)


def premult(img):
    a = img[..., 3:4].astype(np.float64)
    return np.concatenate([img[..., :3] * a / 255.0, a], axis=-1)


def test_mesh_keeps_the_holes_and_the_pins_and_follows_the_density():
    sprite = puppet_sprite(320)
    mask = shape_mask(sprite)
    at = puppet_pins(320)
    coarse = mesh_mask(mask, 8.0, pins=at)
    fine = mesh_mask(mask, 4.0, pins=at)
    assert len(coarse.boundary_loops) == 3  # the outline and the two eyes
    assert coarse.n_components == 1
    assert np.array_equal(coarse.vertices[:len(at), :2], at)  # pins are vertices 0..p-1
    assert 3.0 < fine.n_vertices / coarse.n_vertices < 5.0  # about (8 / 4)^2
    # every pixel that is not fully transparent is inside the mesh (none is cut off)
    from matplotlib.path import Path as MPath

    tri = coarse.vertices[coarse.faces, :2]
    ys, xs = np.nonzero(sprite[..., 3] > 0)
    pts = np.stack([xs + 0.5, ys + 0.5], 1)
    inside = np.zeros(len(pts), bool)
    for t in tri:
        inside |= MPath(t).contains_points(pts, radius=1e-9)
    assert inside.all()


def test_pins_at_rest_give_the_picture(sprite):
    at = puppet_pins(160)
    w = ImageWarp(sprite, at)
    out = w.frame(at).image
    assert np.abs(out[..., 3].astype(int) - sprite[..., 3]).max() <= 1
    seen = sprite[..., 3] > 0
    assert np.abs(out[seen].astype(int) - sprite[seen]).max() <= 1  # every level


def test_a_rigid_motion_of_the_pins_moves_the_picture_rigidly(sprite):
    from scipy.ndimage import affine_transform

    at = puppet_pins(160)
    t = np.radians(25.0)
    Q = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    c = np.array([80.0, 80.0])
    to = (at - c) @ Q.T + c + [6.0, -4.0]
    w = ImageWarp(sprite, at)
    res = w.frame(to)
    assert np.abs(res.vertices - ((w.rest - c) @ Q.T + c + [6.0, -4.0])).max() < 1e-9
    # independent: each output pixel centre p samples the source at Q^T (p - c - s) + c
    Pm = premult(sprite)
    Qi = Q.T
    shift = c - Qi @ (c + [6.0, -4.0])
    # in (row, col) = (y, x) index space with pixel centres at integers
    M = Qi[::-1, ::-1]
    off = (shift + Qi @ [0.5, 0.5] - [0.5, 0.5])[::-1]
    ref = np.stack([affine_transform(Pm[..., k], M, offset=off, order=1) for k in range(4)], -1)
    got = premult(res.image)
    solid = affine_transform((sprite[..., 3] == 255).astype(float), M, offset=off, order=0)
    from scipy.ndimage import binary_erosion

    interior = binary_erosion(solid > 0.5, iterations=2)
    assert interior.sum() > 5000
    assert np.abs(got[interior] - ref[interior]).max() <= 1.5


def test_depth_decides_which_part_is_in_front():
    img = np.zeros((60, 120, 4), np.uint8)
    img[20:40, 5:55] = [255, 0, 0, 255]     # a red bar
    img[20:40, 65:115] = [0, 0, 255, 255]   # a blue bar
    pins = [{"at": [10, 30], "to": [40, 30]}, {"at": [50, 30], "to": [80, 30]},
            {"at": [70, 30], "to": [40, 30.5]}, {"at": [110, 30], "to": [80, 30.5]}]
    for red, blue, front in ((1, 0, 0), (0, 1, 2)):
        p = [dict(q, depth=red if i < 2 else blue) for i, q in enumerate(pins)]
        out = warp_image(img, p).image
        px = out[30, 60]  # where both bars lie now
        assert px[front] > 200 and px[2 - front] < 50, px


def test_keyframes_render_gif_apng_and_frames(tmp_path):
    keys = load_keyframes(ROOT / "examples" / "puppet-keys.json")
    n = len(keys.frames())
    for name in ("a.gif", "a.png", "frames"):
        r = subprocess.run([sys.executable, "-m", "arapkit.cli", "warp",
                            str(ROOT / "examples" / "puppet.png"), "--keyframes",
                            str(ROOT / "examples" / "puppet-keys.json"), "-o",
                            str(tmp_path / name)], capture_output=True, text=True,
                           env={"PYTHONPATH": SRC, "PATH": "/usr/bin:/bin"})
        assert r.returncode == 0, r.stderr
        out = tmp_path / name
        if out.is_dir():
            assert len(list(out.glob("frame_*.png"))) == n
        else:
            with Image.open(out) as im:
                assert getattr(im, "n_frames", 1) == n


def test_cli_warp_writes_the_image_and_the_mesh(tmp_path):
    out, mesh = tmp_path / "w.png", tmp_path / "w.obj"
    r = subprocess.run([sys.executable, "-m", "arapkit.cli", "warp",
                        str(ROOT / "examples" / "puppet.png"), "--pins",
                        str(ROOT / "examples" / "puppet-pins.json"), "-o", str(out),
                        "--save-mesh", str(mesh)], capture_output=True, text=True,
                       env={"PYTHONPATH": SRC, "PATH": "/usr/bin:/bin"})
    assert r.returncode == 0, r.stderr
    with Image.open(out) as im:
        assert im.size == (256, 256) and im.mode == "RGBA"
    lines = mesh.read_text().splitlines()
    v = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("v ")])
    vt = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("vt ")])
    pins = json.loads((ROOT / "examples" / "puppet-pins.json").read_text())
    assert len(v) == len(vt) and np.all(v[:, 2] == 0)
    assert np.allclose(v[:len(pins), :2], [p["to"] for p in pins], atol=1e-5)  # pins met
    assert np.allclose(vt[:len(pins)] * [256, -256] + [0, 256], [p["at"] for p in pins],
                       atol=1e-3)


@pytest.mark.parametrize("case, message", [
    ("transparent", "no opaque pixels"),
    ("one-colour", "no opaque pixels"),
    ("pin-outside", "pin 1 at (2, 2) is outside the shape"),
    ("pin-off-image", "pin 0 at (500, 10) is outside the 64 x 64 image"),
    ("bad-pins", "pin 0 \"to\": expected two finite numbers"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, case, message):
    img = np.zeros((64, 64, 4), np.uint8)
    img[16:48, 16:48] = [90, 160, 60, 255]
    pins = [{"at": [20, 32], "to": [20, 32]}, {"at": [44, 32], "to": [50, 30]}]
    if case == "transparent":
        img[..., 3] = 0
    elif case == "one-colour":
        img = np.full((64, 64, 3), 77, np.uint8)
    elif case == "pin-outside":
        pins[1]["at"] = [2, 2]
    elif case == "pin-off-image":
        pins[0]["at"] = [500, 10]
    elif case == "bad-pins":
        pins[0]["to"] = [1, "x"]
    Image.fromarray(img).save(tmp_path / "in.png")
    (tmp_path / "p.json").write_text(json.dumps(pins))
    r = subprocess.run([sys.executable, "-m", "arapkit.cli", "warp", str(tmp_path / "in.png"),
                        "--pins", str(tmp_path / "p.json"), "-o", str(tmp_path / "o.png")],
                       capture_output=True, text=True,
                       env={"PYTHONPATH": SRC, "PATH": "/usr/bin:/bin"})
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and message in r.stderr, r.stderr
    assert not (tmp_path / "o.png").exists()


def test_library_refusals_are_input_errors(sprite):
    with pytest.raises(InputError, match="no opaque pixels"):
        ImageWarp(np.zeros((8, 8, 4), np.uint8), [[4, 4]])
    with pytest.raises(InputError, match="expected a uint8 array"):
        ImageWarp(np.zeros((8, 8, 4)), [[4, 4]])
