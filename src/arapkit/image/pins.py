"""Pins and keyframes of an image warp: what ``--pins`` and ``--keyframes`` files hold.

A pins file is JSON, a list of pins in pixels of the image (origin top left, y down)::

    [{"at": [120, 80], "to": [150, 60]},
     {"at": [300, 400], "to": [300, 400], "angle": 30, "depth": 1}]

``at`` is where the pin is put on the picture, ``to`` where it is dragged; ``angle``
(degrees, counter-clockwise on screen) turns the pin's neighbourhood (Photoshop's pin
rotation); ``depth`` decides which part is in front where parts overlap (larger: nearer;
default 0). A keyframe file animates the same pins::

    {"fps": 12, "keyframes": [{"time": 0, "pins": [...]}, {"time": 1.5, "pins": [...]}]}

Every keyframe lists the same pins (the same ``at``, in the same order); ``to``, ``angle``
and ``depth`` are interpolated linearly between keyframes.

Examples
--------
>>> p = parse_pins([{"at": [1, 2], "to": [3, 4], "angle": 90}], "pins.json")
>>> p.at.tolist(), p.to.tolist(), round(float(p.angles[0]), 4)
([[1.0, 2.0]], [[3.0, 4.0]], -1.5708)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..validate import parse_json, read_input

__all__ = ["Keyframes", "Pins", "load_keyframes", "load_pins", "parse_keyframes", "parse_pins"]


@dataclass(frozen=True)
class Pins:
    """Pins of one frame.

    Attributes
    ----------
    at, to : (p, 2) float
        Where each pin is on the picture, and where it goes (pixels).
    angles : (p,) float
        The turn of each pin in radians in the solver's frame (NaN: none). The image's y
        points down, so a counter-clockwise turn on screen is a negative angle there.
    depth : (p,) float
        Larger is nearer.
    """

    at: np.ndarray
    to: np.ndarray
    angles: np.ndarray
    depth: np.ndarray

    @property
    def turned(self) -> np.ndarray | None:
        """The angles, or None when no pin turns."""
        return None if np.isnan(self.angles).all() else self.angles


def _point(value, where: str) -> list[float]:
    if (not isinstance(value, (list, tuple)) or len(value) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
            or not all(math.isfinite(v) for v in value)):
        raise InputError(f"{where}: expected two finite numbers [x, y], got {value!r}")
    return [float(value[0]), float(value[1])]


def _scalar(value, where: str) -> float:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
        raise InputError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def parse_pins(data, name: str = "pins") -> Pins:
    """Pins from decoded JSON (a list of ``{"at", "to", "angle"?, "depth"?}``)."""
    if not isinstance(data, list) or not data:
        raise InputError(f"{name}: expected a non-empty list of pins "
                         '[{"at": [x, y], "to": [x, y]}, ...]')
    at, to, ang, dep = [], [], [], []
    for i, pin in enumerate(data):
        where = f"{name}: pin {i}"
        if not isinstance(pin, dict):
            raise InputError(f"{where}: expected an object with \"at\" and \"to\"")
        unknown = sorted(set(pin) - {"at", "to", "angle", "depth"})
        if unknown:
            raise InputError(f"{where}: unknown key {unknown[0]!r} (use at, to, angle, depth)")
        if "at" not in pin:
            raise InputError(f"{where}: missing \"at\"")
        at.append(_point(pin["at"], f"{where} \"at\""))
        to.append(_point(pin.get("to", pin["at"]), f"{where} \"to\""))
        a = pin.get("angle")
        ang.append(math.nan if a is None else -math.radians(_scalar(a, f"{where} \"angle\"")))
        dep.append(_scalar(pin.get("depth", 0.0), f"{where} \"depth\""))
    A = np.array(at)
    key = [tuple(p) for p in at]
    if len(set(key)) != len(key):
        first = next(i for i, k in enumerate(key) if key.index(k) != i)
        raise InputError(f"{name}: pin {first} is at the same place as pin {key.index(key[first])}")
    return Pins(A, np.array(to), np.array(ang), np.array(dep))


def load_pins(path) -> Pins:
    """Pins from a JSON file (one-line errors name the file and the pin)."""
    return parse_pins(parse_json(read_input(Path(path), "pins files"), str(path)), str(path))


@dataclass(frozen=True)
class Keyframes:
    """Pins over time: the frames of an animation.

    Attributes
    ----------
    times : (k,) float
        Keyframe times in seconds, increasing.
    keys : list of Pins
        The pins at each keyframe (the same ``at``).
    fps : float
        Frames per second of the rendering.
    """

    times: np.ndarray
    keys: list[Pins]
    fps: float

    def frames(self) -> list[Pins]:
        """The pins of every frame from the first keyframe to the last, at ``fps``.

        Examples
        --------
        >>> k = parse_keyframes({"fps": 2, "keyframes": [
        ...     {"time": 0, "pins": [{"at": [0, 0], "to": [0, 0]}]},
        ...     {"time": 1, "pins": [{"at": [0, 0], "to": [4, 0]}]}]})
        >>> [float(f.to[0, 0]) for f in k.frames()]
        [0.0, 2.0, 4.0]
        """
        n = int(math.floor((self.times[-1] - self.times[0]) * self.fps + 1e-9)) + 1
        out = []
        for f in range(n):
            t = self.times[0] + f / self.fps
            j = int(np.clip(np.searchsorted(self.times, t, side="right") - 1, 0,
                            len(self.times) - 2)) if len(self.times) > 1 else 0
            if len(self.times) == 1:
                out.append(self.keys[0])
                continue
            t0, t1 = self.times[j], self.times[j + 1]
            w = min(1.0, max(0.0, (t - t0) / (t1 - t0)))
            a, b = self.keys[j], self.keys[j + 1]
            ang = np.where(np.isnan(a.angles) & np.isnan(b.angles), np.nan,
                           (1 - w) * np.nan_to_num(a.angles) + w * np.nan_to_num(b.angles))
            out.append(Pins(a.at, (1 - w) * a.to + w * b.to, ang,
                            (1 - w) * a.depth + w * b.depth))
        return out


def parse_keyframes(data, name: str = "keyframes") -> Keyframes:
    """Keyframes from decoded JSON (see the module's docstring)."""
    if not isinstance(data, dict) or not isinstance(data.get("keyframes"), list) \
            or not data["keyframes"]:
        raise InputError(f'{name}: expected {{"fps": 12, "keyframes": [{{"time": 0, '
                         '"pins": [...]}, ...]}')
    fps = _scalar(data.get("fps", 12), f"{name}: fps")
    if not 0 < fps <= 240:
        raise InputError(f"{name}: fps must be in (0, 240], got {fps:g}")
    times, keys = [], []
    for i, k in enumerate(data["keyframes"]):
        if not isinstance(k, dict) or "pins" not in k:
            raise InputError(f"{name}: keyframe {i}: expected {{\"time\": t, \"pins\": [...]}}")
        times.append(_scalar(k.get("time", i), f"{name}: keyframe {i} \"time\""))
        keys.append(parse_pins(k["pins"], f"{name}: keyframe {i}"))
        if i and (keys[i].at.shape != keys[0].at.shape
                  or not np.array_equal(keys[i].at, keys[0].at)):
            raise InputError(f"{name}: keyframe {i} has other pins than keyframe 0 (every "
                             "keyframe lists the same pins, the same \"at\", in order)")
    T = np.array(times)
    if (np.diff(T) <= 0).any():
        bad = int(np.flatnonzero(np.diff(T) <= 0)[0]) + 1
        raise InputError(f"{name}: keyframe {bad}'s time does not come after the one before")
    frames = (T[-1] - T[0]) * fps + 1
    if frames > 10_000:
        raise InputError(f"{name}: {frames:.0f} frames; at most 10,000")
    return Keyframes(T, keys, fps)


def load_keyframes(path) -> Keyframes:
    """Keyframes from a JSON file."""
    return parse_keyframes(parse_json(read_input(Path(path), "keyframe files"), str(path)),
                           str(path))
