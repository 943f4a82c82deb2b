"""The panel's input when it is drawn by more than one ImGui context: every event to each of them.

A wide window shows the panel as two ImGui windows, each in its own ImGui context (the desk, rebuilt every
frame for its meters; the settings, rebuilt only when something on them changes: see
:class:`~facepuppet.runtime.panel.desk.DeskPanel`). The window's keyboard and mouse (and the tests' synthetic
events) are handed to both contexts' IO: each context's windows take the events that fall on them, the other
sees a click on empty space, which does nothing. :attr:`PanelIO.events` counts the events, so that a context
that is not rebuilt every frame knows an event is waiting for it.
"""

from __future__ import annotations

from typing import Any


class PanelIO:
    """The ``add_*_event`` calls of ImGui's IO, handed to every context's IO in ``ios``.

    Parameters
    ----------
    ios : ImGui IO objects (``imgui.get_io()`` of each context), the first the desk's

    Attributes
    ----------
    events : int, the events handed on so far
    """

    def __init__(self, *ios: Any) -> None:
        if not ios:
            raise ValueError("PanelIO: expected at least one ImGui IO")
        self._ios = ios
        self.events = 0

    def _each(self, name: str, *args: Any) -> None:
        self.events += 1
        for io in self._ios:
            getattr(io, name)(*args)

    def add_mouse_pos_event(self, x: float, y: float) -> None:
        self._each("add_mouse_pos_event", x, y)

    def add_mouse_button_event(self, button: int, down: bool) -> None:
        self._each("add_mouse_button_event", button, down)

    def add_mouse_wheel_event(self, dx: float, dy: float) -> None:
        self._each("add_mouse_wheel_event", dx, dy)

    def add_key_event(self, key: Any, down: bool) -> None:
        self._each("add_key_event", key, down)

    def add_input_character(self, codepoint: int) -> None:
        self._each("add_input_character", codepoint)

    def add_input_characters_utf8(self, text: str) -> None:
        self._each("add_input_characters_utf8", text)

    def add_focus_event(self, focused: bool) -> None:
        self._each("add_focus_event", focused)

    @property
    def want_text_input(self) -> bool:
        """A text field of any context has the keyboard (Tab and C then type, not toggle or calibrate)."""
        return any(io.want_text_input for io in self._ios)

    @property
    def want_capture_mouse(self) -> bool:
        return any(io.want_capture_mouse for io in self._ios)

    @property
    def want_capture_keyboard(self) -> bool:
        return any(io.want_capture_keyboard for io in self._ios)
