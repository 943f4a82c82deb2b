"""The Face section: blink linking and mirror (``[face]``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from facepuppet.runtime.live.config import LiveConfig
    from facepuppet.runtime.panel.ui import Ui


def face_section(ui: Ui, config_now: Callable[[], LiveConfig]) -> LiveConfig | None:
    """Two checkboxes; the config with the one clicked changed, or None."""
    imgui = ui.imgui
    if not imgui.collapsing_header("Face", imgui.TreeNodeFlags_.default_open):
        return None
    config = config_now()
    c1, link = imgui.checkbox("link blinks (both eyes from the stronger)", config.link_blinks)
    ui.remember("face.link_blinks")
    c2, mirror = imgui.checkbox("mirror (left/right, head yaw and roll)", config.mirror)
    ui.remember("face.mirror")
    if c1 or c2:
        return replace(config, link_blinks=bool(link), mirror=bool(mirror))
    return None
