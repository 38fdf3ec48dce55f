"""``arapkit edit``: start the browser editor on a mesh and print its address.

Examples
--------
>>> import argparse
>>> p = argparse.ArgumentParser(); sub = p.add_subparsers()
>>> a = add_parser(sub).parse_args(["bunny.off", "--port", "9000"])
>>> a.mesh, a.port, a.host
('bunny.off', 9000, '127.0.0.1')
"""

from __future__ import annotations

import argparse
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np

from arapkit.cli.common import add_example_epilog, graph_options, port, ring_size, upload_mb
from arapkit.errors import require_extra

_DESCRIPTION = """\
Start a local editor in the browser: pick handle regions (click or Shift+drag a rectangle),
drag their gizmos to deform the mesh live, paint the rigidity r with a brush or a paint
bucket, colour by r or by energy, undo/redo, save sessions and export the result.
Without MESH the built-in bar is opened with its left end fixed and its right end as a
handle. A picture (.png ...) or a planar mesh (one z) opens the 2D view: click to pin, drag
or turn pins, paint r or pick a preset, export the warped PNG, mesh and pins.
The server binds 127.0.0.1 unless --host says otherwise; press Ctrl-C to stop.
"""


EXAMPLES = [
    "arapkit edit                                  # the built-in bar, ends as handles",
    "arapkit edit examples/cactus.off --handles examples/cactus.json --rings 2",
    "arapkit edit examples/cactus.off --handles examples/cactus.json --groups "
    "examples/cactus-groups.json",
    "arapkit edit mesh.off --rings-file rings.txt --export-dir out --port 9000",
    "arapkit edit examples/puppet.png              # the 2D view: pin and warp a sprite",
    "arapkit edit --session out/mesh-session.json  # resume a saved session",
]


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register ``edit`` on an argparse subparsers object and return its parser."""
    p = subparsers.add_parser(
        "edit",
        help="interactive browser editor (drag handles, paint r)",
        description=_DESCRIPTION,
        **add_example_epilog(EXAMPLES),
    )
    p.add_argument(
        "mesh", nargs="?", metavar="MESH",
        help="OBJ/PLY/OFF/STL mesh, or a point cloud (a PLY/OBJ/OFF without faces, .xyz, "
        ".npy; docs/clouds.md) (default: the built-in bar)"
    )
    p.add_argument("--rings-file", metavar="R", help="per-vertex r (text, .npy or PLY 'rings')")
    p.add_argument(
        "--rings",
        "-r",
        type=ring_size,
        default=1,
        metavar="N",
        help="uniform r when no rings file is given (default 1)",
    )
    p.add_argument("--handles", "-H", metavar="H", help="handle file (JSON, or .sel with .def)")
    p.add_argument("--groups", "-G", metavar="G",
                   help="rigid parts and shared-rotation groups to start with (as for "
                   "arapkit deform --groups; paint more with the tool 'Paint part')")
    from arapkit.cli.common import add_graph_options, add_weld_option

    add_weld_option(p)
    add_graph_options(p)
    p.add_argument(
        "--session", metavar="S", help="editor session JSON to resume (names its own mesh)"
    )
    p.add_argument(
        "--port",
        type=port,
        default=8080,
        help="port (default 8080; the next free one is used when taken)",
    )
    p.add_argument(
        "--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)"
    )
    p.add_argument(
        "--export-dir",
        default="arapkit-edits",
        metavar="DIR",
        help="folder for exports and saved sessions (default ./arapkit-edits)",
    )
    p.add_argument(
        "--up",
        default=None,
        metavar="AXIS",
        help="axis shown up: +x, -x, +y, -y, +z or -z (write --up=-y); default: guessed "
        "from the mesh, as arapkit info prints it",
    )
    p.add_argument(
        "--max-upload-mb",
        type=upload_mb,
        default=64.0,
        metavar="MB",
        help="size cap for files uploaded from the page (default 64)",
    )
    return p


def build_state(args: argparse.Namespace, shape: Any = None) -> Any:
    """The editor state the command line asks for (raises InputError on bad files).

    ``shape``: ``args.mesh`` already loaded (as :func:`~arapkit.io.load_shape` loads it
    with the graph options), so that a large file is not read twice.

    Examples
    --------
    >>> ns = argparse.Namespace(mesh=None, rings_file=None, rings=2, handles=None,
    ...                         session=None)
    >>> st = build_state(ns)
    >>> [h.name for h in st.handles], int(st.rings[0])
    (['fixed end', 'free end'], 2)
    """
    from arapkit.editor.state import EditorState
    from arapkit.errors import InputError
    from arapkit.io import load_handles, load_rings, load_shape
    from arapkit.validate import ring_size as ring_size_rule

    if args.session:
        if args.mesh:
            raise InputError("give either MESH or --session (the session names its mesh)")
        if any(v is not None for v in graph_options(args).values()):
            raise InputError("--neighbours/--radius set the graph of a MESH given here; a "
                             "session keeps the graph it was made with")
        st = EditorState.from_session(args.session)
    elif args.mesh:
        from arapkit.cli.common import maybe_weld

        if shape is None:  # a file without faces: a point cloud, on the graph asked for
            shape = load_shape(args.mesh, **graph_options(args))
        if shape.faces is None and getattr(args, "weld", None) is not None:
            raise InputError(f"{args.mesh}: --weld merges a mesh's split vertices; a point "
                             "cloud has none")
        mesh = maybe_weld(shape, getattr(args, "weld", None))
        st = EditorState(mesh, mesh_path=str(Path(args.mesh).resolve()))
    else:
        st = _bar_state()
    ring_size_rule(args.rings, "--rings")
    if not args.session and args.rings != 1:
        st.rings = st.check_rings(args.rings)
    # vertex numbers in files given on the command line are the input's, also when welded
    welded = getattr(st.mesh, "welded_from", None)
    source = welded.source if welded is not None else st.mesh
    if args.rings_file:
        rings = load_rings(args.rings_file, source.n_vertices)
        if welded is not None:
            from arapkit.mesh.welding import weld_values

            rings = weld_values(st.mesh, rings)
        st.rings = st.check_rings(rings)
    if args.handles:
        hs = load_handles(args.handles, source.vertices,
                          welded=None if welded is None else st.mesh)
        st.add_handle_set(hs, record=False)
    if getattr(args, "groups", None):
        from arapkit.io import load_groups

        st.load_groups(load_groups(args.groups, source.vertices,
                                   welded=None if welded is None else st.mesh))
    st.clear_history()  # start-up choices are not undoable edits
    return st


def _bar_state() -> Any:
    from arapkit.editor.state import EditorState
    from arapkit.mesh.shapes import bar

    mesh = bar()
    st = EditorState(mesh)
    x = mesh.vertices[:, 0]
    tol = 1e-9 * (x.max() - x.min())  # relative: the caps at any scale
    st.add_handle(np.flatnonzero(x <= x.min() + tol), name="fixed end", frozen=True)
    st.add_handle(np.flatnonzero(x >= x.max() - tol), name="free end")
    return st


def _up(text: str | None) -> str | None:
    """``--up`` as the editor spells it ('y' = '+y'), or None to guess."""
    from arapkit.mesh.orientation import parse_axis

    if text is None:
        return None
    v = parse_axis(text)
    k = int(np.argmax(np.abs(v)))
    return ("+" if v[k] > 0 else "-") + "xyz"[k]


#: what ``arapkit edit`` opens in the 2D view (a picture is meshed from its alpha)
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".webp", ".bmp", ".gif", ".tif", ".tiff")


def _run_2d(args: argparse.Namespace, source: Any) -> int:
    """The 2D view (:mod:`arapkit.editor.sprite`) on a picture or a planar mesh."""
    from arapkit.editor.sprite import SpriteEditor

    app = SpriteEditor(source, host=args.host, port=args.port, export_dir=args.export_dir)
    what = "picture" if isinstance(source, str) else "planar mesh"
    print(f"arapkit 2D editor: {app.url}  ({what} {app.name}, {app.mesh.n_vertices} "
          f"vertices; exports go to {app.export_dir}; Ctrl-C to stop)", flush=True)
    try:
        threading.Event().wait()
    except KeyboardInterrupt:
        pass
    finally:
        app.stop()
    return 0


def run(args: argparse.Namespace) -> int:
    """Start the editor and serve until Ctrl-C."""
    # the editor serves with viser and colours energy with matplotlib's maps
    require_extra(("viser", "matplotlib"), "editor", "arapkit edit")
    loaded = None
    if args.mesh and not args.session:
        from arapkit.validate import host as check_host

        check_host(args.host, "--host")
        if Path(args.mesh).suffix.lower() in IMAGE_SUFFIXES:
            require_extra(["PIL", "skimage", "shapely", "pythoncdt"], "image",
                          "arapkit edit on a picture")
            return _run_2d(args, args.mesh)
        from arapkit.io import load_shape
        from arapkit.mesh.planar import is_planar

        # a file without faces is a point cloud: the 3D editor, whatever its shape
        loaded = load_shape(args.mesh, **graph_options(args))
        if (loaded.faces is not None and is_planar(loaded.vertices) and not args.handles
                and not args.rings_file):
            require_extra(["PIL", "skimage", "shapely", "pythoncdt"], "image",
                          "arapkit edit on a planar mesh")
            return _run_2d(args, loaded)
    from arapkit.editor.app import EditorApp
    from arapkit.mesh.cloud import counted
    from arapkit.validate import host

    host(args.host, "--host")  # before anything starts: a server that cannot bind hangs
    state = build_state(args, loaded)
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        print(
            f"arapkit: warning: serving on {args.host}: anyone who can reach this "
            "address can edit and write to the export folder",
            file=sys.stderr,
        )
    app = EditorApp(
        state,
        host=args.host,
        port=args.port,
        export_dir=args.export_dir,
        max_upload_mb=args.max_upload_mb,
        up=_up(getattr(args, "up", None)),
    )
    print(
        f"arapkit editor: {app.url}  ({'mesh' if state.mesh.faces is not None else 'point cloud'}"
        f" {state.mesh.name}, {counted(state.n, state.mesh)}; "
        f"exports go to {app.export_dir}; Ctrl-C to stop)",
        flush=True,
    )
    app.serve_forever()
    return 0
