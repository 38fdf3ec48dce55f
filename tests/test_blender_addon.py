"""The ARAP Deform add-on in Blender itself (bpy, Blender as a Python module), headless.

Each scene runs in a fresh Python (``tests/blender_scenes.py``): Blender keeps global state
and can be imported once per process. The results are checked here against arapkit's own
``Deformer`` on the same data, with the handles, targets and r recomputed by hand from the
scene's coordinates and matrices, not taken from the add-on. The extension zip is built
(``blender/build.py``, as ``make blender-addon``), validated with Blender's own extension
tool, installed into a clean Blender profile and run from there.

``pip install --no-deps bpy`` brings Blender (``.ci/run`` does; ``--no-deps`` because
bpy pins numpy<2 for its audio module only). Without it these tests skip.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import tomllib

from arapkit import Deformer, Mesh

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "tests" / "blender_scenes.py"
#: the add-on's solve is the library's: round-off of the bounding-box diagonal apart
SAME = 1e-9



def _bpy_missing() -> str | None:
    """Why Blender cannot run here (None when it can): bpy absent or failing to import."""
    if importlib.util.find_spec("bpy") is None:
        return "bpy (Blender as a Python module) is not installed: pip install --no-deps bpy"
    done = subprocess.run([sys.executable, "-c", "import bpy"], capture_output=True,
                          text=True, timeout=300)
    if done.returncode != 0:
        return f"bpy does not import: {done.stderr.strip().splitlines()[-1]}"
    return None


_WHY = _bpy_missing()
pytestmark = pytest.mark.skipif(_WHY is not None, reason=str(_WHY))


def run_scene(scene: str, out: Path, *args: str, env: dict | None = None,
              flags: tuple[str, ...] = (), timeout: float = 900) -> tuple[dict, dict]:
    """Run one scene in a fresh Python; its JSON result and its arrays."""
    base = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    done = subprocess.run([sys.executable, *flags, str(SCENES), scene, str(out), *args],
                          env={**base, **(env or {})}, capture_output=True, text=True,
                          timeout=timeout)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    npz = out / "result.npz"
    arrays = dict(np.load(npz, allow_pickle=False)) if npz.exists() else {}
    return json.loads((out / "result.json").read_text()), arrays


def _local_motion(obj, rest, moved) -> np.ndarray:
    """A driver's motion in the mesh's own coordinates (as the Hook modifier has it), in
    float64 from Blender's float32 matrices."""
    frame = np.asarray(obj, dtype=np.float64)
    return (np.linalg.inv(frame) @ np.asarray(moved, dtype=np.float64)
            @ np.linalg.inv(np.asarray(rest, dtype=np.float64)) @ frame)


def _bar_handles(V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x = V[:, 0]
    return np.flatnonzero(x <= x.min() + 1e-6), np.flatnonzero(x >= x.max() - 1e-6)


def _targets(V: np.ndarray, pin, tip, M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    h = np.sort(np.concatenate([pin, tip]))
    T = V[h].copy()
    moving = np.isin(h, tip)
    T[moving] = V[h[moving]] @ M[:3, :3].T + M[:3, 3]
    return h, T


@pytest.fixture(scope="module")
def solved(tmp_path_factory) -> tuple[dict, dict]:
    return run_scene("solve", tmp_path_factory.mktemp("solve"))


def test_the_shape_key_is_the_librarys_solve_with_painted_r(solved):
    info, a = solved
    V = a["base_before"]
    np.testing.assert_array_equal(a["rest"], V)  # what was solved is the mesh at rest
    pin, tip = _bar_handles(V)
    # r painted by hand as the scene paints it (Weight Paint stores float32), 0 -> 1, 1 -> 4
    w = np.float32(np.round(np.clip(1.0 - np.abs(V[:, 0]) / 2.0, 0.0, 1.0), 2))
    rings = np.rint(1 + 3 * w.astype(np.float64)).astype(np.int32)
    assert set(rings.tolist()) == {1, 2, 3, 4}
    mesh = Mesh(V, a["tris"])
    diag = mesh.bounding_box_diagonal
    for shape, key, empty in ((a["shape0"], a["key0"], info["empty_rest"]),
                              (a["shape1"], a["key1"], info["empty_moved"])):
        M = _local_motion(info["object"], np.array(info["empty_rest"]), np.array(empty))
        h, T = _targets(V, pin, tip, M)
        want = Deformer(mesh, h, rings=rings, tol=1e-4).solve(T).vertices
        assert np.abs(shape - want).max() <= SAME * diag
        # the shape key holds it as Blender stores coordinates: float32
        np.testing.assert_array_equal(key, shape.astype(np.float32))
    # the moved pose really bends the bar
    assert np.abs(a["shape1"] - V).max() > 0.2 * diag
    assert "converged" in info["status"]


def test_a_moved_handle_object_is_followed_live(solved):
    info, a = solved
    V = a["base_before"]
    pin, tip = _bar_handles(V)
    M = _local_motion(info["object"], np.array(info["empty_rest"]),
                      np.array(info["empty_moved"]))
    h, T = _targets(V, pin, tip, M)
    live = a["live"]
    assert live.shape == V.shape, "no shape was written while the solve ran"
    diag = Mesh(V, a["tris"]).bounding_box_diagonal
    assert np.abs(live[h] - T).max() <= SAME * diag  # handles on their new targets
    free = np.setdiff1d(np.arange(len(V)), h)
    assert np.abs(live[free] - a["shape0"][free]).max() > 0.05 * diag
    # once the drag stops it is solved on from there, to the stopping test: near the exact
    # solve from rest (0.2 % of the diagonal here), not on it
    warm = a["warm"]
    assert np.abs(warm[h] - T).max() <= SAME * diag
    assert np.abs(warm - a["shape1"]).max() <= 1e-2 * diag
    assert "converged" in info["status"]


def test_nothing_but_the_shape_key_changes(solved):
    info, a = solved
    np.testing.assert_array_equal(a["base_after"], a["base_before"])
    np.testing.assert_array_equal(a["uv_after"], a["uv_before"])
    np.testing.assert_array_equal(a["temperature"], np.arange(len(a["temperature"])))
    assert info["materials"] == ["Clay"]
    assert info["keys"] == ["Basis", "ARAP Deform"] and info["key_value"] == 1.0


def test_a_bone_carries_its_group(tmp_path):
    info, a = run_scene("bone", tmp_path)
    V = a["rest"]
    pin, tip = _bar_handles(V)
    M = _local_motion(a["object"], a["arm_before"].astype(float) @ a["bone_before"],
                      a["arm_after"].astype(float) @ a["bone_after"])
    assert np.abs(M[:3, :3] - np.eye(3)).max() > 0.3  # the pose turned the bone
    h, T = _targets(V, pin, tip, M)
    mesh = Mesh(V, a["tris"])
    want = Deformer(mesh, h, rings=2, tol=1e-4).solve(T).vertices
    assert np.abs(a["shape"] - want).max() <= SAME * mesh.bounding_box_diagonal


def test_each_frame_of_an_animation_is_solved_exactly(tmp_path):
    """Setting a frame (rendering, blender -b) waits for that pose's exact solve."""
    info, a = run_scene("animation", tmp_path)
    V = a["rest"]
    pin, tip = _bar_handles(V)
    mesh = Mesh(V, a["tris"])
    rest_pose = np.eye(4)
    rest_pose[:3, 3] = (2.3, -0.2, 0.5)
    rest_pose = rest_pose.astype(np.float32).astype(np.float64)  # as Blender stores it
    w = np.float32(np.round(np.clip(1.0 - np.abs(V[:, 0]) / 2.0, 0.0, 1.0), 2))
    rings = np.rint(1 + 3 * w.astype(np.float64)).astype(np.int32)
    for shape, pose in zip(a["shapes"], a["poses"]):
        h, T = _targets(V, pin, tip, _local_motion(a["object"], rest_pose, pose))
        want = Deformer(mesh, h, rings=rings, tol=1e-4).solve(T).vertices
        # the key is float32: its round-off, not the solve's, bounds the difference
        assert np.abs(shape - want).max() <= 1e-6 * np.abs(want).max()
    assert np.abs(a["shapes"][1] - a["shapes"][0]).max() > 0.05 * mesh.bounding_box_diagonal


def test_the_panel_draws_what_each_state_needs(tmp_path):
    """No window without a desktop: the panel draws into a stand-in layout that checks every
    property, vertex-group search and operator it names exists (tests/blender_scenes.py)."""
    seen, _ = run_scene("panel", tmp_path)
    names = {state: {tuple(x[:2]) for x in calls} for state, calls in seen.items()}
    assert ("prop", "r") in names["before"] and ("search", "rigidity_group") not in names[
        "before"]
    assert ("search", "rigidity_group") in names["painted, running"]
    assert not {("prop", "r"), ("prop", "r_min"), ("search", "rigidity_group")} & names[
        "sr-arap"]  # a method without a rigidity map shows no rigidity controls
    assert ("operator", "object.arap_stop") not in names["before"]
    assert ("operator", "object.arap_stop") in names["painted, running"]
    for state in seen:  # the handle list: group, kind, and for a moving one its object, bone
        assert {("search", "group"), ("prop", "kind"), ("prop", "target"),
                ("search", "bone"), ("list", "handles")} <= names[state]


def test_bad_input_is_one_line_in_the_report_and_the_mesh_is_kept(tmp_path):
    results, _ = run_scene("bad", tmp_path)
    expected = {
        "no handles": "Bar: no handle groups",
        "no fixed group": "Bar: no fixed group",
        "empty group": "Bar: vertex group 'Tip' is empty",
        "missing group": "Bar: there is no vertex group 'Nope'",
        "no object": "Bar: moving group 'Tip' has no object to follow",
        "edit mode": "Bar: leave Edit Mode first",
        "no rigidity group": "Bar: Rigidity is Painted but no rigidity group is chosen",
    }
    for case, words in expected.items():
        r = results[case]
        assert r["result"] == ["CANCELLED"], case
        msg = r["message"].strip()
        assert msg.startswith("Error: ") and words in msg and "\n" not in msg, (case, msg)
        assert r["untouched"] and r["keys"] is None, case  # no shape key was even made
    # a non-manifold fin and a loose vertex: solved, and the report says so
    fin = results["non-manifold"]
    assert fin["result"] == ["FINISHED"] and fin["untouched"], fin
    assert fin["nonmanifold_edges"] == 1
    assert "1 non-manifold edge(s)" in fin["message"]
    assert "referenced by no face" in fin["message"]
    assert "solved as Blender's triangles" in fin["message"]


# ------------------------------------------------------------------------- the extension
@pytest.fixture(scope="module")
def extension(tmp_path_factory) -> Path:
    """The linux-x64 zip, built as ``make blender-addon`` builds it (wheels from PyPI)."""
    out = tmp_path_factory.mktemp("dist")
    done = subprocess.run([sys.executable, str(ROOT / "blender" / "build.py"),
                           "--platform", "linux-x64", "--out", str(out)],
                          capture_output=True, text=True, timeout=900)
    if done.returncode != 0 and "download" in done.stderr:
        pytest.skip(f"cannot download the wheels from PyPI: {done.stderr.strip()[-300:]}")
    assert done.returncode == 0, done.stderr[-3000:]
    (zip_path,) = out.glob("arapkit-*-linux_x64.zip")
    return zip_path


def _blender_ext() -> Path:
    """Blender's own extension tool (it validates and builds extensions), found in bpy's
    files without importing bpy here."""
    spec = importlib.util.find_spec("bpy")
    found = list(Path(spec.origin).parent.glob("*/scripts/addons_core/bl_pkg/cli/"
                                               "blender_ext.py"))
    if not found:
        pytest.skip("this bpy has no extension tool (bl_pkg/cli/blender_ext.py)")
    return found[0]


def _requirements(wheel: bytes) -> set[str]:
    """The distributions a wheel requires unconditionally (no extra, no marker)."""
    import io
    import re

    with zipfile.ZipFile(io.BytesIO(wheel)) as w:
        meta = next(n for n in w.namelist() if n.endswith(".dist-info/METADATA"))
        lines = w.read(meta).decode().splitlines()
    out = set()
    for line in lines:
        if line.startswith("Requires-Dist:") and ";" not in line:
            name = re.match(r"[A-Za-z0-9._-]+", line.split(":", 1)[1].strip()).group(0)
            out.add(name.lower().replace("_", "-"))
    return out


def test_the_zip_has_a_valid_manifest_and_its_wheels(extension):
    done = subprocess.run([sys.executable, str(_blender_ext()), "validate", str(extension)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and "Success" in done.stdout, done.stdout + done.stderr
    with zipfile.ZipFile(extension) as z:
        names = set(z.namelist())
        manifest = tomllib.loads(z.read("blender_manifest.toml").decode())
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert manifest["id"] == "arapkit" and manifest["type"] == "add-on"
    assert manifest["version"] == project["version"]
    assert manifest["blender_version_min"] == "4.2.0"
    assert manifest["platforms"] == ["linux-x64"]
    wheels = {w.removeprefix("./") for w in manifest["wheels"]}
    assert wheels == {n for n in names if n.startswith("wheels/")}, "listed != packed"
    dists = {Path(w).name.split("-")[0].lower().replace("_", "-") for w in wheels}
    core = {d.split(">")[0].split("=")[0].strip().lower() for d in project["dependencies"]}
    assert dists >= (core - {"numpy"}) | {"arapkit"} and "numpy" not in dists  # Blender's
    # every wheel's own requirements are in the zip too (or are Blender's numpy)
    with zipfile.ZipFile(extension) as z:
        for w in sorted(wheels):
            for need in _requirements(z.read(w)):
                assert need in dists | {"numpy"}, f"{w} needs {need}, which is not bundled"
    for w in wheels:
        tag = Path(w).stem.split("-")[-1]
        assert tag == "any" or "x86_64" in tag and "linux" in tag, w
        assert Path(w).stem.split("-")[-3] in ("py3", "cp311"), w
    assert {"__init__.py", "engine.py", "ops.py", "props.py", "ui.py"} <= names


def test_the_zip_installs_into_a_clean_blender_and_deforms(extension, tmp_path):
    """Install from Disk, then a new session: the bundled wheels (not this checkout, not
    the test environment's packages) import and solve."""
    spec = importlib.util.find_spec("bpy")
    site = Path(spec.origin).parent.parent
    clean = tmp_path / "path"
    clean.mkdir()
    for name in ("bpy", "numpy", "numpy.libs"):  # Blender and the numpy it ships: nothing else
        if (site / name).exists():
            (clean / name).symlink_to(site / name)
    env = {"PYTHONPATH": str(clean), "BLENDER_USER_RESOURCES": str(tmp_path / "user")}
    # -S: no site-packages, so no package of this environment (arapkit included) is seen
    info, _ = run_scene("install", tmp_path / "install", str(extension), env=env,
                        flags=("-S",))
    assert info["result"] == ["FINISHED"]
    info, a = run_scene("installed", tmp_path / "run", env=env, flags=("-S",))
    site_ext = str(tmp_path / "user" / "extensions" / ".local")
    for module, path in info["files"].items():
        assert path.startswith(site_ext), f"{module} from {path}, not the extension"
    # the compiled kernels are kept in the extension's user folder, for the next session
    cache = tmp_path / "user" / "extensions" / ".user" / "user_default" / "arapkit"
    assert list(cache.rglob("*.nbi")), f"no numba cache in {cache}"
    mesh = Mesh(a["rest"], a["tris"])
    want = Deformer(mesh, a["handles"], rings=a["rings"], tol=1e-4).solve(a["targets"])
    assert np.abs(a["shape"] - want.vertices).max() <= SAME * mesh.bounding_box_diagonal
    assert np.abs(a["shape"] - a["rest"]).max() > 0.1 * mesh.bounding_box_diagonal
