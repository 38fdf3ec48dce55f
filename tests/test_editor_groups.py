"""Painting vertex groups in the editor: the painted groups, undo and sessions.

The same in a real browser is ``test_browser_paint_a_part_and_drag`` in
``tests/test_editor_browser.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

from arapkit.editor.groups import ERASE, PaintedGroups
from arapkit.editor.state import EditorState
from arapkit.errors import InputError
from arapkit.mesh.shapes import bar


def test_painted_groups_undo_sessions_and_names():
    st = EditorState(bar())
    g = st.new_group(rigid=True)
    assert st.paint_group(st.vertices[600], 0.5, g) > 0
    shared = st.new_group(rigid=False)
    st.paint_group(st.vertices[100], 0.3, shared)
    vg = st.groups.vertex_groups()
    assert vg.names == ("part 1", "group 1") and vg.rigid.tolist() == [True, False]
    assert st.groups.index_of(ERASE) == -1 and st.groups.index_of("part 1 (rigid)") == 0
    # a session keeps them; undo takes the last stroke back
    again = EditorState(bar())
    again.apply_dict(st.to_dict())
    assert np.array_equal(again.groups.ids, st.groups.ids)
    st.undo()
    assert (st.groups.ids == shared).sum() == 0
    st.remove_group(0)
    assert st.groups.n_groups == 1 and (st.groups.ids >= 0).sum() == 0
    with pytest.raises(InputError, match="overlaps another"):
        PaintedGroups.from_json([{"name": "a", "rigid": True, "indices": [0, 1]},
                                 {"name": "b", "rigid": True, "indices": [1]}], 3)
