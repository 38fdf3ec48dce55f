"""Old flat module paths keep working for one release (arapkit._compat and arapkit.mesh).

Every entry of ``_compat.MOVED`` imports, warns with a DeprecationWarning, and exposes every
public name the flat module had (its ``__all__`` and top-level public definitions, as of
arapkit 0.1).
"""

from __future__ import annotations

import importlib
import subprocess
import sys
import warnings

import pytest

from arapkit import _compat

#: the public names of the flat modules of arapkit 0.1
OLD_NAMES = {
    "accel": ["Anderson"],
    "attributes": ["MeshAttributes", "polygon_area_vectors", "recompute_normals"],
    "backend": ["CPUBackend", "gather_rhs", "local_step", "neighbourhood_energies", "scatter_rows"],
    "batch": ["INSTALL_HINT", "JOB_KEYS", "SUMMARY_COLUMNS", "augment_jobs", "dask_map",
        "dry_run", "job_hash", "job_spec", "load_jobs", "normalise_job", "report_path",
        "require_dask", "run", "run_job", "write_jobs", "write_summary"],
    "colors": ["ENERGY_CMAP", "RING_COLORS", "ring_rgb"],
    "compare": ["CSV_COLUMNS", "MethodRun", "comparison_figure", "comparison_rows", "format_rows",
        "method_list", "run_comparison", "write_csv"],
    "constraints": ["CholeskyFactor", "Elimination", "FREE_COMPONENT_POLICIES",
        "anchor_components", "check_handles", "check_targets", "follow_rigidly"],
    "embedded": ["DEFAULT_NODES", "EmbeddedDeformation", "K_NEAREST", "check_nodes",
        "sample_nodes"],
    "energy": ["ENERGIES", "LOCAL_GLOBAL", "NeighbourhoodEnergy", "energy_from_entries",
        "make_energy", "rest_term", "rring_energy"],
    "fileio": ["FIGURE_FORMATS", "MESH_FORMATS", "atomic_open", "atomic_write",
        "check_figure_format", "check_output_path", "mesh_format", "ply_property_column",
        "read_ply_vertex_properties", "save_mesh", "to_jsonable", "write_json"],
    "handles": ["COMMENT_KEY", "GROUP_KEYS", "HandleGroup", "HandleSet", "MOTION_KEYS",
        "SELECTION_KEYS", "handles_to_json", "load_def", "load_handles", "load_rings", "load_sel",
        "parse_handles", "rotation_matrix", "save_def", "save_handles", "save_rings", "save_sel",
        "select_box", "select_nearest", "select_sphere"],
    "jobs": ["DEFAULT_ENERGY", "DeformJob", "ENERGIES", "JobInputs", "PreparedJob", "job_report",
        "load_job_inputs", "method_description", "prepare_job", "save_result"],
    "laplacian": ["LaplacianEditor", "differential_operator", "laplacian_edit"],
    "loop": ["Result", "local_global"],
    "methods.decimation_child": ["homes", "simplify"],
    "meshwriters": ["write_with_attributes"],
    "orientation": ["AXES", "BoundingBox", "UpGuess", "VIEWS", "bounding_box", "guess_up",
        "parse_axis", "view_frame"],
    "problem": ["ARAPProblem", "EdgeGraph", "bandwidth_order", "unit_scale"],
    "quality": ["FOLD_DEGREES", "dihedral_angles", "enclosed_volume", "folded_edge_fraction",
        "volume", "volume_change"],
    "rings": ["MAX_RINGS", "Neighbourhoods", "build_neighbourhoods", "check_rings",
        "neighbourhoods_from_arrays", "rings_summary", "vertex_adjacency"],
    "rotations": ["fit_rotation_range", "fit_rotations", "rotation_from_covariance"],
    "shapes": ["bar", "bar_bend", "bar_two_materials"],
    "solver": ["CholeskyFactor", "DEVICES", "Deformer", "INITS", "Result", "anchor_components",
        "bandwidth_order", "check_handles", "check_method", "unit_scale"],
    "spokes_rims": ["face_edge_weights", "spokes_and_rims_energy"],
    "sr_arap": ["DEFAULT_ALPHA", "check_alpha", "sr_arap_energy", "surface_area"],
    "torch_backend": ["TorchBackend", "TorchSystem", "best_rotations", "check_dtype",
        "fit_rotations", "resolve_device"],
    "volume": ["CLAMP_FRACTION", "COARSE_TARGET", "DEFAULT_DENSITY", "DEFAULT_VOLUME_WEIGHTS",
        "ENVELOPE", "LATTICE_CLEARANCE", "MAX_LATTICE_CELLS", "MAX_LATTICE_POINTS", "MESHER_HINT",
        "MIN_EDGE_OVER_ENVELOPE", "TetMesh", "VOLUME_FORMATS", "VOLUME_WEIGHTS",
        "VolumetricDeformer", "check_closed", "extend_rings", "have_mesher", "interior_lattice",
        "lattice_spacing", "mesh_volume", "morton_codes", "save_volume", "tet_cotangent_weights",
        "tet_volume_weights", "tetrahedralise", "volume_graph"],
    "weights": ["CLAMP_FRACTION", "COT_CAP", "DEFAULT_WEIGHTS", "SOUND_WEIGHTS", "WEIGHT_KINDS",
        "cotangent_weights", "edge_weights", "voronoi_areas"],
    "welding": ["WELD_TOL", "WeldMap", "soup_facts", "to_source", "weld", "weld_frame",
        "weld_handle_set", "weld_handles", "weld_values"],
}

#: the flat ``arapkit.mesh`` module, now a package of the same name
OLD_MESH_NAMES = ["COORDINATE_RANGE", "EdgeTopology", "Mesh", "check_number_range",
                  "load_mesh", "scale_free_vertices", "weld"]


def _fresh_import(name: str):
    """Import ``name`` anew (the alias warns on creation), returning module and warnings."""
    sys.modules.pop(name, None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        module = importlib.import_module(name)
    return module, [w for w in caught if issubclass(w.category, DeprecationWarning)]


def test_old_path_warning_names_the_importing_file():
    """The warning points at the line that imports the old path, so a script sees it."""
    out = subprocess.run([sys.executable, "-c", "import arapkit.solver"], capture_output=True,
                         text=True, check=True)
    assert "<string>:1: DeprecationWarning: arapkit.solver moved to" in out.stderr


def test_every_old_module_is_listed():
    assert sorted(OLD_NAMES) == sorted(k.removeprefix("arapkit.") for k in _compat.MOVED)


#: old modules whose new home needs an optional extra, and that extra's import name
NEEDS = {"torch_backend": "torch"}


@pytest.mark.parametrize("old", sorted(OLD_NAMES))
def test_old_module_imports_with_warning_and_keeps_its_names(old):
    if old in NEEDS:
        pytest.importorskip(NEEDS[old], reason=f"arapkit.{old} needs {NEEDS[old]} "
                            "(pip install 'arapkit[torch]')")
    module, caught = _fresh_import(f"arapkit.{old}")
    assert caught and _compat.MOVED[f"arapkit.{old}"] in str(caught[0].message)
    missing = [n for n in OLD_NAMES[old] if not hasattr(module, n)]
    assert not missing, f"arapkit.{old} lost {missing}"


def test_old_io_paths_of_the_readme_and_scripts():
    with pytest.warns(DeprecationWarning):
        sys.modules.pop("arapkit.handles", None)
        from arapkit.handles import HandleSet, load_sel, select_box
    with pytest.warns(DeprecationWarning):
        sys.modules.pop("arapkit.fileio", None)
        from arapkit.fileio import atomic_open, load_numpy, read_ply_vertex_properties, save_mesh
    import arapkit.io as io

    assert (select_box, load_sel, HandleSet) == (io.select_box, io.load_sel, io.HandleSet)
    assert (save_mesh, atomic_open, read_ply_vertex_properties, load_numpy) == (
        io.save_mesh, io.atomic_open, io.read_ply_vertex_properties, io.load_numpy)


def test_attribute_access_through_arapkit():
    import arapkit

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        assert arapkit.handles.load_rings is importlib.import_module("arapkit.io").load_rings


def test_old_mesh_module_names():
    import arapkit.mesh as mesh

    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)  # the model's names: no warning
        for name in OLD_MESH_NAMES:
            if name != "load_mesh":
                assert hasattr(mesh, name), name
    with pytest.warns(DeprecationWarning, match="arapkit.io.readers.load_mesh"):
        from arapkit.mesh import load_mesh
    from arapkit.io import load_mesh as new

    assert load_mesh is new
    with pytest.raises(AttributeError):
        mesh.no_such_name  # noqa: B018
