"""``python -m arapkit.cli`` runs the command line (same as the ``arapkit`` script)."""

import sys

from arapkit.cli import main

sys.exit(main())
