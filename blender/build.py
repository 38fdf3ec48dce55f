"""Build the Blender extension zips: the add-on, arapkit and its dependencies as wheels.

``make blender-addon`` runs this. One zip per platform (Blender's own ``--split-platforms``
layout, ``dist/arapkit-<version>-<platform>.zip``), each holding ``blender_manifest.toml``
with its ``platforms`` and ``wheels``, the add-on's modules and ``wheels/``: the arapkit
wheel built from this checkout and its core dependencies downloaded from PyPI for Blender's
Python (3.11) on that platform. Blender installs the wheels from the zip, so nothing is
downloaded at install time.

NumPy is left out: Blender ships it, and a bundled copy would shadow Blender's own for every
add-on. The other wheels are resolved against the oldest NumPy a supported Blender ships
(:data:`BLENDER_NUMPY`, Blender 4.2's), so they import with Blender 4.2-5.0's.

Usage: ``python blender/build.py [--platform linux-x64 ...] [--out dist]`` (Python 3.11+
with pip; reaches PyPI).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import tomllib

ROOT = Path(__file__).resolve().parents[1]
ADDON = ROOT / "blender" / "arapkit_addon"
#: Blender 4.2-5.x run Python 3.11
PYTHON_VERSION = "3.11"
#: the oldest NumPy of a supported Blender (4.2 LTS ships 1.24.3; 4.5 and 5.0 ship 1.26)
BLENDER_NUMPY = "1.24.3"
#: Blender's platform names and the wheel platform tags pip may pick for each
PLATFORMS = {
    "linux-x64": ["manylinux_2_28_x86_64", "manylinux_2_27_x86_64", "manylinux_2_24_x86_64",
                  "manylinux_2_17_x86_64", "manylinux2014_x86_64"],
    "windows-x64": ["win_amd64"],
    "macos-arm64": ["macosx_11_0_arm64", "macosx_12_0_arm64", "macosx_13_0_arm64",
                    "macosx_14_0_arm64"],
    "macos-x64": [f"macosx_{v}_x86_64" for v in ("10_9", "10_13", "10_14", "10_15", "11_0",
                                                  "12_0", "13_0", "14_0")],
}
#: what Blender already has: never bundled
PROVIDED_BY_BLENDER = ("numpy",)


def project() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def _pip(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "pip", *args, "--disable-pip-version-check",
                    "--quiet"], check=True)


def arapkit_wheel(work: Path) -> Path:
    """The arapkit wheel of this checkout (pure Python)."""
    out = work / "arapkit-wheel"
    _pip("wheel", str(ROOT), "--no-deps", "--wheel-dir", str(out))
    (wheel,) = out.glob("arapkit-*.whl")
    return wheel


def dependency_wheels(platform: str, work: Path) -> list[Path]:
    """arapkit's core dependencies as cp311 wheels for ``platform``, NumPy left out."""
    out = work / platform
    tags = [a for tag in PLATFORMS[platform] for a in ("--platform", tag)]
    _pip("download", "--only-binary=:all:", "--python-version", PYTHON_VERSION,
         "--implementation", "cp", *tags, "--dest", str(out),
         f"numpy=={BLENDER_NUMPY}", *project()["dependencies"])
    return sorted(w for w in out.glob("*.whl")
                  if w.name.split("-")[0].lower() not in PROVIDED_BY_BLENDER)


def manifest(platform: str, wheels: list[Path]) -> str:
    """The add-on's manifest with this platform's ``platforms`` and ``wheels``."""
    text = (ADDON / "blender_manifest.toml").read_text()
    listed = ",\n".join(f'    "./wheels/{w.name}"' for w in wheels)
    return f'{text}\nplatforms = ["{platform}"]\nwheels = [\n{listed},\n]\n'


def build(platforms: list[str], out: Path) -> list[Path]:
    """Build one zip per platform into ``out``; return their paths."""
    meta = tomllib.loads((ADDON / "blender_manifest.toml").read_text())
    if meta["version"] != project()["version"]:
        raise SystemExit(f"blender_manifest.toml has version {meta['version']}, "
                         f"pyproject.toml {project()['version']}: make them agree")
    out.mkdir(parents=True, exist_ok=True)
    zips = []
    with tempfile.TemporaryDirectory(prefix="arapkit-blender-") as tmp:
        work = Path(tmp)
        own = arapkit_wheel(work)
        for platform in platforms:
            wheels = [own, *dependency_wheels(platform, work)]
            target = out / f"{meta['id']}-{meta['version']}-{platform.replace('-', '_')}.zip"
            part = target.with_suffix(".zip.part")  # whole or absent
            with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as z:
                z.writestr("blender_manifest.toml", manifest(platform, wheels))
                for module in sorted(ADDON.glob("*.py")):
                    z.write(module, module.name)
                for w in wheels:
                    # a wheel is compressed already: stored as it is
                    z.write(w, f"wheels/{w.name}", compress_type=zipfile.ZIP_STORED)
            part.replace(target)
            zips.append(target)
            size = target.stat().st_size / 2**20
            print(f"{target.relative_to(ROOT) if target.is_relative_to(ROOT) else target}: "
                  f"{len(wheels)} wheels, {size:.0f} MB")
    return zips


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--platform", action="append", choices=sorted(PLATFORMS),
                        help="a Blender platform (repeat; default: all of them)")
    parser.add_argument("--out", type=Path, default=ROOT / "dist", help="where the zips go")
    args = parser.parse_args(argv)
    try:
        build(args.platform or list(PLATFORMS), args.out)
    except subprocess.CalledProcessError as exc:
        print(f"blender/build.py: {' '.join(exc.cmd[2:5])} failed (exit {exc.returncode})",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
