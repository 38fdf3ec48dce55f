"""What a user calls: surface and volumetric ARAP, Laplacian editing, embedded deformation.

Importing the package registers every method in :mod:`arapkit.methods.registry`.
"""

from . import deformer, embedded, laplacian, multires, volumetric  # noqa: F401 - registers the methods
