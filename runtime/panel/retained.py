"""An ImGui window built only when needed, its last frame drawn again the other ticks.

The desk's and the settings' windows change far less often than the frame loop ticks: building an ImGui frame
costs a Python call per widget, drawing the last one again only its draw calls. :class:`Retained` is the rule
for when a window of its own ImGui context must be built again; the panel keeps one per window
(:class:`~facepuppet.runtime.panel.desk.DeskPanel`).
"""

from __future__ import annotations

from typing import Any

#: frames a window is still built after an input event or a change (ImGui takes a click over frames and lays out
#: a moved or resized window's scrollbar a frame late)
SETTLE_FRAMES = 3


class Retained:
    """When one ImGui window is built (:meth:`due`), and what its last frame showed (:meth:`done`).

    Built when never built, when what it shows changed (its key), when an event arrived, in the
    :data:`SETTLE_FRAMES` frames after either, and while the operator is on it (the mouse over it, an item
    active, a text field with the keyboard).

    Parameters
    ----------
    now : float, seconds (the panel's clock): the window's first frame takes its ImGui delta time from here

    Attributes
    ----------
    builds : int, frames built so far
    last : float, when its last frame was built (ImGui's delta time)
    """

    __slots__ = ("built", "shown", "events", "settle", "busy", "builds", "last")

    def __init__(self, now: float) -> None:
        self.built, self.shown, self.events, self.settle, self.busy, self.builds = False, None, -1, 0, False, 0
        self.last = now

    def due(self, key: tuple, events: int) -> bool:
        """Whether to build a frame this tick: ``key`` is what it would show, ``events`` the input events so far."""
        return not self.built or self.busy or self.settle > 0 or events != self.events or key != self.shown

    def done(self, key: tuple, events: int, io: Any, imgui: Any) -> None:
        """After a frame: remember what it showed (``key``, the events seen) and whether the operator is on it."""
        if not self.built or events != self.events or key != self.shown:
            self.settle = SETTLE_FRAMES  # a change: this frame and the next ones
        self.built, self.builds, self.events, self.shown = True, self.builds + 1, events, key
        self.settle = max(self.settle - 1, 0)
        self.busy = bool(io.want_capture_mouse or io.want_text_input or imgui.is_any_item_active())
