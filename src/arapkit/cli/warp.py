"""``arapkit warp``: puppet-warp an image by pins, or animate it by keyframes.

Examples
--------
::

    arapkit warp examples/puppet.png --pins examples/puppet-pins.json -o waved.png
    arapkit warp sprite.png --pins pins.json -o out.png --save-mesh out.obj --rigidity rigid
    arapkit warp examples/puppet.png --keyframes examples/puppet-keys.json -o wave.gif
"""

from __future__ import annotations

import argparse
from pathlib import Path

from arapkit.cli.common import add_example_epilog
from arapkit.errors import InputError, require_extra

__all__ = ["add_parser", "run"]


def _rigidity(text: str):
    return int(text) if text.strip().lstrip("-").isdigit() else text


def _colour(text: str) -> tuple[int, int, int]:
    t = text.strip().lstrip("#")
    try:
        if len(t) == 6:
            return tuple(int(t[i:i + 2], 16) for i in (0, 2, 4))
        parts = [int(v) for v in t.split(",")]
        if len(parts) == 3 and all(0 <= v <= 255 for v in parts):
            return tuple(parts)
    except ValueError:
        pass
    raise argparse.ArgumentTypeError(f"expected a colour as RRGGBB or R,G,B, got '{text}'")


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``warp``."""
    p = subparsers.add_parser(
        "warp",
        help="puppet-warp an image by pins (2D ARAP, no folded triangles)",
        description="Mesh the shape of IMAGE (its opaque part, or what differs from a key "
        "colour), move the pins of PINS.json (a list of {\"at\": [x, y], \"to\": [x, y]} in "
        "pixels, origin top left, y down; optional \"angle\" in degrees and \"depth\") and "
        "draw the warped picture. With --keyframes, render an animation (a .gif, an APNG "
        ".png, or PNG frames in a folder). Needs the image extra: pip install "
        "'arapkit[image]'.",
        **add_example_epilog([
            "arapkit warp examples/puppet.png --pins examples/puppet-pins.json -o waved.png",
            "arapkit warp examples/puppet.png --keyframes examples/puppet-keys.json -o wave.gif",
        ]),
    )
    p.add_argument("image", metavar="IMAGE", help="the picture (PNG with alpha, or any "
                   "format Pillow reads)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--pins", metavar="PINS.json", help="the pins of one frame")
    src.add_argument("--keyframes", metavar="KEYS.json", help="pins over time: "
                     '{"fps": 12, "keyframes": [{"time": 0, "pins": [...]}, ...]}')
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="the warped image (.png); with --keyframes a .gif, an APNG .png or "
                   "a folder of frames")
    p.add_argument("--save-mesh", metavar="MESH.obj", help="also write the warped triangle "
                   "mesh (z = 0) with the rest positions as UVs")
    p.add_argument("--density", type=float, metavar="PX", help="mesh edge length in pixels "
                   "(default: the shape's longer side / 40)")
    p.add_argument("--rigidity", type=_rigidity, default="normal", metavar="R",
                   help="distort, normal (default), rigid, or a number of rings r")
    p.add_argument("--key", type=_colour, metavar="RRGGBB", help="mesh every pixel away "
                   "from this colour (default: the alpha channel, or the top-left colour of "
                   "an image without transparency)")
    p.add_argument("--force", action="store_true", help="allow OUT to be the input")
    return p


def run(args: argparse.Namespace) -> int:
    """Run ``warp``."""
    require_extra(["PIL", "skimage", "shapely", "pythoncdt"], "image", "arapkit warp")
    from arapkit.image.pins import load_keyframes, load_pins
    from arapkit.image.warp import ImageWarp, render_keyframes, save_animation, save_image
    from arapkit.io.atomic import check_output_path

    out = Path(args.output)
    if args.pins is not None and out.suffix.lower() != ".png":
        raise InputError(f"{out}: a warped image is written as .png")
    if args.keyframes is None or out.suffix:
        check_output_path(out, [args.image], args.force)
    if args.save_mesh:
        check_output_path(args.save_mesh, [args.image], args.force, "mesh output")
        if Path(args.save_mesh).suffix.lower() != ".obj":
            raise InputError(f"{args.save_mesh}: the warped mesh is written as .obj")
    if args.pins is not None:
        pins = load_pins(args.pins)
        warp = ImageWarp(args.image, pins.at, spacing=args.density, rigidity=args.rigidity,
                         key=args.key)
        res = warp.frame(pins.to, pins.turned, pins.depth, max_iter=1000)
        save_image(out, res.image)
        what = f"{out}"
    else:
        keys = load_keyframes(args.keyframes)
        warp = ImageWarp(args.image, keys.keys[0].at, spacing=args.density,
                         rigidity=args.rigidity, key=args.key)
        frames = render_keyframes(warp, keys)
        files = save_animation(out, frames, keys.fps)
        what = f"{len(frames)} frames to {out}" + (f" ({len(files)} files)" if len(files) > 1
                                                    else "")
        res = None
    if args.save_mesh:
        warp.save_mesh(args.save_mesh)
    folds = "" if res is None or not res.folds else (
        f"; {res.folds} triangles folded (the pins admit no fold-free map)")
    print(f"warped {warp.name} ({warp.mesh.n_vertices} vertices, {len(warp.at)} pins): "
          f"wrote {what}{folds}")
    return 0
