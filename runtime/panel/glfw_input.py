"""A run window's keyboard and mouse fed to the panel's ImGui IO (glfw callbacks); Tab shows or hides the panel.

Events go through ImGui's input queue (``add_mouse_pos_event``, ``add_mouse_button_event``,
``add_mouse_wheel_event``, ``add_key_event``, ``add_input_character``), the same calls the tests make
headless. The run's own keys keep working: C calibrates when ImGui is not typing into a field.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from facepuppet.runtime.panel.desk import DeskPanel


def _key_table(glfw, imgui) -> dict[int, Any]:
    k = imgui.Key
    table = {glfw.KEY_TAB: k.tab, glfw.KEY_LEFT: k.left_arrow, glfw.KEY_RIGHT: k.right_arrow,
             glfw.KEY_UP: k.up_arrow, glfw.KEY_DOWN: k.down_arrow, glfw.KEY_PAGE_UP: k.page_up,
             glfw.KEY_PAGE_DOWN: k.page_down, glfw.KEY_HOME: k.home, glfw.KEY_END: k.end,
             glfw.KEY_INSERT: k.insert, glfw.KEY_DELETE: k.delete, glfw.KEY_BACKSPACE: k.backspace,
             glfw.KEY_SPACE: k.space, glfw.KEY_ENTER: k.enter, glfw.KEY_ESCAPE: k.escape,
             glfw.KEY_KP_ENTER: k.keypad_enter, glfw.KEY_LEFT_CONTROL: k.left_ctrl,
             glfw.KEY_RIGHT_CONTROL: k.right_ctrl, glfw.KEY_LEFT_SHIFT: k.left_shift,
             glfw.KEY_RIGHT_SHIFT: k.right_shift, glfw.KEY_LEFT_ALT: k.left_alt, glfw.KEY_RIGHT_ALT: k.right_alt}
    for i in range(26):  # letters: Ctrl+A/C/V/X/Z in text fields
        table[glfw.KEY_A + i] = getattr(k, chr(ord("a") + i))
    for i in range(10):
        table[glfw.KEY_0 + i] = getattr(k, f"_{i}")
    return table


def bind_window(window: Any, panel: DeskPanel, on_calibrate: Callable[[], None] | None = None) -> None:
    """Install glfw callbacks on ``window`` feeding ``panel.io``; Tab toggles ``panel.visible``."""
    import glfw

    imgui, io = panel.imgui, panel.io
    keys = _key_table(glfw, imgui)

    def mods(m: int) -> None:
        io.add_key_event(imgui.Key.mod_ctrl, bool(m & glfw.MOD_CONTROL))
        io.add_key_event(imgui.Key.mod_shift, bool(m & glfw.MOD_SHIFT))
        io.add_key_event(imgui.Key.mod_alt, bool(m & glfw.MOD_ALT))

    def on_key(win, key, scancode, action, m):
        typing = panel.visible and io.want_text_input
        if action == glfw.PRESS and key == glfw.KEY_TAB and not typing:
            panel.toggle()
            return
        if action == glfw.PRESS and key == glfw.KEY_C and on_calibrate is not None and not typing:
            on_calibrate()
        if key in keys and action in (glfw.PRESS, glfw.RELEASE):
            mods(m)
            io.add_key_event(keys[key], action == glfw.PRESS)

    def on_char(win, codepoint):
        if panel.visible:
            io.add_input_character(codepoint)

    def on_cursor(win, x, y):
        io.add_mouse_pos_event(float(x), float(y))

    def on_button(win, button, action, m):
        if 0 <= button < 5:
            mods(m)
            io.add_mouse_button_event(button, action == glfw.PRESS)

    def on_scroll(win, dx, dy):
        io.add_mouse_wheel_event(float(dx), float(dy))

    def on_focus(win, focused):
        io.add_focus_event(bool(focused))

    glfw.set_key_callback(window, on_key)
    glfw.set_char_callback(window, on_char)
    glfw.set_cursor_pos_callback(window, on_cursor)
    glfw.set_mouse_button_callback(window, on_button)
    glfw.set_scroll_callback(window, on_scroll)
    glfw.set_window_focus_callback(window, on_focus)
