"""Learning a per-vertex rigidity map r_k from example poses (Chen et al. 2017, section 5)."""

from .energies import ring_energies
from .fit import learn_rings, rings_figure
from .selection import AUTO_FLOOR, PAPER_OMEGA, LearnedRings, auto_omega, select_rings
from .sequences import combine_energies, learn_rings_sequences

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
