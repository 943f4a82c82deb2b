"""The Calibration section: Calibrate (capture the neutral over the config's ``capture_s``), Clear (no
neutral), and the calibration's state."""

from __future__ import annotations

from typing import TYPE_CHECKING

from facepuppet.runtime.panel.apply import clear_calibration

if TYPE_CHECKING:
    from facepuppet.runtime.live.pipeline import LivePipeline
    from facepuppet.runtime.panel.ui import Ui


def calibration_section(ui: Ui, pipeline: LivePipeline) -> None:
    """The two buttons act on the pipeline at once, so the state line after them shows what they started."""
    imgui = ui.imgui
    if not imgui.collapsing_header("Calibration", imgui.TreeNodeFlags_.default_open):
        return
    if imgui.button("Calibrate"):
        pipeline.request_calibration()
    ui.remember("calibrate")
    imgui.same_line()
    if imgui.button("Clear"):
        clear_calibration(pipeline)
    ui.remember("clear")
    imgui.same_line()
    neutral = "capturing..." if getattr(pipeline, "calibrating", False) else \
        ("neutral set" if getattr(pipeline, "neutral_weights", None) is not None else "no neutral")
    imgui.text(f"{neutral} ({pipeline.counters.get('calibrations', 0)} calibrations)")
