"""The Tracking loss section: what each region does while the tracker has lost the face (``[tracking_loss]``):
hold, neutral, voice (the mouth only) or idle."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

from facepuppet.runtime.live.tracking_loss import LOSS_MODES, LOSS_REGIONS, VOICE_REGIONS

if TYPE_CHECKING:
    from facepuppet.runtime.live.config import LiveConfig
    from facepuppet.runtime.panel.ui import Ui


def loss_section(ui: Ui, config_now: Callable[[], LiveConfig]) -> LiveConfig | None:
    """A row of radio buttons per region; the config with the mode picked, or None."""
    imgui = ui.imgui
    if not imgui.collapsing_header("Tracking loss", imgui.TreeNodeFlags_.default_open):
        return None
    config = config_now()
    modes = dict(config.loss.modes)
    changed = False
    for region in LOSS_REGIONS:
        imgui.push_id(f"loss.{region}")
        imgui.align_text_to_frame_padding()  # the region's name on the radio buttons' line
        imgui.text(f"{region:6s}")
        for mode in LOSS_MODES:
            if mode == "voice" and region not in VOICE_REGIONS:
                continue  # voice drives the mouth only (the config refuses it elsewhere)
            imgui.same_line()
            if imgui.radio_button(mode, config.loss.mode(region) == mode) and modes.get(region) != mode:
                modes[region] = mode
                changed = True
            ui.remember(f"loss.{region}.{mode}")
        imgui.pop_id()
    return replace(config, loss=replace(config.loss, modes=modes)) if changed else None
