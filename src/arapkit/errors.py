"""Exception raised for bad user input.

Every message is one line that names the file, vertex, handle or group at fault,
so the command line can print it as is and exit with status 2.
"""

from __future__ import annotations


class InputError(ValueError):
    """A user-supplied mesh, handle set, rigidity map or option is invalid.

    Examples
    --------
    >>> raise InputError("bar.off: face 3 references vertex 99 (mesh has 10)")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: bar.off: face 3 references vertex 99 (mesh has 10)
    """
