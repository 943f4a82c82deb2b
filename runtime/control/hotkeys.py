"""Keyboard hotkeys in the run's window, bound to the control verbs by a ``[hotkeys]`` table of the config.

::

    [hotkeys]
    J = { verb = "expression", name = "Joy", action = "toggle", fade = 0.2 }
    K = { verb = "expression", name = "Angry", action = "for", seconds = 2 }
    F5 = { verb = "record", action = "start" }
    F6 = { verb = "record", action = "stop" }

A key is a letter A-Z, a digit 0-9 or F1-F12; ``C`` and Tab are the window's own (calibrate, the panel). Each
value is the verb's JSON object written as TOML (:mod:`~facepuppet.runtime.control.commands`), checked when the
config is read; a pressed key hands its command to the control stage, applied at the next tick and recorded as
the WebSocket's and OSC's are. Keys typed into the panel's text fields do not fire.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Callable
from typing import Any

from facepuppet.runtime.control.commands import SHOW_VERBS, Command, CommandError, parse_command

logger = logging.getLogger(__name__)

_KEY = re.compile(r"[A-Z0-9]|F([1-9]|1[0-2])")
RESERVED = {"C": "the window's calibrate key"}
MAX_HOTKEYS = 48


def parse_hotkeys(where: str, table: object, error: type[Exception]) -> tuple[tuple[str, dict], ...]:
    """The ``[hotkeys]`` table as (key, command object) pairs, each checked; ``error`` (naming ``where`` and the
    key) otherwise."""
    if not isinstance(table, dict):
        raise error(f"{where}: key 'hotkeys': expected a table of KEY = {{ verb = ... }}")
    if len(table) > MAX_HOTKEYS:
        raise error(f"{where}: key 'hotkeys': {len(table)} keys; at most {MAX_HOTKEYS}")
    out = []
    for key, doc in table.items():
        name = str(key).upper()
        if not _KEY.fullmatch(name):
            raise error(f"{where}: key 'hotkeys.{key}': a hotkey is a letter A-Z, a digit 0-9 or F1-F12")
        if name in RESERVED:
            raise error(f"{where}: key 'hotkeys.{key}': {name} is {RESERVED[name]}")
        try:
            command = parse_command(doc, f"{where}: key 'hotkeys.{key}'")
        except CommandError as exc:
            raise error(str(exc)) from None
        if command.verb not in SHOW_VERBS:
            raise error(f"{where}: key 'hotkeys.{key}': verb {command.verb!r} answers a client; a hotkey takes one "
                        f"of {', '.join(SHOW_VERBS)}")
        out.append((name, dict(doc)))
    return tuple(out)


def glfw_key(glfw: Any, name: str) -> int:
    """The glfw key code of a hotkey name (A-Z, 0-9, F1-F12)."""
    if name.startswith("F") and len(name) > 1:
        return glfw.KEY_F1 + int(name[1:]) - 1
    if name.isdigit():
        return glfw.KEY_0 + int(name)
    return glfw.KEY_A + ord(name) - ord("A")


def bind_hotkeys(window: Any, hotkeys: tuple[tuple[str, dict], ...], submit: Callable[[Command], bool],
                 typing: Callable[[], bool] = lambda: False) -> None:
    """Chain a key callback onto ``window``'s (the panel's or the calibrate key's stays in force) that submits
    each hotkey's command on a press, unless ``typing()`` (a panel text field has the keyboard)."""
    import glfw

    table = {glfw_key(glfw, name): parse_command(doc, f"hotkey {name}") for name, doc in hotkeys}
    previous = glfw.set_key_callback(window, None)

    def on_key(win, key, scancode, action, mods) -> None:
        if previous is not None:
            previous(win, key, scancode, action, mods)
        if action == glfw.PRESS and key in table and not typing():
            submit(table[key])

    glfw.set_key_callback(window, on_key)
