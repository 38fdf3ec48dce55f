"""Learning a per-vertex rigidity map r_k from example poses (Chen et al. 2017, section 5)."""

from .fit import (
    AUTO_FLOOR,
    PAPER_OMEGA,
    LearnedRings,
    auto_omega,
    combine_energies,
    learn_rings,
    learn_rings_sequences,
    ring_energies,
    rings_figure,
    select_rings,
)

__all__ = [
    "AUTO_FLOOR",
    "PAPER_OMEGA",
    "LearnedRings",
    "auto_omega",
    "combine_energies",
    "learn_rings",
    "learn_rings_sequences",
    "ring_energies",
    "rings_figure",
    "select_rings",
]
