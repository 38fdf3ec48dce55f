"""Energies of the local/global solver, one module each, found through one table.

Importing this package imports every energy module, and each registers its builder in
:mod:`arapkit.arap.energies.table`; :func:`make_energy` builds any of them by name.

Examples
--------
>>> from arapkit.arap.energies import energy_names
>>> energy_names()
('rring', 'smooth-arap', 'spokes-and-rims', 'sr-arap')
"""

from . import rring, smooth_arap, spokes_rims, sr_arap  # noqa: F401 - each registers its energy
from .base import NeighbourhoodEnergy, energy_from_entries, rest_term
from .rring import rring_energy
from .table import EnergyInfo, energy_info, energy_names, make_energy, register_energy

__all__ = ["EnergyInfo", "NeighbourhoodEnergy", "energy_from_entries", "energy_info",
           "energy_names", "make_energy", "register_energy", "rest_term", "rring_energy"]
