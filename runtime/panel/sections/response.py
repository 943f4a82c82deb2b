"""The Response section (in the desk's window) of the channel selected in the channel list: gain, clamp, input
range -> output range, curve (linear / ease / threshold, with the threshold value), Reset (drops the channel's
entry), the channel's numbers this tick (written by the live layer), and **drives**: what it maps onto
(``[mapping.channels]``: by name, nothing, or one shape or expression; the session's map step maps with it from
the next tick, :func:`~facepuppet.runtime.live.mapper.follow_mapping`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

from facepuppet.runtime.live.config import CURVES
from facepuppet.runtime.mapping.channels import canonical
from facepuppet.runtime.mapping.expressions import MappingTarget

if TYPE_CHECKING:
    from facepuppet.runtime.live.config import LiveConfig
    from facepuppet.runtime.mapping.expressions import MappingSettings
    from facepuppet.runtime.panel.channels import ChannelList
    from facepuppet.runtime.panel.ui import Ui

DRIVES_ROWS = 6  # rows of the selected channel's "drives" list shown at once (it scrolls)


def _slider(ui: Ui, label: str, value: float, lo: float, hi: float, fmt: str) -> tuple[bool, float]:
    imgui = ui.imgui
    imgui.set_next_item_width(170)
    changed, v = imgui.slider_float(f"##{label}", float(value), lo, hi, fmt)
    ui.remember(f"response.{label}")
    return changed, float(v)


def response_section(ui: Ui, config_now: Callable[[], LiveConfig], channels: ChannelList,
                     live_at: dict[str, tuple], choices: Callable[[], list[str]] | None) -> LiveConfig | None:
    """The response of ``channels.selected``; the config with what was edited, or None.

    Where the channel is among this tick's, a line is left blank for its numbers (``live_at["values"]``: x, y).
    ``choices`` gives what the drives list offers (the rig's shapes, then the drive's expressions); None: no
    drives list (a chain that maps through an elastic model).
    """
    imgui = ui.imgui
    if not imgui.collapsing_header("Response (click a channel)", imgui.TreeNodeFlags_.default_open):
        return None
    name = channels.selected
    if name is None:
        imgui.text("no channel selected: click a channel's name above")
        return None
    config = config_now()
    key = canonical(name)
    cs = config.channel(name)
    imgui.text(f"{name}" + ("" if key in config.channels else " (default response)"))
    ui.remember("response.name")
    if channels.values_of(name) is not None:  # room for the meters' numbers of it (the live layer's)
        p = imgui.get_cursor_screen_pos()
        imgui.dummy(imgui.ImVec2(imgui.get_content_region_avail().x, imgui.get_text_line_height()))
        ui.remember("response.values")
        live_at["values"] = (float(int(p.x)), float(int(p.y)))
    imgui.push_id("response")
    new = cs
    c, v = _slider(ui, "gain", cs.gain, 0.0, 3.0, "gain %.2f")
    if c:
        new = replace(new, gain=v)
    lo, hi = cs.clamp
    c1, v1 = _slider(ui, "clamp_low", lo, -1.0, 2.0, "clamp low %.2f")
    imgui.same_line()
    c2, v2 = _slider(ui, "clamp_high", hi, -1.0, 2.0, "clamp high %.2f")
    if c1 or c2:  # low <= high: the one dragged pushes the other
        lo, hi = (v1, max(v1, hi)) if c1 else (min(lo, v2), v2)
        new = replace(new, clamp=(lo, hi))
    ilo, ihi = cs.input_range or (0.0, 1.0)
    c1, v1 = _slider(ui, "in_low", ilo, -1.0, 2.0, "in %.2f")
    imgui.same_line()
    c2, v2 = _slider(ui, "in_high", ihi, -1.0, 2.0, "to %.2f")
    if c1 or c2:  # low < high (the config's rule): the one dragged pushes the other
        ilo, ihi = (v1, max(v1 + 1e-3, ihi)) if c1 else (min(ilo, v2 - 1e-3), v2)
        new = replace(new, input_range=(ilo, ihi))
    ofrom, oto = cs.output_range or (0.0, 1.0)
    c1, v1 = _slider(ui, "out_from", ofrom, -1.0, 2.0, "out %.2f")
    imgui.same_line()
    c2, v2 = _slider(ui, "out_to", oto, -1.0, 2.0, "to %.2f")
    if c1 or c2:  # from > to is allowed: an inverted channel
        new = replace(new, output_range=(v1 if c1 else ofrom, v2 if c2 else oto))
    for curve in CURVES:
        if imgui.radio_button(curve, cs.curve == curve) and curve != cs.curve:
            new = replace(new, curve=curve)
        ui.remember(f"response.curve.{curve}")
        imgui.same_line()
    imgui.new_line()
    if cs.curve == "threshold":
        c, v = _slider(ui, "threshold", cs.threshold, 0.0, 1.0, "threshold %.2f")
        if c:
            new = replace(new, threshold=v)
    mapping = drives_list(ui, name, config, choices()) if choices is not None else None
    reset = imgui.button("Reset")
    ui.remember("response.reset")
    imgui.pop_id()
    if mapping is not None:
        return replace(config, mapping=mapping)
    channels_cfg = dict(config.channels)
    if reset and key in channels_cfg:
        del channels_cfg[key]
        return replace(config, channels=channels_cfg)
    if new != cs:
        channels_cfg[key] = new
        return replace(config, channels=channels_cfg)
    return None


def drives_list(ui: Ui, name: str, config: LiveConfig, choices: list[str]) -> MappingSettings | None:
    """What channel ``name`` drives, as ``[mapping.channels]`` says it (runtime.expressions): by name (no entry:
    the routes a channel takes without one), nothing, or one of ``choices`` at weight 1. Returns the new
    MappingSettings when one is picked, else None. An entry of several targets or weights written in
    ``--config`` is shown as written and kept until another choice replaces it."""
    imgui = ui.imgui
    key = canonical(name)
    targets = config.mapping.channels.get(key)
    if targets is None:
        shown = "(by name)"
    elif not targets:
        shown = "(nothing)"
    else:
        shown = ", ".join(t.to if t.weight == 1.0 else f"{t.to} x{t.weight:g}" for t in targets)
    picked = None
    imgui.text(f"drives: {shown}")
    ui.remember("response.drives")
    # a list in the window, not a pop-up: a pop-up would open under the settings' window (a context of its
    # own, drawn after the desk) and a click on it would reach the settings too
    rows = min(DRIVES_ROWS, 2 + len(choices))
    size = imgui.ImVec2(min(300.0, imgui.get_content_region_avail().x),
                        rows * imgui.get_text_line_height_with_spacing() + 4.0)
    if imgui.begin_list_box("##drives", size):
        for i, label in enumerate(["(by name)", "(nothing)", *choices]):
            current = label == shown
            if imgui.selectable(f"{label}##drive{i}", current)[0] and not current:
                picked = label
            ui.remember(f"response.drives.{label}")
        imgui.end_list_box()
    if picked is None:
        return None
    channels, written = dict(config.mapping.channels), dict(config.mapping.written)
    if picked == "(by name)":
        channels.pop(key, None)
        written.pop(key, None)
    else:
        channels[key] = () if picked == "(nothing)" else (MappingTarget(picked),)
        written[key] = name
    return replace(config.mapping, channels=channels, written=written)
