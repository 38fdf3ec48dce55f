"""The top of the editor's panel: status, Next hint, colour legend and a build's progress.

They are one HTML block that sticks to the top of the panel's scroll area, so the status,
the hint and the legend stay in view while the lower panels (Rigidity, Session ...) are
used. viser draws its HTML component with ``innerHTML``: a ``<style>`` element in it applies
to the page, which is how the block is made sticky (and how the upload notification that
says "File uploaded successfully" before the editor has read the file is hidden: the
editor's own notification says whether the file was opened). Everything shown is built
here from a small markdown subset, escaped, so a file name can never inject markup.

Examples
--------
>>> markdown_html("**r-ring ARAP** · _note_  \\nnext <b>")
'<b>r-ring ARAP</b> · <i>note</i><br>next &lt;b&gt;'
"""

from __future__ import annotations

import html
import re
from typing import Any

__all__ = ["PAGE_CSS", "TopBlock", "markdown_html", "progress_html"]

#: the page's style: the top block sticks (its wrappers inside the scroll area must not
#: clip it), has an opaque background and padding (the legend's first letter sat on the
#: panel's edge), the upload notification's premature "success" is not shown, and a number
#: box left empty (it takes no letters: "abc" leaves it blank and sends nothing) is marked
#: red with "numbers only" under it
PAGE_CSS = """<style>
.mantine-ScrollArea-viewport div:has(#arapkit-top) { overflow: visible !important; }
div:has(> #arapkit-top) {
  position: sticky; top: 0; z-index: 30;
  background: var(--mantine-color-body, #fff);
  box-shadow: 0 2px 3px -2px rgba(0, 0, 0, 0.25);
}
#arapkit-top { padding: 0.35em 0.75em 0.45em 0.75em; font-size: 0.875rem; line-height: 1.4; }
#arapkit-top p { margin: 0 0 0.35em 0; }
#arapkit-top .legend { font-size: 0.8em; margin-top: 0.2em; }
#arapkit-top .bar { height: 0.5em; background: #e6e8ec; border-radius: 0.25em; overflow: hidden; }
#arapkit-top .bar > div { height: 100%; background: #228be6; }
.mantine-Notification-root:has(.tabler-icon-check) { display: none; }
.mantine-NumberInput-root:has(input[value=""]) { position: relative; }
.mantine-NumberInput-root:has(input[value=""]) input { outline: 2px solid #fa5252; }
.mantine-NumberInput-root:has(input[value=""])::after {
  content: "numbers only"; position: absolute; right: 0; top: 100%; z-index: 5;
  font-size: 0.65rem; color: #fa5252; white-space: nowrap;
}
</style>"""

_BOLD = re.compile(r"\*\*(.+?)\*\*")
_CODE = re.compile(r"`([^`]+)`")
# _x_ and *x* at word edges only: snake_case names keep their underscores
_ITALIC = re.compile(r"(?<![\w*])[_*](?![\s_*])(.+?)(?<![\s_*])[_*](?![\w*])")


def markdown_html(text: str) -> str:
    """The editor's markdown subset as HTML: ``**bold**``, ``_italic_``, `` `code` ``,
    a line break for ``"  \\n"`` and a paragraph for a blank line; the rest is escaped.

    Examples
    --------
    >>> markdown_html("a_b_c.off and `x<y`")
    'a_b_c.off and <code>x&lt;y</code>'
    """
    paragraphs = []
    for para in re.split(r"\n\s*\n", str(text)):
        out = html.escape(para, quote=False)
        out = _CODE.sub(r"<code>\1</code>", out)
        out = _BOLD.sub(r"<b>\1</b>", out)
        out = _ITALIC.sub(r"<i>\1</i>", out)
        paragraphs.append(re.sub(r" {2,}\n|\n", "<br>", out))
    return "</p><p>".join(paragraphs)


def progress_html(fraction: float, text: str) -> str:
    """A progress bar with a line of text under it.

    Examples
    --------
    >>> progress_html(0.5, "half") .count("width:50%")
    1
    """
    pct = max(0.0, min(1.0, float(fraction))) * 100
    return (f'<div class="bar" role="progressbar" aria-valuenow="{pct:.0f}" '
            f'aria-valuemin="0" aria-valuemax="100"><div style="width:{pct:.0f}%"></div></div>'
            f"<p>{markdown_html(text)}</p>")


class _Part:
    """One part of the top block, with the ``content`` of a viser markdown handle."""

    def __init__(self, block: TopBlock, key: str) -> None:
        self._block, self._key = block, key

    @property
    def content(self) -> str:
        return self._block.parts[self._key]

    @content.setter
    def content(self, text: str) -> None:
        if self._block.parts[self._key] != text:
            self._block.parts[self._key] = text
            self._block.render()


class TopBlock:
    """Status, hint, legend and progress in one sticky HTML element of the panel.

    ``status``, ``hint`` (markdown) and ``legend`` (HTML made by the editor) read and take
    ``.content`` like viser's own handles; :meth:`progress` shows or hides a bar.
    """

    def __init__(self, gui: Any, status: str = "", hint: str = "") -> None:
        gui.add_html(PAGE_CSS)
        self.parts = {"status": status, "hint": hint, "legend": "", "progress": ""}
        self.status, self.hint, self.legend = (_Part(self, k) for k in ("status", "hint",
                                                                            "legend"))
        self._handle = gui.add_html(self._html())

    def progress(self, fraction: float | None, text: str = "") -> None:
        """Show a progress bar with ``text`` (``None``: hide it)."""
        new = "" if fraction is None else progress_html(fraction, text)
        if new != self.parts["progress"]:
            self.parts["progress"] = new
            self.render()

    def _html(self) -> str:
        p = self.parts
        legend = f'<div class="legend">{p["legend"]}</div>' if p["legend"] else ""
        return (f'<div id="arapkit-top"><p>{markdown_html(p["status"])}</p>{p["progress"]}'
                f'<p>{markdown_html(p["hint"])}</p>{legend}</div>')

    def render(self) -> None:
        """Send the block to the page."""
        self._handle.content = self._html()
