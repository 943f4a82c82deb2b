"""What every part of the panel draws with: ImGui, where each labelled widget was drawn, and sections out of view
built as one blank item.

Every widget an operator (or a test, or the window's clicks) may aim at is remembered under a label with its
rectangle in pixels (:attr:`Ui.rects`: ``"filter.mouth.beta"``, ``"channel.jawOpen"``, ``"record.start"``).
A settings section the window does not show (scrolled out, or below its bottom) is built as one blank item as
tall as it was when last built (:meth:`Ui.section`): ImGui's clipping still costs a Python call per widget,
the blank one; its labels are dropped while it is not drawn (nothing to click there).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


class Ui:
    """ImGui with the panel's bookkeeping of widget rectangles and section heights.

    Parameters
    ----------
    imgui : the ``imgui_bundle.imgui`` module (an ImGui context current: its style's item spacing is read)

    Attributes
    ----------
    imgui : the ``imgui_bundle.imgui`` module
    rects : dict of widget label -> (x0, y0, x1, y1) in pixels, as last drawn (where to click)
    spacing_y : float, the style's vertical item spacing in pixels
    """

    def __init__(self, imgui: Any) -> None:
        self.imgui = imgui
        self.rects: dict[str, tuple[float, float, float, float]] = {}
        self.spacing_y = imgui.get_style().item_spacing.y
        self._section_h: dict[str, float] = {}  # a section's height when last built
        self._section_rects: dict[str, set[str]] = {}  # the rects' labels of each section
        self._collect: set[str] | None = None  # the labels remembered by the section being built

    def remember(self, label: str) -> None:
        """The last item's rectangle under ``label`` (and among the labels of the section being built)."""
        a, b = self.imgui.get_item_rect_min(), self.imgui.get_item_rect_max()
        self.rects[label] = (a.x, a.y, b.x, b.y)
        if self._collect is not None:
            self._collect.add(label)

    def section(self, key: str, build: Callable[..., None], *args: Any) -> None:
        """Call ``build(*args)`` (a section's widgets), or, when the window shows none of section ``key``, only
        a blank item as tall as it was when last built. A section comes back the frame its space scrolls into
        view."""
        imgui = self.imgui
        h = self._section_h.get(key, 0.0)
        if h > self.spacing_y and not imgui.is_rect_visible(imgui.ImVec2(1.0, h)):
            imgui.dummy(imgui.ImVec2(0.0, h - self.spacing_y))  # the cursor moves on by h, as after the section
            for label in self._section_rects.pop(key, ()):
                self.rects.pop(label, None)
            return
        y0 = imgui.get_cursor_pos_y()
        self._collect = labels = set()
        try:
            build(*args)
        finally:
            self._collect = None
        self._section_h[key] = imgui.get_cursor_pos_y() - y0
        self._section_rects[key] = labels
