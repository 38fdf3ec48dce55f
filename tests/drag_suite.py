"""The extreme-drag suite of issue 48: bends, twists to 360 degrees, stretches, pins dragged
across the shape, each a sequence of frames solved warm from the frame before, and each
admitting a fold-free map in every frame (given below where it is not obvious).

Shared by ``tests/test_flips.py`` (no fold with the flip guard, pins exact) and
``benchmarks/bench_2d.py`` (fold counts beside plain ARAP and libigl's ``dim=2``).

The fold-free witness of the bends and twists is the bending map of the strip onto an
annulus sector, ``(x, y) -> c + (rho - y)(sin(x / rho), -cos(x / rho))`` with
``rho = L / phi``: its Jacobian determinant is ``(rho - y) / rho > 0`` while
``rho > w / 2``, which holds up to ``phi = 2 L / w`` (8 rad for the 4 x 1 strip: a full
turn, 2 pi, included).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from arapkit.mesh.shapes2d import strip, strip_ends


@dataclass
class Scenario:
    """Handles, then per frame their targets ``(h, 2)`` and angles (None: no pin turns)."""

    name: str
    what: str
    mesh: object
    handles: np.ndarray
    frames: list[np.ndarray]
    angles: list[np.ndarray | None] = field(default_factory=list)

    def angle(self, i: int):
        return self.angles[i] if self.angles else None


def bending_map(P: np.ndarray, phi: float, length: float = 4.0) -> np.ndarray:
    """The strip bent through ``phi`` (left end in place, turning left): fold-free while
    ``length / phi > width / 2``."""
    if phi == 0.0:
        return P[:, :2].copy()
    rho = length / phi
    a = P[:, 0] / rho
    r = rho - P[:, 1]
    return np.stack([r * np.sin(a), rho - r * np.cos(a)], axis=1)


def scenarios(segments=(40, 10)) -> list[Scenario]:
    """The suite on the 4 x 1 strip (451 vertices at the default size)."""
    m = strip(segments=segments)
    V = m.vertices[:, :2]
    left, right = strip_ends(m)
    ends = np.concatenate([left, right])
    out = []

    phis = np.radians(np.arange(15, 181, 15))
    out.append(Scenario("bend-180", "left end held, right end bent round to 180 deg", m, ends,
                        [bending_map(V[ends], p) for p in phis]))
    phis = np.radians(np.arange(15, 361, 15))
    out.append(Scenario("twist-360", "right end turned a full 360 deg (the strip coils)", m,
                        ends, [bending_map(V[ends], p) for p in phis]))
    tip = int(np.argmin(np.linalg.norm(V - [4.0, 0.0], axis=1)))
    h = np.concatenate([left, [tip]])
    out.append(Scenario(
        "pin-turn-360", "one pin at the tip carried and turned to 360 deg (pin rotation)", m, h,
        [bending_map(V[h], p) for p in phis],
        [np.r_[np.full(len(left), np.nan), p] for p in phis]))
    stretch = np.arange(1, 9) * 1.0
    out.append(Scenario("stretch-3x", "right end pulled out to three times the length", m, ends,
                        [V[ends] + np.where(np.isin(ends, right)[:, None], [s, 0.0], 0.0)
                         for s in stretch]))
    # squashed to half: x -> x / 2 is a fold-free witness
    out.append(Scenario("squash-half", "right end pushed in to half the length", m, ends,
                        [V[ends] - np.where(np.isin(ends, right)[:, None], [s, 0.0], 0.0)
                         for s in np.linspace(0.25, 2.0, 8)]))
    # a pin on the top edge dragged down through the strip and out below it; witness: the
    # strip bent into a V through the pin (both halves stretched, none turned over)
    top = int(np.argmin(np.linalg.norm(V - [2.0, 0.5], axis=1)))
    h = np.concatenate([ends, [top]])
    out.append(Scenario("drag-across", "a pin dragged from the top edge across the strip to "
                        "2 widths below it, ends held", m, h,
                        [np.r_[V[ends], [[2.0, 0.5 - s]]] for s in np.linspace(0.25, 3.0, 12)]))
    # a pin on the right end dragged up and over the left end (the right end otherwise
    # free); witness: the strip bent round by the bending map through that point
    h = np.concatenate([left, [tip]])
    out.append(Scenario("fling-over", "the tip pin swung up and back over the held left end",
                        m, h, [np.r_[V[left], bending_map(V[[tip]], p)]
                               for p in np.radians(np.arange(20, 301, 20))]))
    return out
