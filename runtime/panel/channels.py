"""The panel's channel list: one row per input channel with three meters, and the tick's values behind them.

The meters of a row: raw input, after the stages (filter and calibration), after mapping (the rig weight, or the
expression's value, the session's map step sends the channel to first: what the character gets). By default only
the channels the input sends have a row. A click on a row's name selects it (the Response section edits the
selected channel and shows its numbers; a row under the mouse shows them in a tooltip).

The rows are one item: the desk's window draws the names, the selection and the meters' frames straight into
the list's draw list (:meth:`ChannelList.section`), and the live layer the bars, whose lengths are this tick's
values (:meth:`ChannelList.draw_meters`), as plain whole-pixel rectangles. The values are read as Python floats
once per tick (:meth:`ChannelList.tick`), not through NumPy per row.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from facepuppet.runtime.live.loop import TickInfo
    from facepuppet.runtime.live.mapper import Mapper

METER_W, METER_H, METER_GAP = 80.0, 12.0, 6.0  # a channel meter's size in pixels and the gap after it
METERS_W = 3 * (METER_W + METER_GAP) + 2.0  # the three meters of a row, before its name
#: meter colours (RGBA 0..1): raw, after the stages, after mapping; distinct so tests and eyes can tell them apart
METER_COLOURS = ((0.35, 0.55, 0.95, 1.0), (0.30, 0.85, 0.40, 1.0), (0.98, 0.60, 0.15, 1.0))


def value_text(name: str, values: tuple[float, float, float]) -> str:
    """A channel's three meter values as text (``-``: not sent / no shape)."""
    return f"{name}: " + "  ".join(f"{what} {v:.2f}" if math.isfinite(v) else f"{what} -"
                                  for what, v in zip(("raw", "filtered", "mapped"), values))


class ChannelList:
    """This tick's channels and values, the rows shown and the selection.

    Parameters
    ----------
    imgui : the ``imgui_bundle.imgui`` module (an ImGui context current: the meters' colours are made once)
    mapper : Mapper, the session's map step (what each channel drives: the mapped meter reads it)

    Attributes
    ----------
    selected : str or None, the channel the Response section edits
    sent_only : bool, rows only for the channels the input sends (NaN: not sent)
    channels : tuple of str or None, this tick's input channels (the raw frame's, else the frame's after the
        stages)
    rows : tuple of int, the rows shown this tick (indices into ``channels``)
    values : (channels, raw, filtered, rig, mapped) or None: this tick's values as lists of floats (raw and
        filtered per channel, rig per shape then expression then the eyes' blinks; each None when absent) and
        per channel the index into rig it drives (-1: none)
    """

    def __init__(self, imgui: Any, mapper: Mapper) -> None:
        self.imgui = imgui
        self.mapper = mapper
        self.selected: str | None = None
        self.sent_only = True
        self.channels: tuple | None = None
        self.rows: tuple = ()
        self.values: tuple | None = None
        self._last_raw_w = None  # the last raw weights of these channels (a tick without a new frame shows them)
        self._colours = [imgui.color_convert_float4_to_u32(imgui.ImVec4(*c)) for c in METER_COLOURS]

    def tick(self, info: TickInfo) -> None:
        """This tick's channels and values (raw, after the stages, the rig's: :attr:`values`) and the rows shown
        (:attr:`rows`: all channels, or those the input sends)."""
        raw = info.raw
        frame = info.frame
        channels = (raw.channels if raw is not None and raw.channels else
                    frame.channels if frame is not None and frame.channels else None)
        self.channels = channels
        if channels is None:
            self.values, self.rows = None, ()
            return
        raw_w = raw.weights if raw is not None and raw.channels == channels else None
        if raw_w is not None:
            self._last_raw_w = raw_w
        elif self._last_raw_w is not None and len(self._last_raw_w) == len(channels):
            raw_w = self._last_raw_w
        flt = frame.weights if frame is not None and frame.channels == channels else None
        mapped = self.mapper.first_targets(channels)[1]
        rig = info.weights
        nan = math.nan
        raw_v = raw_w.tolist() if raw_w is not None else None
        flt_v = flt.tolist() if flt is not None else None
        rig_v = rig.tolist() if rig is not None else None
        drive = self.mapper.drive
        if rig_v is not None and drive is not None and len(drive.expression_names):  # then the expressions' values
            ex = info.expressions
            rig_v += ex.tolist() if ex is not None else [nan] * len(drive.expression_names)
            emap = self.mapper.map_for(channels, report=False)  # then the eyes' blinks (Blink + Blink_L/R)
            rig_v += list(emap.eye_blinks(ex)) if ex is not None else [nan, nan]
        self.values = (channels, raw_v, flt_v, rig_v, mapped)  # the Response section reads the selected one's
        if self.sent_only and raw_v is not None:  # NaN: not sent (a VMC sender names only some channels)
            self.rows = tuple(i for i, v in enumerate(raw_v) if v == v)
        else:
            self.rows = tuple(range(len(channels)))

    def row_values(self, i: int) -> tuple[float, float, float]:
        """Channel ``i``'s raw, filtered and mapped value this tick (NaN: not sent / no shape)."""
        _, raw_v, flt_v, rig_v, mapped = self.values
        m = mapped[i]
        nan = math.nan
        return (raw_v[i] if raw_v is not None else nan, flt_v[i] if flt_v is not None else nan,
                rig_v[m] if rig_v is not None and m >= 0 else nan)

    def values_of(self, name: str) -> tuple[float, float, float] | None:
        """This tick's raw, filtered and mapped value of channel ``name`` (None: not among the channels)."""
        if self.values is None:
            return None
        channels, raw_v, flt_v, rig_v, mapped = self.values
        try:
            i = channels.index(name)
        except ValueError:
            return None
        m = mapped[i]
        return (raw_v[i] if raw_v is not None else math.nan, flt_v[i] if flt_v is not None else math.nan,
                rig_v[m] if rig_v is not None and m >= 0 else math.nan)

    def section(self, rects: dict[str, tuple[float, float, float, float]], live_at: dict[str, tuple],
                window_h: float) -> None:
        """In the desk's window: one row per channel, its meters' frames and its name (click: select).

        The rows are one invisible button (a click selects the row under the mouse, a hover shows its numbers
        in a tooltip); the names of the rows in view, the selection and the meters' frames go straight into the
        child window's draw list, their rectangles into ``rects``; where the bars go into ``live_at["meters"]``
        (left, row 0's top, row pitch, bar offset, first row, end row, clip rectangle) for the live layer.
        The list is as tall as its rows, at most about a third of the window's height ``window_h``.
        """
        imgui = self.imgui
        if not imgui.collapsing_header("Channels: raw | filtered | mapped", imgui.TreeNodeFlags_.default_open):
            return
        channels = self.channels
        if channels is None:
            imgui.text("no channels yet")
            return
        _, self.sent_only = imgui.checkbox("only the channels the input sends", self.sent_only)
        rows = self.rows
        # as tall as its rows, at most a third of the window (then it scrolls; the sections below stay in view)
        n = len(rows)
        pitch = imgui.get_text_line_height_with_spacing()
        fit = max(n, 1) * pitch + 2 * imgui.get_style().window_padding.y
        height = min(fit, max(120.0, 0.35 * window_h))
        imgui.begin_child("channels", imgui.ImVec2(0, height))
        origin = imgui.get_cursor_screen_pos()  # row 0's top left, scrolled
        vec = imgui.ImVec2
        imgui.invisible_button("##channel_rows", vec(max(imgui.get_content_region_avail().x, 1.0), max(n, 1) * pitch))
        under = -1
        if imgui.is_item_hovered():
            under = int((imgui.get_mouse_pos().y - origin.y) // pitch)
            under = under if 0 <= under < n else -1
            if under >= 0 and imgui.is_item_clicked():
                self.selected = channels[rows[under]]
        scroll, view = imgui.get_scroll_y(), imgui.get_window_height()
        first, last = max(int(scroll // pitch), 0), min(n, int((scroll + view) // pitch) + 1)
        left = float(int(origin.x))
        names_x = left + METERS_W
        right = names_x + max(imgui.get_content_region_avail().x - METERS_W, 1.0)
        dy = float(int(0.5 * (pitch - METER_H)))  # whole pixels: see draw_meters
        ty = 0.5 * (pitch - imgui.get_text_line_height())
        dl = imgui.get_window_draw_list()
        selected = self.selected
        text_col = imgui.get_color_u32(imgui.Col_.text)
        add_text = dl.add_text
        for row in range(first, last):
            i = rows[row]
            top = float(int(origin.y + row * pitch))
            name = channels[i]
            if name == selected or row == under:
                dl.add_rect_filled(vec(names_x - 2.0, top), vec(right, top + pitch), imgui.get_color_u32(
                    imgui.Col_.header if name == selected else imgui.Col_.header_hovered))
            add_text(vec(names_x, top + ty), text_col, name)
            rects[f"channel.{name}"] = (names_x, top, right, top + pitch)
            if row == under:
                imgui.set_tooltip(value_text(name, self.row_values(i)))
        if last > first:  # per column one background strip from the first row's top to the last row's bottom
            top0 = float(int(origin.y + first * pitch)) + dy
            bottom = float(int(origin.y + (last - 1) * pitch)) + dy + METER_H
            frame_col = imgui.get_color_u32(imgui.Col_.frame_bg)
            for j in range(3):
                x = left + j * (METER_W + METER_GAP)
                dl.add_rect_filled(vec(x, top0), vec(x + METER_W, bottom), frame_col)
                rects[f"meter.0.{j}"] = (x, top0, x + METER_W, top0 + METER_H)  # the first row in view's
            wp, ws = imgui.get_window_pos(), imgui.get_window_size()
            live_at["meters"] = (left, float(int(origin.y)), pitch, dy, first, last,
                                 (wp.x, wp.y, wp.x + ws.x, wp.y + ws.y))
        imgui.end_child()

    def draw_meters(self, dl: Any, layout: tuple) -> None:
        """In the live layer: the bars of the rows in view into its draw list ``dl`` (the desk drew their frames
        where ``layout`` says): per meter a bar as long as its value, a dash for none, clipped to the channel
        list. Corners on whole pixels: ImGui draws a rectangle with a fractional corner as an anti-aliased path
        (30 indices instead of 6; llvmpipe's draw call costs by the index)."""
        imgui = self.imgui
        left, top0, pitch, dy, first, last, clip = layout
        rows = self.rows
        vec, rect, line = imgui.ImVec2, dl.add_rect_filled, dl.add_line
        step = METER_W + METER_GAP
        colours, dash_col = self._colours, None
        row_values = self.row_values
        dl.push_clip_rect(vec(clip[0], clip[1]), vec(clip[2], clip[3]))
        for row in range(first, min(last, len(rows))):
            values = row_values(rows[row])
            y0 = float(int(top0 + row * pitch)) + dy
            y1 = y0 + METER_H
            x = left
            for j in range(3):
                v = values[j]
                if v > 0.0:
                    rect(vec(x, y0), vec(x + float(int(METER_W * (v if v < 1.0 else 1.0) + 0.5)), y1), colours[j])
                elif v != v:  # not sent, or no shape of it: a dash
                    if dash_col is None:
                        dash_col = imgui.get_color_u32(imgui.Col_.text_disabled)
                    line(vec(x + 0.3 * METER_W, y0 + 0.5 * METER_H), vec(x + 0.7 * METER_W, y0 + 0.5 * METER_H),
                         dash_col)
                x += step
        dl.pop_clip_rect()
