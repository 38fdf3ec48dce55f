"""Test collection for the whole repository: ``tests/`` and the docstring examples of ``src``.

Modules that import an optional extra at their top are left out of the doctest run when
that extra is not installed (their tests in ``tests/`` skip with a reason instead).
"""

import importlib.util

collect_ignore = []
if importlib.util.find_spec("torch") is None:
    collect_ignore += ["src/arapkit/torch.py", "src/arapkit/torch_backend.py"]
