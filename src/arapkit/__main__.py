"""``python -m arapkit`` runs the command line, like the ``arapkit`` script.

Python users try ``python -m PACKAGE`` when a console script is not on their ``PATH``
(a venv not activated, ``pip install --user``); it must reach the same door.
"""

import sys

from arapkit.cli import main

sys.exit(main())
