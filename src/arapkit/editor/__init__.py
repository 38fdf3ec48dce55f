"""Browser editor for arapkit (``arapkit edit``): drag handles, paint rigidity, watch energy.

The package is split so that the logic can be tested without a browser (only the page
modules, ``app``, ``panels`` and ``files``, import viser):

* :mod:`arapkit.editor.state` -- selection, handles, rigidity paint, undo;
* :mod:`arapkit.editor.handles` -- a handle and its gizmo pose;
* :mod:`arapkit.editor.settings` -- the solver panel's methods (from the method registry);
* :mod:`arapkit.editor.session` -- session files;
* :mod:`arapkit.editor.geometry` -- camera, picking, rectangle and brush geometry;
* :mod:`arapkit.editor.worker` -- the background solver thread (latest drag wins);
* :mod:`arapkit.editor.views` -- colours of the r and energy views;
* :mod:`arapkit.editor.tools` -- the pointer tools, a registry;
* :mod:`arapkit.editor.panels` -- the side panel's widgets;
* :mod:`arapkit.editor.files` -- uploads and exports;
* :mod:`arapkit.editor.app` -- the viser page wiring it all together.

Examples
--------
>>> from arapkit.mesh.shapes import bar
>>> from arapkit.editor import EditorState
>>> EditorState(bar()).n
1154
"""

from arapkit.editor.state import CameraView, EditorState, Handle, SolverSettings
from arapkit.editor.worker import SolveRequest, SolveUpdate, SolveWorker

__all__ = [
    "CameraView",
    "EditorState",
    "Handle",
    "SolveRequest",
    "SolveUpdate",
    "SolveWorker",
    "SolverSettings",
]
