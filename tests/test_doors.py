"""Every method through every interface that offers it: the method x interface matrix.

The matrix is generated from the method registry (:mod:`arapkit.methods.registry`: the
methods, :data:`~arapkit.methods.registry.INTERFACES`,
:data:`~arapkit.methods.registry.VOLUMETRIC_INTERFACES`) and the editor's selector
(:func:`arapkit.editor.settings.solver_choices`), so a newly registered method joins it and
an interface that claims a method but cannot run it fails here. A cell either runs (exit 0,
finite, deformed, handles met: to round-off for hard constraints, within the method's
``handle_tol`` for soft ones) or is refused with its one-line message (exit 2 on the
command line). Every cell runs on the example mesh and, for the doors that take one, on the
example point cloud (``examples/cactus-points.ply``): a method defined on triangles (the
registry's ``needs_faces``), a volume or a Laplacian start is refused there.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from arapkit import Deformer
from arapkit.errors import InputError
from arapkit.io import load_handles, load_mesh, save_rings
from arapkit.methods.registry import (
    INTERFACES,
    VOLUMETRIC_INTERFACES,
    method,
    method_names,
    methods,
)

ROOT = Path(__file__).resolve().parents[1]
MESH = ROOT / "examples" / "cactus.off"
HANDLES = ROOT / "examples" / "cactus.json"
#: the same cactus as a point cloud (the same handle file selects on its points)
CLOUD = ROOT / "examples" / "cactus-points.ply"
#: the shape file of each domain
SHAPES = {"mesh": MESH, "cloud": CLOUD}
#: a rigid left arm (held by its hand's handles) and a right arm with one shared rotation
GROUPS = ROOT / "examples" / "cactus-groups.json"
#: a rigid part keeps its edge lengths to this, relative to each edge
RIGID_TOL = 1e-9
#: hard constraints: met to round-off of the bounding-box diagonal
HARD_TOL = 1e-9
#: free vertices must move at least this much (relative to the diagonal): the arms swing
MIN_MOTION = 0.02
#: what a door that can name a method it does not offer says
NOT_OFFERED = {"library": "unknown energy", "cli": "unknown energy",
               "batch": "is not available in this build", "torch": "is not available in ARAPLayer"}


@dataclass(frozen=True)
class Variant:
    """One way to ask for a method: energy, rigidity (1, 3 or the mixed map), options."""

    energy: str
    rings: str = "1"
    volumetric: bool = False
    init: str = "identity"
    domain: str = "mesh"
    groups: bool = False

    @property
    def id(self) -> str:
        extra = [f"r{self.rings}"] if self.rings != "1" else []
        extra += ["volumetric"] * self.volumetric + (["laplacian-init"] if self.init !=
                                                      "identity" else [])
        extra += ["groups"] * self.groups
        return "-".join([*(["cloud"] if self.domain == "cloud" else []), self.energy, *extra])

    def refusal(self, interface: str) -> str | None:
        """The fragment of the one-line refusal this cell must give; None if it runs."""
        can = method(self.energy)
        if self.volumetric and interface not in VOLUMETRIC_INTERFACES:
            return "unknown key 'volumetric'"
        if interface not in can.interfaces:
            return NOT_OFFERED[interface]
        if self.domain == "cloud":
            if not can.applies_to(False):
                return "needs a triangle mesh"
            if self.volumetric:
                return "fills a closed triangle surface"
            if self.init == "laplacian":
                return "(Laplacian editing) needs a triangle mesh"
        if self.volumetric and not can.volumetric:
            return "volumetric=True runs r-ring ARAP"
        if self.rings != "1" and not can.rigidity_map:
            return "has no rigidity map"
        if self.groups and not can.groups:
            return "takes no vertex groups"
        return None


def _variants() -> list[Variant]:
    """Every method at r = 1, r = 3, the mixed map, volumetric, Laplacian init.

    The volume is asked for with the mixed map where the method has one (as ``compare``
    runs it), so that a refusal has one reason.
    """
    out = []
    for e in method_names():
        vol_r = "mixed" if method(e).rigidity_map else "1"
        out += [Variant(e), Variant(e, "3"), Variant(e, "mixed"),
                Variant(e, vol_r, volumetric=True), Variant(e, init="laplacian"),
                # rigid parts and shared rotations, with the mixed map where there is one
                Variant(e, vol_r, groups=True)]
    # on the point cloud: each cell with one reason to refuse (a method on triangles is
    # asked for plainly; the others as on the mesh)
    for e in method_names():
        can = method(e)
        out.append(Variant(e, domain="cloud"))
        if can.applies_to(False):
            out += [Variant(e, "3", domain="cloud"), Variant(e, "mixed", domain="cloud"),
                    Variant(e, volumetric=True, domain="cloud"),
                    Variant(e, init="laplacian", domain="cloud")]
    return out


#: which interfaces can even express a variant (the editor has no "--init"; compare and the
#: editor take no method name for a method they do not list, the layer has no volume)
def _expressible(v: Variant, interface: str) -> bool:
    can = method(v.energy)
    if v.domain == "cloud":
        if interface == "blender":  # Blender's objects are meshes
            return False
        if interface in ("compare", "editor"):  # they list only what applies to a cloud
            return (interface in can.interfaces and can.applies_to(False)
                    and not v.volumetric and v.init == "identity"
                    and (v.rings == "1" or can.rigidity_map))
    if interface == "compare":  # runs its fixed set: nothing to ask, nothing to refuse
        from arapkit.workflows.compare import RINGS_METHOD

        return interface in can.interfaces and v.refusal(interface) is None \
            and v.init == "identity" and (v.rings == "1" or v.energy == RINGS_METHOD) \
            and not v.groups
    if interface == "editor":  # painted r and groups are ignored by methods without them
        return interface in can.interfaces and v.init == "identity" and (
            v.rings == "1" or can.rigidity_map) and (not v.volumetric or can.volumetric) \
            and (not v.groups or can.groups)
    if interface == "torch":
        return not v.volumetric and v.init == "identity"
    if interface == "blender":  # its Method menu lists only what it offers; no volume, no init
        return interface in can.interfaces and v.init == "identity" and not v.volumetric and (
            v.rings == "1" or can.rigidity_map) and not v.groups
    return True


def _editor_panel_choices() -> list:
    from arapkit.editor.settings import solver_choices

    return [pytest.param(c, id=c.label) for c in solver_choices()]


CELLS = [pytest.param(v, i, id=f"{v.id}@{i}") for v in _variants() for i in INTERFACES
         if _expressible(v, i)]


# ------------------------------------------------------------------------------- the case


@cache
def _case(domain: str = "mesh"):
    from arapkit.io import load_shape

    mesh = load_mesh(MESH) if domain == "mesh" else load_shape(CLOUD)
    hs = load_handles(HANDLES, mesh.vertices)
    # stiff arms, soft trunk: a per-vertex map with both values
    mixed = np.where(mesh.vertices[:, 1] > 6.0, 3, 1).astype(np.int32)
    return mesh, hs, mixed


def _rings(v: Variant):
    _, _, mixed = _case(v.domain)
    return mixed if v.rings == "mixed" else int(v.rings)


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("doors")
    for domain in SHAPES:
        _, _, mixed = _case(domain)
        save_rings(d / f"mixed-{domain}.txt", mixed)
    return d


def _check_deformed(v: Variant, V: np.ndarray) -> None:
    """Finite, deformed beyond the handles, handles at their targets, rigid parts rigid."""
    mesh, hs, _ = _case(v.domain)
    diag = mesh.bounding_box_diagonal
    assert V.shape == mesh.vertices.shape and np.isfinite(V).all()
    free = np.setdiff1d(np.arange(mesh.n_vertices), hs.indices)
    assert np.linalg.norm(V[free] - mesh.vertices[free], axis=1).max() > MIN_MOTION * diag
    err = np.linalg.norm(V[hs.indices] - hs.targets, axis=1).max()
    assert err <= max(method(v.energy).handle_tol, HARD_TOL) * diag
    if v.groups:
        g = _groups()
        E = mesh.edges[np.isin(mesh.edges, g.members(int(np.argmax(g.rigid)))).all(axis=1)]
        rest = np.linalg.norm(mesh.vertices[E[:, 0]] - mesh.vertices[E[:, 1]], axis=1)
        now = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
        assert np.abs(now / rest - 1).max() < RIGID_TOL


@cache
def _groups():
    from arapkit.io import load_groups

    return load_groups(GROUPS, _case()[0])


# ---------------------------------------------------------------------------- interfaces


def _library(v: Variant, folder: Path) -> np.ndarray:
    mesh, hs, _ = _case(v.domain)
    kw = {"volumetric": True} if v.volumetric else {}
    if v.groups:
        kw["groups"] = _groups()
    d = Deformer(mesh, hs.indices, rings=_rings(v), energy=v.energy, init=v.init, **kw)
    return d.solve(hs.targets).vertices


def _ply(path: Path) -> np.ndarray:
    from arapkit.io import read_ply_vertex_properties

    p = read_ply_vertex_properties(path)
    return np.stack([p["x"], p["y"], p["z"]], axis=1)


def _cli_rings(v: Variant, folder: Path) -> list[str]:
    return [] if v.rings == "1" else (["--rings", v.rings] if v.rings != "mixed"
                                      else ["--rings-file", str(folder / f"mixed-{v.domain}.txt")])


def _deform(v: Variant, folder: Path, capsys) -> np.ndarray:
    from arapkit.cli import main

    out = folder / f"{v.id}.ply"
    argv = ["deform", str(SHAPES[v.domain]), "--handles", str(HANDLES), "--energy", v.energy,
            *_cli_rings(v, folder), "--init", v.init, *(["--volumetric"] * v.volumetric),
            *(["--groups", str(GROUPS)] * v.groups), "-o", str(out), "-q", "--force"]
    capsys.readouterr()
    code = main(argv)
    err = capsys.readouterr().err.strip()
    if code != 0:
        assert code == 2 and len(err.splitlines()) == 1, err
        raise InputError(err)
    return _ply(out)


@cache
def _compare_run(folder: Path, domain: str = "mesh") -> tuple[dict, Path]:
    """``arapkit compare`` once, with r = 3, the mixed map and (a mesh) the volume:
    label -> kw."""
    from arapkit.cli import main
    from arapkit.workflows.compare import method_list

    out = folder / f"compare-{domain}"
    volume = domain == "mesh"
    code = main(["compare", str(SHAPES[domain]), "--handles", str(HANDLES), "--rings", "3",
                 "--rings-file", str(folder / f"mixed-{domain}.txt"),
                 *(["--volumetric"] * volume), "-o", str(out), "--quiet"])
    assert code == 0
    _, _, mixed = _case(domain)
    return dict(method_list(3, mixed, volumetric=volume, has_faces=volume)), out


def _compare(v: Variant, folder: Path, capsys) -> np.ndarray:
    from arapkit.cli.compare import _slug

    labels, out = _compare_run(folder, v.domain)
    want = _rings(v)

    n = _case(v.domain)[0].n_vertices

    def same(kw: dict) -> bool:
        return (kw["energy"] == v.energy and bool(kw.get("volumetric")) == v.volumetric
                and np.array_equal(np.broadcast_to(kw.get("rings", 1), n),
                                   np.broadcast_to(want, n)))

    hits = [label for label, kw in labels.items() if same(kw)]
    assert len(hits) == 1, f"compare does not run {v.id}: {list(labels)}"
    return _ply(out / f"{_slug(hits[0])}.ply")


def _batch(v: Variant, folder: Path, capsys) -> np.ndarray:
    from arapkit.workflows.batch import normalise_job, run_job

    job = {"mesh": str(SHAPES[v.domain]), "handles": str(HANDLES), "energy": v.energy,
           "init": v.init, "output": f"{v.id}.ply"}
    if v.rings == "mixed":
        job["rings_file"] = str(folder / f"mixed-{v.domain}.txt")
    else:
        job["rings"] = int(v.rings)
    if v.volumetric:
        job["volumetric"] = True
    if v.groups:
        job["groups"] = str(GROUPS)
    row = run_job(normalise_job(job, folder), folder / "batch", resume=False)
    if row["status"] != "ok":
        assert row["status"] == "failed" and "\n" not in row["error"]
        raise InputError(row["error"])
    return _ply(folder / "batch" / job["output"])


def _editor(v: Variant, folder: Path, capsys) -> np.ndarray:
    from arapkit.editor.settings import SolverSettings, solver_choices
    from arapkit.editor.worker import SolveRequest, SolveWorker

    mesh, hs, _ = _case(v.domain)
    assert any((c.method, c.volumetric) == (v.energy, v.volumetric)
               for c in solver_choices(mesh.faces is not None))
    updates = []
    w = SolveWorker(updates.append)
    w.start()
    try:
        painted = np.broadcast_to(_rings(v), (mesh.n_vertices,)).astype(np.int32)
        w.submit(SolveRequest(mesh, hs.indices, hs.targets, painted,
                              SolverSettings(method=v.energy, volumetric=v.volumetric,
                                             max_iter=1000),
                              groups=_groups() if v.groups else None))
        assert w.wait_idle(300)
    finally:
        w.stop()
    last = updates[-1]
    assert last.final
    if last.error is not None:
        raise InputError(last.error)
    return last.vertices


def _torch(v: Variant, folder: Path, capsys) -> np.ndarray:
    torch = pytest.importorskip("torch", reason="PyTorch not installed")
    from arapkit.torch import ARAPLayer

    mesh, hs, _ = _case(v.domain)
    layer = ARAPLayer(mesh, hs.indices, rings=_rings(v), energy=v.energy,
                      dtype=torch.float64, **({"groups": _groups()} if v.groups else {}))
    return layer(torch.tensor(hs.targets)).detach().numpy()


def _rigid_fit(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """The 4x4 rigid motion taking points P to Q (Kabsch): a handle object's motion."""
    p0, q0 = P.mean(axis=0), Q.mean(axis=0)
    U, _, Vt = np.linalg.svd((P - p0).T @ (Q - q0))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    M = np.eye(4)
    M[:3, :3] = Vt.T @ D @ U.T
    M[:3, 3] = q0 - M[:3, :3] @ p0
    return M


def _blender(v: Variant, folder: Path, capsys) -> np.ndarray:
    """The add-on's path without Blender: groups as weights, objects as motions, the
    painted map as weights mapped to r (tests/test_blender_addon.py runs it in Blender)."""
    from arapkit.blender import GroupHandle, LiveDeformer, make_rig, method_items

    mesh, hs, _ = _case()
    assert v.energy in [name for name, _, _ in method_items()]
    groups, motions = [], []
    for g in hs.groups:
        w = np.zeros(mesh.n_vertices)
        w[g.indices] = 1.0
        moving = not np.array_equal(g.targets, mesh.vertices[g.indices])
        groups.append(GroupHandle(g.name, "moving" if moving else "fixed", w))
        if moving:
            motions.append(_rigid_fit(mesh.vertices[g.indices], g.targets))
    rig = make_rig(mesh.n_vertices, groups, "cactus")
    live = LiveDeformer(mesh, rig.handles, _rings(v), method=v.energy)
    try:
        live.request(rig.targets(mesh.vertices, motions), exact=True)
        shape = live.wait(300)
    finally:
        live.close()
    if shape.error is not None:
        raise InputError(shape.error)
    return shape.vertices


DRIVERS = {"library": lambda v, folder, capsys: _library(v, folder), "cli": _deform,
           "compare": _compare, "batch": _batch, "editor": _editor, "torch": _torch,
           "blender": _blender}


def test_every_interface_has_a_driver():
    """An interface added to the library's list must be added to the matrix too."""
    assert set(INTERFACES) == set(DRIVERS)


@pytest.mark.parametrize("variant, interface", CELLS)
def test_door(variant: Variant, interface: str, folder: Path, capsys):
    if interface == "batch":
        pytest.importorskip("distributed", reason="batch jobs need arapkit[batch]")
    if variant.volumetric:
        from arapkit.methods.volumetric import have_mesher

        if not have_mesher():
            pytest.skip("volumetric ARAP needs pip install 'arapkit[volume]'")
    refusal = variant.refusal(interface)
    if refusal is None:
        _check_deformed(variant, DRIVERS[interface](variant, folder, capsys))
        return
    with pytest.raises(InputError) as exc:
        DRIVERS[interface](variant, folder, capsys)
    msg = str(exc.value)
    assert refusal in msg and "\n" not in msg


def test_cli_embedded_with_default_options_writes_its_report(folder, capsys):
    """``deform --energy embedded`` (defaults) runs and reports the handle residual."""
    from arapkit.cli import main

    out, report = folder / "emb.ply", folder / "emb.json"
    code = main(["deform", str(MESH), "--handles", str(HANDLES), "--energy", "embedded",
                 "-o", str(out), "--report", str(report), "-q", "--force"])
    assert code == 0, capsys.readouterr().err
    rep = json.loads(report.read_text())
    mesh, hs, _ = _case()
    V = _ply(out)
    err = np.linalg.norm(V[hs.indices] - hs.targets, axis=1).max()
    assert rep["result"]["max_handle_error"] == pytest.approx(err, rel=1e-6)
    assert rep["result"]["energy_is_sum_of_squares"] is True
    assert rep["method"] == {"energy": "embedded", "nodes": 200}


@pytest.mark.parametrize("choice", _editor_panel_choices())
def test_every_editor_panel_method_solves(choice):
    """Each entry of the editor's method selector (Laplacian editing included) deforms."""
    from arapkit.editor.settings import SolverSettings
    from arapkit.editor.worker import SolveRequest, SolveWorker

    mesh, hs, mixed = _case()
    method = choice.method
    if choice.volumetric:
        from arapkit.methods.volumetric import have_mesher

        if not have_mesher():
            pytest.skip("volumetric ARAP needs pip install 'arapkit[volume]'")
    updates = []
    w = SolveWorker(updates.append)
    w.start()
    try:
        w.submit(SolveRequest(mesh, hs.indices, hs.targets, mixed,
                              SolverSettings(method=method, volumetric=choice.volumetric,
                                             max_iter=1000)))
        assert w.wait_idle(300)
    finally:
        w.stop()
    last = updates[-1]
    assert last.final and last.error is None
    energy = method if method in method_names() else "rring"  # the others: hard constraints
    _check_deformed(Variant(energy), last.vertices)


def test_laplacian_editing_library():
    """The library's Laplacian editor on the same case: exact handles, deformed."""
    from arapkit import LaplacianEditor

    mesh, hs, _ = _case()
    _check_deformed(Variant("rring"), LaplacianEditor(mesh, hs.indices).solve(hs.targets))


def test_batch_report_command_reproduces_the_job(folder, capsys):
    """The ``deform`` command a batch report records names the method and its options."""
    pytest.importorskip("distributed", reason="batch jobs need arapkit[batch]")
    from arapkit.cli import main
    from arapkit.workflows.batch import normalise_job, report_path, run_job

    job = {"mesh": str(MESH), "handles": str(HANDLES), "energy": "embedded", "nodes": 50,
           "output": "cmd.ply"}
    row = run_job(normalise_job(job, folder), folder / "batch", resume=False)
    assert row["status"] == "ok", row["error"]
    command = json.loads(report_path(folder / "batch" / "cmd.ply").read_text())["command"]
    again = folder / "again.ply"
    argv = command[1:command.index("-o")] + ["-o", str(again), "-q", "--force"]
    assert main(argv) == 0, capsys.readouterr().err
    assert np.array_equal(_ply(again), _ply(folder / "batch" / "cmd.ply"))


# ------------------------------------------------------------------------ the 2D rows
# (issue 48) every method the registry marks ``planar`` through each door that offers it, on
# a planar mesh: solved in its plane, handles met, no triangle turned over; and the doors
# that are 2D only: warp (library and command line) and the 2D editor.

PLANAR = [m.name for m in methods() if m.planar]
PLANAR_DOORS = ("library", "cli", "batch", "editor", "torch")


@cache
def _planar_case(folder: Path):
    from arapkit.io import save_mesh
    from arapkit.mesh.shapes2d import strip, strip_ends

    m = strip(segments=(24, 6))
    left, right = strip_ends(m)
    V = m.vertices
    path = folder / "strip.obj"
    save_mesh(path, V, m.faces)
    hpath = folder / "strip-handles.json"
    hpath.write_text(json.dumps([
        {"name": "held", "indices": left.tolist()},
        {"name": "bent", "indices": right.tolist(), "translate": [-1.0, 1.5, 0.0]}]))
    return m, path, hpath, load_handles(hpath, V)


def _check_planar(m, hs, V: np.ndarray, folds: int = 0) -> None:
    from arapkit.mesh.planar import signed_areas

    V = np.asarray(V, dtype=np.float64)
    assert np.isfinite(V).all() and V.shape[0] == m.n_vertices
    if V.shape[1] == 3:
        assert np.abs(V[:, 2]).max() == 0.0  # stayed in its plane
    P = V[:, :2]
    assert np.abs(P[hs.indices] - hs.targets[:, :2]).max() <= HARD_TOL * 5.0
    assert np.abs(P - m.vertices[:, :2]).max() > 0.5
    # nothing turned over (the torch layer, plain ARAP without the guard: as many as the
    # library's flips="allow")
    assert int((signed_areas(P, m.faces) <= 0).sum()) == folds


@pytest.mark.parametrize("energy, door", [(e, d) for e in PLANAR for d in PLANAR_DOORS
                                          if d in method(e).interfaces],
                         ids=lambda x: x)
def test_door_2d(energy: str, door: str, folder: Path, capsys):
    m, path, hpath, hs = _planar_case(folder)
    if door == "library":
        d = Deformer(m, hs.indices, energy=energy)
        assert d.dim == 2
        V = d.solve(hs.targets).vertices
    elif door == "cli":
        from arapkit.cli import main

        out = folder / f"strip-{energy}.ply"
        assert main(["deform", str(path), "--handles", str(hpath), "--energy", energy,
                     "-o", str(out), "-q", "--force"]) == 0
        V = _ply(out)
    elif door == "batch":
        pytest.importorskip("distributed", reason="batch jobs need arapkit[batch]")
        from arapkit.workflows.batch import normalise_job, run_job

        job = {"mesh": str(path), "handles": str(hpath), "energy": energy,
               "output": f"strip-{energy}-batch.ply"}
        row = run_job(normalise_job(job, folder), folder / "batch2d", resume=False)
        assert row["status"] == "ok", row
        V = _ply(folder / "batch2d" / job["output"])
    elif door == "editor":
        from arapkit.editor.settings import SolverSettings
        from arapkit.editor.worker import SolveRequest, SolveWorker

        updates = []
        w = SolveWorker(updates.append)
        w.start()
        try:
            w.submit(SolveRequest(m, hs.indices, hs.targets,
                                  np.ones(m.n_vertices, np.int32),
                                  SolverSettings(method=energy, max_iter=1000)))
            assert w.wait_idle(300)
        finally:
            w.stop()
        assert updates[-1].error is None, updates[-1].error
        V = updates[-1].vertices
    else:
        torch = pytest.importorskip("torch", reason="PyTorch not installed")
        from arapkit.torch import ARAPLayer

        layer = ARAPLayer((m.vertices[:, :2], m.faces), hs.indices, energy=energy,
                          dtype=torch.float64)
        assert layer.planar
        V = layer(torch.tensor(hs.targets[:, :2])).detach().numpy()
        assert V.shape == (m.n_vertices, 2)
        # the layer has no fold guard: it turns over what plain ARAP does (Smooth ARAP's
        # Laplacian term folds this strip's bend; the guarded library door does not)
        plain = Deformer(m, hs.indices, energy=energy, flips="allow").solve(
            hs.targets, tol=1e-8, max_iter=20000)
        _check_planar(m, hs, V, folds=plain.folds)
        return
    _check_planar(m, hs, V)


def test_warp_door_2d(folder: Path, capsys):
    """``warp_image`` and ``arapkit warp`` on the example sprite: the pins land."""
    pytest.importorskip("pythoncdt", reason="the image extra is not installed")
    from arapkit.cli import main
    from arapkit.image.pins import load_pins
    from arapkit.image.warp import ImageWarp

    pins = load_pins(ROOT / "examples" / "puppet-pins.json")
    w = ImageWarp(ROOT / "examples" / "puppet.png", pins.at)
    res = w.frame(pins.to, pins.turned, max_iter=1000)
    assert res.folds == 0 and np.abs(res.vertices[:len(pins.at)] - pins.to).max() < 1e-9
    out = folder / "waved.png"
    assert main(["warp", str(ROOT / "examples" / "puppet.png"), "--pins",
                 str(ROOT / "examples" / "puppet-pins.json"), "-o", str(out)]) == 0
    assert out.stat().st_size > 1000
