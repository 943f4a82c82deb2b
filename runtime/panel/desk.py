"""What the panel shows and edits: input status, per-channel meters, filters per region, calibration, record, chain.

The panel is two ImGui windows, each in its own ImGui context: the desk (input, channels, response) and the
settings (the rest; at the right edge of a window wide enough for both and some face, else under the desk),
drawn after the character, into the same framebuffer (:class:`~facepuppet.runtime.panel.gl.ImguiGL`). The desk
is built every frame (its meters); the settings only when what they show changes (the config in force, the
calibration's state, the recording, the profile's messages, the layout: :meth:`DeskPanel._settings_key`), when
an event arrives (the window's events go to both contexts: :class:`~facepuppet.runtime.panel.fanout.PanelIO`)
and while the mouse is over them; the other frames draw their last frame again. It runs as a
:class:`~facepuppet.runtime.live.loop.FrameLoop` overlay: after the character's
draw call of a tick, before the GPU wait, with that tick's
:class:`~facepuppet.runtime.live.loop.TickInfo` (the raw frame the snapshot took,
the frame after the stages, the rig weights drawn), so the meters show the
frame on screen, not the one before.

* **Input status**: kind, listening address and the frames' source, packets/s and frames drawn/s
  (over the last half second), drops by reason (every non-zero drop counter of the receiver and the loop),
  age of the last new frame, tracking state (waiting / live / lost / easing back), receive→draw latency
  p50/p99 (``end_to_end`` of the live stats over the last half second).
* **Channels**: one row per input channel (by default only those the input sends) with three meters:
  raw input, after the stages (filter and calibration), after mapping (the rig weight of the shape of that
  name: what the character gets). The meters are bars (the numbers of the selected channel are under
  Response, those of a row under the mouse in its tooltip).
* **Filters**: One Euro min cutoff and beta per region.
* **Response** of the channel selected (click its name in the channel rows): gain, clamp, input range ->
  output range, curve (linear / ease / threshold, with the threshold value); Reset drops the channel's entry;
  **drives**: what it maps onto (``[mapping.channels]``: by name, nothing, or one shape or expression;
  :func:`~facepuppet.runtime.live.stages.follow_mapping` maps with it from the next tick).
* **Face**: blink linking and mirror (``[face]``).
* **Tracking loss**: the mode per region (hold / neutral / voice for the mouth / idle, ``[tracking_loss]``).
* **Calibrate** (neutral capture over ``capture_s``) and **Clear** (no neutral).
* **Profile** (a run with ``--profile``: ``chain.profile``): Save, Save as (a name or a path), Revert, and a
  warning when the profile was made for another character or input.
* **Record**: Record (a file name, or blank for ``facepuppet-YYYYmmdd-HHMMSS.fps`` next to the ``--record``
  file or in the current folder) and Stop, the file and its size on disk (``run``'s
  :class:`~facepuppet.runtime.recording.switch.SwitchableRecorder`: each recording replays like ``--record``'s).
* **Chain**: the stage chain; **Character**: name, shapes, credits.

Every edit is a config change: a copy of the pipeline's ``LiveConfig`` (``dataclasses.replace``) handed
to the pipeline's ``apply_config``, which applies it at the next tick. The status numbers that need a
percentile or a file size are refreshed twice a second, not every frame, so the panel's cost stays small;
so do the settings built only on a change, the channel rows as one item whose names and meters (plain
whole-pixel rectangles) go straight into the list's draw list, and the settings sections out of view built
as one blank item (:meth:`DeskPanel._section`).
Nothing is kept per frame.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from facepuppet.runtime.channels import canonical
from facepuppet.runtime.errors import FacepuppetError
from facepuppet.runtime.live.config import CURVES
from facepuppet.runtime.live.mapper import Mapper
from facepuppet.runtime.live.timing import DurationSketch
from facepuppet.runtime.live.tracking_loss import LOSS_MODES, LOSS_REGIONS, VOICE_REGIONS
from facepuppet.runtime.panel import load_imgui
from facepuppet.runtime.panel.apply import apply_config, clear_calibration, config_in_force
from facepuppet.runtime.panel.fanout import PanelIO
from facepuppet.runtime.panel.gl import ImguiGL

if TYPE_CHECKING:
    import moderngl

    from facepuppet.runtime.character import Character
    from facepuppet.runtime.live.config import LiveConfig
    from facepuppet.runtime.live.loop import TickInfo
    from facepuppet.runtime.live.pipeline import LivePipeline
    from facepuppet.runtime.live.stages import Chain
    from facepuppet.runtime.live.stats import LiveStats
    from facepuppet.runtime.recording.recorder import PacketRecorder
    from facepuppet.runtime.recording.switch import SwitchableRecorder

WEIGHT_REGIONS = ("eyes", "brows", "mouth", "other", "head")
#: per region: the ImGui ids of its two filter sliders and their :attr:`DeskPanel.rects` labels (made once)
_FILTER_LABELS = {r: (f"##cutoff.{r}", f"##beta.{r}", f"filter.{r}.min_cutoff", f"filter.{r}.beta")
                  for r in WEIGHT_REGIONS}
REFRESH_S = 0.5  # status numbers (rates, percentiles, file size) are recomputed this often
DRIVES_ROWS = 6  # rows of the selected channel's "drives" list shown at once (it scrolls)
#: ImGui frames per second at most: a tick closer than 0.9 / REBUILD_HZ to the last frame draws that frame
#: again (its buffers are uploaded already; only the draw calls), e.g. every other tick at 120 frames/s on arrival
REBUILD_HZ = 60.0
#: frames the settings' context is still built after an input event (ImGui takes one event per frame)
SETTLE_FRAMES = 3
SETTINGS_MIN_H = 150.0  # the settings' window under the desk's (a narrow window) is at least this tall
PANEL_WIDTH = 430
METER_W, METER_H, METER_GAP = 80.0, 12.0, 6.0  # a channel meter's size in pixels and the gap after it
METERS_W = 3 * (METER_W + METER_GAP) + 2.0  # the three meters of a row, before its name
#: meter colours (RGBA 0..1): raw, after the stages, after mapping; distinct so tests and eyes can tell them apart
METER_COLOURS = ((0.35, 0.55, 0.95, 1.0), (0.30, 0.85, 0.40, 1.0), (0.98, 0.60, 0.15, 1.0))
#: a counter is a drop reason when its name has one of these (malformed, unknown_address, non_finite, oversized,
#: filtered_sender, internal_error, stale_dropped, nonfinite_rejected, record_dropped, ...)
DROP_WORDS = ("drop", "malformed", "unknown", "finite", "oversized", "filtered", "error", "rejected", "truncated",
              "invalid", "bad")


#: characters the panel's font (ImGui's built-in, ASCII) lacks, written as ASCII
_NOT_IN_FONT = str.maketrans({"→": "->", "—": "-", "–": "-", "×": "x", "µ": "u", "©": "(c)", "’": "'", "“": '"',
                              "”": '"'})


def _value_text(name: str, values: tuple[float, float, float]) -> str:
    """A channel's three meter values as text (``-``: not sent / no shape)."""
    return f"{name}: " + "  ".join(f"{what} {v:.2f}" if math.isfinite(v) else f"{what} -"
                                  for what, v in zip(("raw", "filtered", "mapped"), values))


def _ascii(text: str) -> str:
    """``text`` for the panel's font: arrows and dashes as ASCII, anything else outside ASCII as '?'."""
    return text.translate(_NOT_IN_FONT).encode("ascii", "replace").decode("ascii")


class _Retained:
    """An ImGui window built only when needed (:meth:`due`), its last frame drawn again the other ticks.

    Built when never built, when what it shows changed (its key), when an event arrived, in the
    :data:`SETTLE_FRAMES` frames after either (ImGui takes a click over frames and lays out a moved or resized
    window's scrollbar a frame late), and while the operator is on it (the mouse over it, an item active, a text
    field with the keyboard).
    """

    __slots__ = ("built", "shown", "events", "settle", "busy", "builds", "last")

    def __init__(self, now: float) -> None:
        self.built, self.shown, self.events, self.settle, self.busy, self.builds = False, None, -1, 0, False, 0
        self.last = now  # when its last frame was built (ImGui's delta time)

    def due(self, key: tuple, events: int) -> bool:
        return not self.built or self.busy or self.settle > 0 or events != self.events or key != self.shown

    def done(self, key: tuple, events: int, io: Any, imgui: Any) -> None:
        """After a frame: remember what it showed (``key``, the events seen) and whether the operator is on it."""
        if not self.built or events != self.events or key != self.shown:
            self.settle = SETTLE_FRAMES  # a change: this frame and the next ones
        self.built, self.builds, self.events, self.shown = True, self.builds + 1, events, key
        self.settle = max(self.settle - 1, 0)
        self.busy = bool(io.want_capture_mouse or io.want_text_input or imgui.is_any_item_active())


class DeskPanel:
    """The live panel of one run.

    Parameters
    ----------
    ctx : moderngl.Context, the run's context
    fbo : moderngl.Framebuffer the character is drawn into (the renderer's ``fbo``: offscreen, or the window's)
    width, height : int, the framebuffer size in pixels (and, in a window, ``window_size`` the window's)
    pipeline : LivePipeline or None, the filter stage (edited through its ``apply_config``)
    chain : Chain or None, for the stage chain, the rig's channel names and the map step (its ``mapper``, shared
        with the frame loop)
    character : Character or None
    counters : callable returning the run's counter groups (``{"udp": {...}, "loop": {...}, ...}``) or None
    stats : LiveStats or None, for the receive→draw latency
    recorder : SwitchableRecorder (Record / Stop), PacketRecorder (shown only) or None
    input_kind, address : str, what the run listens to and where
    visible : bool, shown at start (Tab toggles it in a window)
    clock : callable returning seconds (monotonic; injectable for tests)
    window_size : (width, height) of the window in screen units (default the framebuffer size)
    names : the rig's channels drawn, in order (default ``chain.names``): the mapped meters read these

    Attributes
    ----------
    io : ImGui's IO of this panel's own ImGui context (tests and the window feed events here)
    rects : dict of widget label -> (x0, y0, x1, y1) in pixels, as last drawn (where to click)
    edits : int, config changes handed to the pipeline
    draw_s : float, seconds the last panel draw took on the CPU (build + submit, or the redraw of the last frame)
    rebuild_hz : float, ImGui frames per second at most (:data:`REBUILD_HZ`); ``reused`` counts the ticks that
        drew the last frame again instead
    draw_sketch : DurationSketch of every panel draw's CPU time (streaming: fixed memory in a long run)
    submit_sketch : DurationSketch of the GL part of it (buffer uploads and draw calls; on llvmpipe the
        vertex work of the draw calls runs here, on the calling thread)
    build_sketch : DurationSketch of the ImGui frame alone (status, sections, ``imgui.render``)
    calls_sketch : DurationSketch of the draw calls alone (on llvmpipe: the panel's vertex shading and triangle
        binning, done on the CPU; a GPU does it itself); ``draw_calls_s`` the last frame's (0 when hidden)
    cpu_sketch : DurationSketch of build + submit without the draw calls (what the panel costs the CPU on any
        OpenGL: the ImGui frame, the buffer uploads, the state changes)
    """

    def __init__(self, ctx: moderngl.Context, fbo: moderngl.Framebuffer, width: int, height: int, *,
                 pipeline: LivePipeline | None = None, chain: Chain | None = None,
                 character: Character | None = None, counters: Callable[[], dict] | None = None,
                 stats: LiveStats | None = None, recorder: SwitchableRecorder | PacketRecorder | None = None,
                 input_kind: str = "", address: str = "", visible: bool = True,
                 clock: Callable[[], float] = time.monotonic, window_size: tuple[int, int] | None = None,
                 names: tuple[str, ...] | None = None) -> None:
        self.imgui = imgui = load_imgui()
        self._prev_context = imgui.get_current_context()
        # three ImGui contexts: the desk's and the settings' windows, each built only when what it shows changes,
        # and the live layer over the desk (its status lines, meters and the selected channel's numbers), built
        # every frame; the window's events go to the two windows' contexts (PanelIO), none to the live layer
        self._context, desk_io, self.gl = self._new_context(ctx)
        self._settings_context, settings_io, self.gl_settings = self._new_context(ctx)
        self._live_context, _, self.gl_live = self._new_context(ctx)
        imgui.set_current_context(self._context)
        self.io = PanelIO(desk_io, settings_io)
        self._desk_io, self._settings_io = desk_io, settings_io
        self.width, self.height = int(width), int(height)
        self.window_size = window_size or (self.width, self.height)
        self.fbo = fbo
        self.pipeline, self.chain, self.character = pipeline, chain, character
        self.names = tuple(names) if names is not None else tuple(chain.names) if chain is not None else ()
        mapper = getattr(chain, "mapper", None)
        # the session's map step: the meters read what the loop maps each channel to (one cache, one drive)
        self.mapper = mapper if mapper is not None and mapper.names == self.names else Mapper(self.names)
        self.counters, self.stats, self.recorder = counters, stats, recorder
        self.input_kind, self.address = input_kind, address
        self.visible = bool(visible)
        self.clock = clock
        self.rects: dict[str, tuple[float, float, float, float]] = {}
        self.edits = 0
        self.draw_s = 0.0
        self.draw_sketch = DurationSketch()
        self.submit_sketch = DurationSketch()
        self.build_sketch = DurationSketch()
        self.calls_sketch = DurationSketch()
        self.cpu_sketch = DurationSketch()
        self.settings_sketch = DurationSketch()
        self.draw_calls_s = 0.0
        self.rebuild_hz = REBUILD_HZ
        self.reused = 0  # ticks that drew the live layer's last ImGui frame again
        self.live_builds = 0  # ImGui frames of the live layer built
        self._built = False  # the live layer's last frame is there to draw again
        self._last = clock()
        self._desk = _Retained(self._last)
        self._settings = _Retained(self._last)
        self._desk_bottom = 0.0  # the desk window's foot when last built (a narrow window: the settings go under)
        #: where the desk's last frame left room for the live layer: "status" (x, y, wrap width), "meters"
        #: (left, row 0's top, row pitch, bar offset, first row, end row, clip rectangle), "values" (x, y)
        self._live_at: dict[str, tuple] = {}
        self._status_h = 0.0  # the height of the status lines, as the live layer last laid them out
        self._rows: tuple = ()  # the channel rows shown this tick (indices into the channels)
        self._channels: tuple | None = None
        self._status: dict[str, Any] = {}
        self._refresh_at = -math.inf
        self._rate_base: tuple[float, int, int] | None = None
        self._ticks = 0
        self._last_raw_at: float | None = None
        self._values: tuple | None = None  # this frame's channels and values (raw, filtered, rig, mapped index)
        self.sent_only = True
        self.selected: str | None = None  # the channel the response editor edits
        self.profile_name = ""  # the Save as field
        self.record_name = ""  # the Record field (blank: a name from the date and time)
        self.profile_message = ""  # what the last Save / Save as / Revert did (or why it failed)
        self.profile_warning = ""  # the profile was made for another character or input
        self._profile_checked: object = None  # the profile path the warning was computed for
        self._config: LiveConfig | None = None
        self._lines: dict[str, str] = {}  # status lines built at each refresh, not every frame
        self._colours = [imgui.color_convert_float4_to_u32(imgui.ImVec4(*c)) for c in METER_COLOURS]
        self._spacing_y = imgui.get_style().item_spacing.y
        self._section_h: dict[str, float] = {}  # a settings section's height when last built (skipped unseen)
        self._section_rects: dict[str, set[str]] = {}  # the rects' labels of each settings section
        self._collect: set[str] | None = None  # the labels remembered by the section being built

    # -- the loop's overlay ----------------------------------------------------------------------

    def toggle(self) -> None:
        self.visible = not self.visible

    def _new_context(self, ctx: moderngl.Context) -> tuple[Any, Any, ImguiGL]:
        """A fresh ImGui context (no imgui.ini, one input event per frame), its IO and its renderer."""
        imgui = self.imgui
        context = imgui.create_context()
        imgui.set_current_context(context)
        io = imgui.get_io()
        io.set_ini_filename("")  # no imgui.ini written into the working folder
        io.config_input_trickle_event_queue = True
        return context, io, ImguiGL(ctx, imgui)

    @property
    def desk_builds(self) -> int:
        """ImGui frames of the desk's window built (the other ticks drew its last frame again)."""
        return self._desk.builds

    @property
    def settings_builds(self) -> int:
        """ImGui frames of the settings' window built (the other ticks drew its last frame again)."""
        return self._settings.builds

    def overlay(self, info: TickInfo) -> None:
        """FrameLoop overlay: count the tick, and when shown draw the panel into ``fbo`` (after the character):
        the desk's window, the live layer over it, the settings' window."""
        now = self.clock()
        self._ticks += 1
        if info.raw is not None:
            self._last_raw_at = now
        if not self.visible:
            self._last = now
            self.draw_calls_s = 0.0
            self._built = False  # the live layer's frame is stale; the windows' are not unless a key or event says
            return
        t0 = time.perf_counter()
        wide = self.window_size[0] >= 2 * PANEL_WIDTH + 200  # room for the settings beside the desk
        build_s = 0.0
        if now >= self._refresh_at:
            self._refresh(now)
        self._tick_values(info)
        desk, settings, imgui = self._desk, self._settings, self.imgui
        if desk.due(self._desk_key(wide), self.io.events):
            t1 = time.perf_counter()
            self._begin_frame(self._context, now - desk.last)
            desk.last = now
            self._config = None  # read afresh this frame
            self._build(now, wide)
            imgui.render()
            build_s += time.perf_counter() - t1
            self.gl.render(imgui.get_draw_data(), self.fbo)
            desk.done(self._desk_key(wide), self.io.events, self._desk_io, imgui)
        else:
            self.gl.redraw(self.fbo)
        calls = self.gl.draw_calls_s
        if self._built and now - self._last < 0.9 / self.rebuild_hz:  # the live layer's last frame is recent
            self.gl_live.redraw(self.fbo)
            self.reused += 1
        else:
            t1 = time.perf_counter()
            self._begin_frame(self._live_context, now - self._last)
            self._last = now
            self._live_layer(now)
            imgui.render()
            build_s += time.perf_counter() - t1
            self.gl_live.render(imgui.get_draw_data(), self.fbo)
            self._built = True
            self.live_builds += 1
        calls += self.gl_live.draw_calls_s
        if settings.due(self._settings_key(wide), self.io.events):
            t1 = time.perf_counter()
            self._begin_frame(self._settings_context, now - settings.last)
            settings.last = now
            self._settings_window(info, wide)
            imgui.render()
            t2 = time.perf_counter()
            build_s += t2 - t1
            self.gl_settings.render(imgui.get_draw_data(), self.fbo)
            settings.done(self._settings_key(wide), self.io.events, self._settings_io, imgui)
            self.settings_sketch.add(t2 - t1)
        else:
            self.gl_settings.redraw(self.fbo)
        calls += self.gl_settings.draw_calls_s
        imgui.set_current_context(self._context)
        self.draw_s = time.perf_counter() - t0
        self.draw_calls_s = calls
        self.draw_sketch.add(self.draw_s)
        self.submit_sketch.add(self.draw_s - build_s)
        if build_s > 0.0:  # a tick that built an ImGui frame (the others drew the last ones again)
            self.build_sketch.add(build_s)
        self.calls_sketch.add(calls)
        self.cpu_sketch.add(self.draw_s - calls)

    def _begin_frame(self, context: Any, dt: float) -> None:
        """Make ``context`` current and start its ImGui frame (display size and scale, ``dt`` since its last)."""
        imgui = self.imgui
        imgui.set_current_context(context)
        io = imgui.get_io()
        io.display_size = imgui.ImVec2(*self.window_size)
        io.display_framebuffer_scale = imgui.ImVec2(self.width / self.window_size[0],
                                                    self.height / self.window_size[1])
        io.delta_time = max(dt, 1e-4)
        imgui.new_frame()

    def _desk_key(self, wide: bool) -> tuple:
        """What the desk's window shows that can change without an event on it: the channels and the rows shown,
        the selection, the config in force (the Response section's values), the room the status lines need, the
        layout (the live layer draws the values that change every frame)."""
        return (self._channels, self._rows, self.selected, self.sent_only, id(getattr(self.pipeline, "config", None)),
                self._status_h, self.window_size, wide)

    def _settings_key(self, wide: bool) -> tuple:
        """What the settings show that can change without an event on them: the config in force (an edit in the
        desk's Response, a Revert, a Clear), the calibration's state, the recording's file, size and message,
        the profile's message and warning, the window's size and, in a narrow one, the desk's foot (the
        settings' window goes under it)."""
        p, rec = self.pipeline, self.recorder
        return (id(getattr(p, "config", None)), bool(getattr(p, "calibrating", False)),
                getattr(p, "counters", {}).get("calibrations", 0), getattr(p, "neutral_weights", None) is not None,
                self._status.get("record"), getattr(rec, "recording", None), getattr(rec, "message", None),
                getattr(getattr(self.chain, "profile", None), "exists", None), self.profile_message,
                self.profile_warning, self.window_size, wide, 0.0 if wide else self._desk_bottom)

    def _refresh(self, now: float) -> None:
        """Rates, drops, latency percentiles and the record size: twice a second."""
        self._refresh_at = now + REFRESH_S
        groups = dict(self.counters().items()) if self.counters is not None else {}  # items(): fresh udp
        udp = dict(groups.get("udp", {}))
        packets = int(udp.get("packets", 0))
        s = self._status
        if self._rate_base is not None and now > self._rate_base[0]:
            dt = now - self._rate_base[0]
            s["packets_s"] = (packets - self._rate_base[1]) / dt
            s["drawn_s"] = (self._ticks - self._rate_base[2]) / dt
        self._rate_base = (now, packets, self._ticks)
        drops = {}
        for group in ("udp", "loop"):
            for name, value in dict(groups.get(group, {})).items():
                if group == "loop" and name in drops:
                    continue  # the loop's stale_dropped counts the frames the receiver superseded: shown once
                if any(w in name for w in DROP_WORDS) and isinstance(value, (int, np.integer)) and value:
                    drops[f"{name}" if group == "udp" else f"{group}.{name}"] = int(value)
        s["drops"] = drops
        s["latency"] = None
        if self.stats is not None:
            since = s.get("stats_n", 0)
            lat = self.stats.latency(since=since, stages=("end_to_end",)).get("end_to_end", {})  # one: not all
            s["stats_n"] = getattr(self.stats, "_n", 0)
            if lat.get("n"):
                s["latency"] = (lat["p50_ms"], lat["p99_ms"], lat["n"])
        self._refresh_record()
        self._status_lines()

    def _refresh_record(self) -> None:
        """The recording's file and its size on disk."""
        s = self._status
        path = getattr(self.recorder, "path", None) if self.recorder is not None else None
        if path is not None:
            try:
                s["record"] = (str(path), os.path.getsize(path))
            except OSError:
                s["record"] = (str(path), None)
        else:
            s.pop("record", None)

    # -- content ------------------------------------------------------------------------------------

    def _remember(self, label: str) -> None:
        a, b = self.imgui.get_item_rect_min(), self.imgui.get_item_rect_max()
        self.rects[label] = (a.x, a.y, b.x, b.y)
        if self._collect is not None:
            self._collect.add(label)

    def _build(self, now: float, wide: bool) -> None:
        """The desk's window: input, channels, response, with room left for the live layer's lines and meters.
        In a ``wide`` window it is as tall as the window; in a narrow one as tall as its content, and the
        settings' window goes under it."""
        imgui = self.imgui
        w, h = self.window_size
        imgui.set_next_window_pos(imgui.ImVec2(8, 8), imgui.Cond_.first_use_ever)
        if wide:
            imgui.set_next_window_size(imgui.ImVec2(PANEL_WIDTH, h - 16), imgui.Cond_.first_use_ever)
        else:
            imgui.set_next_window_size(imgui.ImVec2(PANEL_WIDTH, 0.0), imgui.Cond_.always)  # 0: fit the content
        imgui.set_next_window_bg_alpha(0.85)
        imgui.begin("facepuppet desk (Tab hides)")
        self._live_at = {}
        self._input_section()
        self._channel_section()
        self._response_section()
        self._desk_bottom = float(int(imgui.get_window_pos().y + imgui.get_window_height()))
        imgui.end()

    def _settings_window(self, info: TickInfo, wide: bool) -> None:
        """The settings in a window of their own (their own ImGui context): at the right edge of a ``wide``
        window, else under the desk's (at least :data:`SETTINGS_MIN_H` tall, over the desk's foot if need be)."""
        imgui = self.imgui
        w, h = self.window_size
        if wide:
            imgui.set_next_window_pos(imgui.ImVec2(w - PANEL_WIDTH - 8, 8), imgui.Cond_.first_use_ever)
            imgui.set_next_window_size(imgui.ImVec2(PANEL_WIDTH, h - 16), imgui.Cond_.first_use_ever)
        else:
            top = max(min(self._desk_bottom + 8.0, h - SETTINGS_MIN_H - 8.0), 8.0)
            imgui.set_next_window_pos(imgui.ImVec2(8, top), imgui.Cond_.always)
            imgui.set_next_window_size(imgui.ImVec2(PANEL_WIDTH, h - 8.0 - top), imgui.Cond_.always)
        imgui.set_next_window_bg_alpha(0.85)
        imgui.begin("settings")
        self._config = None  # read afresh: the desk's frame may be an older one drawn again
        self._settings_sections(info)
        imgui.end()

    def _settings_sections(self, info: TickInfo) -> None:
        section = self._section
        section("filter", self._filter_section)
        section("calibration", self._calibration_section)
        section("face", self._face_section)
        section("profile", self._profile_section)
        section("loss", self._loss_section)
        section("record", self._record_section, info)
        section("info", self._info_section)

    def _section(self, key: str, build: Callable[..., None], *args: Any) -> None:
        """Build a settings section, or, when the window shows none of it (scrolled out, or below the window's
        bottom), only a blank item as tall as it was when last built: ImGui's clipping still costs a Python call
        per widget, this costs one. Its widgets' :attr:`rects` are dropped while it is not drawn (nothing to
        click). A section comes back the frame its space scrolls into view."""
        imgui = self.imgui
        h = self._section_h.get(key, 0.0)
        if h > self._spacing_y and not imgui.is_rect_visible(imgui.ImVec2(1.0, h)):
            imgui.dummy(imgui.ImVec2(0.0, h - self._spacing_y))  # the cursor moves on by h, as after the section
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

    def _input_section(self) -> None:
        """The Input header and room for the status lines (the live layer writes them: :meth:`_status_text`)."""
        imgui = self.imgui
        if not imgui.collapsing_header("Input", imgui.TreeNodeFlags_.default_open):
            return
        p = imgui.get_cursor_screen_pos()
        wrap = imgui.get_content_region_avail().x
        imgui.dummy(imgui.ImVec2(wrap, max(self._status_h, imgui.get_text_line_height())))
        self._live_at["status"] = (float(int(p.x)), float(int(p.y)), wrap)

    def _status_text(self, now: float) -> tuple[str, str]:
        """The status lines (where, rates, last frame and tracking, latency) and the drops line, this tick."""
        if not self._lines:
            self._status_lines()
        lines = self._lines
        age = "no frame yet" if self._last_raw_at is None else f"{(now - self._last_raw_at) * 1e3:.0f} ms"
        state = getattr(self.pipeline, "tracking_state", "-")  # waiting / live / lost / easing
        events = getattr(self.pipeline, "events", ())
        last = (f" ({'found' if events[-1][1] else 'lost'} at {events[-1][0]:.1f} s)" if events else "")
        return (f"{lines['where']}\n{lines['rates']}\nlast frame: {age}   tracking: {state}{last}\n{lines['latency']}",
                lines["drops"])

    def _status_lines(self) -> None:
        """The input section's lines that change only with the status numbers (at each refresh)."""
        s = self._status
        lat = s.get("latency")
        drops = s.get("drops") or {}
        self._lines = {
            "where": f"{self.input_kind or '-'} on {self.address or '-'}",
            "rates": (f"{s['packets_s']:.1f} packets/s, {s['drawn_s']:.1f} frames drawn/s" if "packets_s" in s
                      else "packets/s and frames drawn/s: measuring"),
            "latency": ("receive->draw: no frames in the last 0.5 s" if lat is None
                        else f"receive->draw p50 {lat[0]:.2f} ms, p99 {lat[1]:.2f} ms ({lat[2]} frames)"),
            "drops": "drops: " + (", ".join(f"{k} {v}" for k, v in sorted(drops.items())) or "none")}

    def _filter_section(self) -> None:
        imgui, pipeline = self.imgui, self.pipeline
        if pipeline is None or not imgui.collapsing_header("Filter (One Euro)", imgui.TreeNodeFlags_.default_open):
            return
        config = self._config_now()
        filters = dict(config.filters)
        changed = False
        slider, same_line, remember, log = imgui.slider_float, imgui.same_line, self._remember, \
            imgui.SliderFlags_.logarithmic
        imgui.push_item_width(130)  # one width for the section's sliders, not one call per slider
        for region, (cutoff_id, beta_id, cutoff_rect, beta_rect) in _FILTER_LABELS.items():
            fs = filters[region]
            c1, cutoff = slider(cutoff_id, fs.min_cutoff, 0.05, 10.0, "%.2f Hz", log)
            remember(cutoff_rect)
            same_line()
            c2, beta = slider(beta_id, fs.beta, 0.0, 5.0, "beta %.2f")
            remember(beta_rect)
            same_line()
            imgui.text_unformatted(region)
            if c1 or c2:
                # only the value dragged changes: ImGui hands back float32, the other keeps its exact value
                filters[region] = replace(fs, min_cutoff=max(float(cutoff), 1e-3) if c1 else fs.min_cutoff,
                                          beta=max(float(beta), 0.0) if c2 else fs.beta)
                changed = True
        imgui.pop_item_width()
        if changed:
            self.apply(replace(config, filters=filters))

    def _slider(self, label: str, value: float, lo: float, hi: float, fmt: str) -> tuple[bool, float]:
        imgui = self.imgui
        imgui.set_next_item_width(170)
        changed, v = imgui.slider_float(f"##{label}", float(value), lo, hi, fmt)
        self._remember(f"response.{label}")
        return changed, float(v)

    def _selected_values(self, name: str) -> tuple[float, float, float] | None:
        """This frame's raw, filtered and mapped value of channel ``name`` (None: not among the channels)."""
        if self._values is None:
            return None
        channels, raw_v, flt_v, rig_v, mapped = self._values
        try:
            i = channels.index(name)
        except ValueError:
            return None
        m = mapped[i]
        return (raw_v[i] if raw_v is not None else math.nan, flt_v[i] if flt_v is not None else math.nan,
                rig_v[m] if rig_v is not None and m >= 0 else math.nan)

    def _response_section(self) -> None:
        """The response of the selected channel: gain, clamp, input range -> output range, curve."""
        imgui, pipeline = self.imgui, self.pipeline
        if pipeline is None or not imgui.collapsing_header("Response (click a channel)",
                                                           imgui.TreeNodeFlags_.default_open):
            return
        name = self.selected
        if name is None:
            imgui.text("no channel selected: click a channel's name above")
            return
        config = self._config_now()
        key = canonical(name)
        cs = config.channel(name)
        imgui.text(f"{name}" + ("" if key in config.channels else " (default response)"))
        self._remember("response.name")
        if self._selected_values(name) is not None:  # room for the meters' numbers of it (the live layer's)
            p = imgui.get_cursor_screen_pos()
            imgui.dummy(imgui.ImVec2(imgui.get_content_region_avail().x, imgui.get_text_line_height()))
            self._remember("response.values")
            self._live_at["values"] = (float(int(p.x)), float(int(p.y)))
        imgui.push_id("response")
        new = cs
        c, v = self._slider("gain", cs.gain, 0.0, 3.0, "gain %.2f")
        if c:
            new = replace(new, gain=v)
        lo, hi = cs.clamp
        c1, v1 = self._slider("clamp_low", lo, -1.0, 2.0, "clamp low %.2f")
        imgui.same_line()
        c2, v2 = self._slider("clamp_high", hi, -1.0, 2.0, "clamp high %.2f")
        if c1 or c2:  # low <= high: the one dragged pushes the other
            lo, hi = (v1, max(v1, hi)) if c1 else (min(lo, v2), v2)
            new = replace(new, clamp=(lo, hi))
        ilo, ihi = cs.input_range or (0.0, 1.0)
        c1, v1 = self._slider("in_low", ilo, -1.0, 2.0, "in %.2f")
        imgui.same_line()
        c2, v2 = self._slider("in_high", ihi, -1.0, 2.0, "to %.2f")
        if c1 or c2:  # low < high (the config's rule): the one dragged pushes the other
            ilo, ihi = (v1, max(v1 + 1e-3, ihi)) if c1 else (min(ilo, v2 - 1e-3), v2)
            new = replace(new, input_range=(ilo, ihi))
        ofrom, oto = cs.output_range or (0.0, 1.0)
        c1, v1 = self._slider("out_from", ofrom, -1.0, 2.0, "out %.2f")
        imgui.same_line()
        c2, v2 = self._slider("out_to", oto, -1.0, 2.0, "to %.2f")
        if c1 or c2:  # from > to is allowed: an inverted channel
            new = replace(new, output_range=(v1 if c1 else ofrom, v2 if c2 else oto))
        for curve in CURVES:
            if imgui.radio_button(curve, cs.curve == curve) and curve != cs.curve:
                new = replace(new, curve=curve)
            self._remember(f"response.curve.{curve}")
            imgui.same_line()
        imgui.new_line()
        if cs.curve == "threshold":
            c, v = self._slider("threshold", cs.threshold, 0.0, 1.0, "threshold %.2f")
            if c:
                new = replace(new, threshold=v)
        mapping = self._drives_list(name, config) if getattr(self.chain, "elastic", None) is None else None
        reset = imgui.button("Reset")
        self._remember("response.reset")
        imgui.pop_id()
        if mapping is not None:
            self.apply(replace(config, mapping=mapping))
            return
        channels = dict(config.channels)
        if reset and key in channels:
            del channels[key]
            self.apply(replace(config, channels=channels))
        elif new != cs:
            channels[key] = new
            self.apply(replace(config, channels=channels))

    def _drives_list(self, name: str, config) -> Any:
        """What the selected channel drives, as ``[mapping.channels]`` says it (runtime.expressions): by name (no
        entry: the routes a channel takes without one), nothing, or one shape or expression of the character at
        weight 1. Returns the new MappingSettings when one is picked, else None. An entry of several targets or
        weights written in ``--config`` is shown as written and kept until another choice replaces it."""
        from facepuppet.runtime.expressions import MappingTarget

        imgui = self.imgui
        key = canonical(name)
        targets = config.mapping.channels.get(key)
        drive = self.mapper.drive
        choices = list(self.names) + [e for e in (drive.expression_names if drive is not None else ())
                                      if e not in self.names]
        if targets is None:
            shown = "(by name)"
        elif not targets:
            shown = "(nothing)"
        else:
            shown = ", ".join(t.to if t.weight == 1.0 else f"{t.to} x{t.weight:g}" for t in targets)
        picked = None
        imgui.text(f"drives: {shown}")
        self._remember("response.drives")
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
                self._remember(f"response.drives.{label}")
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

    def _face_section(self) -> None:
        imgui, pipeline = self.imgui, self.pipeline
        if pipeline is None or not imgui.collapsing_header("Face", imgui.TreeNodeFlags_.default_open):
            return
        config = self._config_now()
        c1, link = imgui.checkbox("link blinks (both eyes from the stronger)", config.link_blinks)
        self._remember("face.link_blinks")
        c2, mirror = imgui.checkbox("mirror (left/right, head yaw and roll)", config.mirror)
        self._remember("face.mirror")
        if c1 or c2:
            self.apply(replace(config, link_blinks=bool(link), mirror=bool(mirror)))

    def _loss_section(self) -> None:
        imgui, pipeline = self.imgui, self.pipeline
        if pipeline is None or not imgui.collapsing_header("Tracking loss", imgui.TreeNodeFlags_.default_open):
            return
        config = self._config_now()
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
                self._remember(f"loss.{region}.{mode}")
            imgui.pop_id()
        if changed:
            self.apply(replace(config, loss=replace(config.loss, modes=modes)))

    def _check_profile(self, profile: Any) -> None:
        """The mismatch warning of the profile's file (read once per path and after each Save / Revert)."""
        from facepuppet.runtime.live.profiles import read_made_for

        self._profile_checked = profile.path
        try:
            made = read_made_for(profile.path) if profile.path.exists() else {}
        except (OSError, ValueError) as exc:
            self.profile_warning = f"cannot read {profile.path}: {exc}"
            return
        notes = [f"{what} {theirs!r} (this run: {mine!r})"
                 for what, mine in (("character", profile.character), ("input", profile.input_kind))
                 if mine and (theirs := made.get(what)) and theirs != mine]
        self.profile_warning = ("made for " + ", ".join(notes) + "; its settings apply by channel name") \
            if notes else ""

    def _profile_section(self) -> None:
        imgui, pipeline = self.imgui, self.pipeline
        profile = getattr(self.chain, "profile", None)
        if profile is None or pipeline is None or not imgui.collapsing_header("Profile",
                                                                              imgui.TreeNodeFlags_.default_open):
            return
        if self._profile_checked != profile.path:
            self._check_profile(profile)
        imgui.text_wrapped(f"{profile.path}" + ("" if profile.exists else " (not saved yet)"))
        if self.profile_warning:
            imgui.push_style_color(imgui.Col_.text, imgui.ImVec4(1.0, 0.75, 0.2, 1.0))
            imgui.text_wrapped(f"warning: {self.profile_warning}")
            imgui.pop_style_color()
            self._remember("profile.warning")
        action = None
        if imgui.button("Save"):
            action = "save"
        self._remember("profile.save")
        imgui.same_line()
        if imgui.button("Revert"):
            action = "revert"
        self._remember("profile.revert")
        imgui.set_next_item_width(200)
        _, self.profile_name = imgui.input_text_with_hint("##profile_name", "name or path.toml", self.profile_name)
        self._remember("profile.name")
        imgui.same_line()
        if imgui.button("Save as"):
            action = "save_as"
        self._remember("profile.save_as")
        if self.profile_message:
            imgui.text_wrapped(self.profile_message)
        if action is not None:
            self.profile_action(action)

    def profile_action(self, action: str) -> None:
        """``save``, ``save_as`` (to :attr:`profile_name`) or ``revert`` the run's profile; the outcome (or the
        error, which loses nothing: the config in force stays) in :attr:`profile_message`."""
        profile, pipeline = self.chain.profile, self.pipeline
        try:
            if action == "save":
                self.profile_message = f"saved {profile.save(config_in_force(pipeline))}"
            elif action == "save_as":
                name = self.profile_name.strip()
                if not name:
                    self.profile_message = "Save as: type a profile name or a path to a .toml file first"
                    return
                self.profile_message = f"saved {profile.save_as(name, config_in_force(pipeline))}"
            elif action == "revert":
                self.apply(profile.revert())
                self.profile_message = f"reverted to {profile.path}"
            else:
                raise ValueError(f"profile action: expected save, save_as or revert, got {action!r}")
        except (OSError, ValueError, FacepuppetError) as exc:
            self.profile_message = f"{action}: failed: {exc}"
        self._check_profile(profile)

    def _calibration_section(self) -> None:
        imgui, pipeline = self.imgui, self.pipeline
        if pipeline is None or not imgui.collapsing_header("Calibration", imgui.TreeNodeFlags_.default_open):
            return
        if imgui.button("Calibrate"):
            pipeline.request_calibration()
        self._remember("calibrate")
        imgui.same_line()
        if imgui.button("Clear"):
            clear_calibration(pipeline)
        self._remember("clear")
        imgui.same_line()
        neutral = "capturing..." if getattr(pipeline, "calibrating", False) else \
            ("neutral set" if getattr(pipeline, "neutral_weights", None) is not None else "no neutral")
        imgui.text(f"{neutral} ({pipeline.counters.get('calibrations', 0)} calibrations)")

    def _record_section(self, info: TickInfo) -> None:
        """Record / Stop (a run's :class:`~facepuppet.runtime.recording.switch.SwitchableRecorder`), the file
        and its size (refreshed with the status numbers)."""
        imgui, rec = self.imgui, self.recorder
        if not imgui.collapsing_header("Record", imgui.TreeNodeFlags_.default_open):
            return
        shown = self._status.get("record")
        recording = bool(getattr(rec, "recording", rec is not None))
        if shown is None:
            imgui.text("not recording" if rec is not None else "record: off (--record FILE)")
        else:
            size = "-" if shown[1] is None else f"{shown[1] / 1e6:.2f} MB"
            imgui.text_wrapped(f"{'recording' if recording else 'stopped'}: {shown[0]} ({size})")
        if not hasattr(rec, "start"):
            return
        action = None
        imgui.push_id("record")  # the button "Record" is not the header "Record"
        if recording:
            if imgui.button("Stop"):
                action = "stop"
            self._remember("record.stop")
        else:
            if imgui.button("Record"):
                action = "start"
            self._remember("record.start")
            imgui.same_line()
            imgui.set_next_item_width(-1)
            _, self.record_name = imgui.input_text_with_hint("##record_name", "file (default: facepuppet-DATE-TIME)",
                                                            self.record_name)
            self._remember("record.name")
        imgui.pop_id()
        if rec.message and not (recording and rec.message == f"recording to {rec.path}"):  # not the line above again
            imgui.text_wrapped(rec.message)
        if action is not None:
            self.record_action(action)

    def record_action(self, action: str) -> None:
        """``start`` a recording (to :attr:`record_name`, blank: the default name; the config in force its
        first CONFIG) or ``stop`` it; a failure is in the recorder's message and loses nothing."""
        rec = self.recorder
        if action == "stop":
            rec.stop()
        elif action == "start":
            text = None
            if self.pipeline is not None:
                from facepuppet.runtime.live.profiles import config_to_toml

                text = config_to_toml(config_in_force(self.pipeline))
            try:
                rec.start(self.record_name, config_text=text)
            except (OSError, ValueError):
                pass  # said in rec.message, shown under the buttons
        else:
            raise ValueError(f"record action: expected start or stop, got {action!r}")
        self._refresh_record()  # the new file and its size at once

    def _info_section(self) -> None:
        imgui = self.imgui
        shown = imgui.collapsing_header("Chain, character")
        self._remember("header.chain")
        if not shown:
            return
        if self.chain is not None:
            imgui.text_wrapped(_ascii(self.chain.describe()))
            self._remember("chain.text")
        ch = self.character
        if ch is not None:
            imgui.text_wrapped(_ascii(f"character: {ch.name}, {len(ch.shape_names)} shapes"))
            self._remember("character.text")
            if getattr(ch, "credits", None):
                imgui.text_wrapped(_ascii(f"credits: {ch.credits}"))

    def _mapped_index(self, channels: tuple) -> np.ndarray:
        """For each input channel what it drives (-1: none), from the session's map step (the loop's own maps):
        with an expression drive (a VRM character, a ``[mapping]``) the first shape or expression its map sends
        it to (``n_shapes + e`` for expression e: the meters read the shapes' weights followed by the
        expressions' values); else the shape of the same name, or the first the by-name channel map sends it to
        (an unsided browInnerUp drives browInnerUp_L)."""
        return self.mapper.first_targets(channels)[0]

    def _tick_values(self, info: TickInfo) -> None:
        """This tick's channels and values (raw, after the stages, the rig's; :attr:`_values`) and the rows shown
        (:attr:`_rows`: all channels, or those the input sends). The values are read as Python floats once per
        tick (three ``tolist``), not through NumPy per row."""
        raw = info.raw
        frame = info.frame
        channels = (raw.channels if raw is not None and raw.channels else
                    frame.channels if frame is not None and frame.channels else None)
        self._channels = channels
        if channels is None:
            self._values, self._rows = None, ()
            return
        raw_w = raw.weights if raw is not None and raw.channels == channels else None
        if raw_w is not None:
            self._last_raw_w = raw_w
        elif getattr(self, "_last_raw_w", None) is not None and len(self._last_raw_w) == len(channels):
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
        self._values = (channels, raw_v, flt_v, rig_v, mapped)  # the Response section reads the selected one's
        if self.sent_only and raw_v is not None:  # NaN: not sent (a VMC sender names only some channels)
            self._rows = tuple(i for i, v in enumerate(raw_v) if v == v)
        else:
            self._rows = tuple(range(len(channels)))

    def _row_values(self, i: int) -> tuple[float, float, float]:
        """Channel ``i``'s raw, filtered and mapped value this tick (NaN: not sent / no shape)."""
        _, raw_v, flt_v, rig_v, mapped = self._values
        m = mapped[i]
        nan = math.nan
        return (raw_v[i] if raw_v is not None else nan, flt_v[i] if flt_v is not None else nan,
                rig_v[m] if rig_v is not None and m >= 0 else nan)

    def _channel_section(self) -> None:
        """One row per channel: three meters (raw, after the stages, after mapping) and the name (click: select).

        The rows are one invisible button (a click selects the row under the mouse, a hover shows its numbers in
        a tooltip); the names of the rows in view, the selection and the meters' frames are drawn straight into
        the child window's draw list; the meters' bars, whose lengths are this tick's values, by the live layer
        (:meth:`_draw_meters`) where this leaves them room (the numbers of the selected channel are in the
        Response section).
        """
        imgui = self.imgui
        if not imgui.collapsing_header("Channels: raw | filtered | mapped", imgui.TreeNodeFlags_.default_open):
            return
        channels = self._channels
        if channels is None:
            imgui.text("no channels yet")
            return
        _, self.sent_only = imgui.checkbox("only the channels the input sends", self.sent_only)
        rows = self._rows
        # as tall as its rows, at most a third of the window (then it scrolls; the sections below stay in view)
        n = len(rows)
        pitch = imgui.get_text_line_height_with_spacing()
        fit = max(n, 1) * pitch + 2 * imgui.get_style().window_padding.y
        height = min(fit, max(120.0, 0.35 * self.window_size[1]))
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
        dy = float(int(0.5 * (pitch - METER_H)))  # whole pixels: see _draw_meters
        ty = 0.5 * (pitch - imgui.get_text_line_height())
        dl = imgui.get_window_draw_list()
        selected = self.selected
        text_col = imgui.get_color_u32(imgui.Col_.text)
        add_text, rects = dl.add_text, self.rects
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
                imgui.set_tooltip(_value_text(name, self._row_values(i)))
        if last > first:  # per column one background strip from the first row's top to the last row's bottom
            top0 = float(int(origin.y + first * pitch)) + dy
            bottom = float(int(origin.y + (last - 1) * pitch)) + dy + METER_H
            frame_col = imgui.get_color_u32(imgui.Col_.frame_bg)
            for j in range(3):
                x = left + j * (METER_W + METER_GAP)
                dl.add_rect_filled(vec(x, top0), vec(x + METER_W, bottom), frame_col)
                self.rects[f"meter.0.{j}"] = (x, top0, x + METER_W, top0 + METER_H)  # the first row in view's
            wp, ws = imgui.get_window_pos(), imgui.get_window_size()
            self._live_at["meters"] = (left, float(int(origin.y)), pitch, dy, first, last,
                                       (wp.x, wp.y, wp.x + ws.x, wp.y + ws.y))
        imgui.end_child()

    def _live_layer(self, now: float) -> None:
        """This tick's values over the desk's last frame, into the live context's foreground list: the status
        lines, the meters' bars and the selected channel's numbers, where the desk left them room. When the
        status lines need more (or less) room than the desk left, the desk is built again next tick."""
        imgui = self.imgui
        at = self._live_at
        fg = imgui.get_foreground_draw_list()
        col = imgui.get_color_u32(imgui.Col_.text)
        where = at.get("status")
        if where is not None:
            x, y, wrap = where
            lines, drops = self._status_text(now)
            fg.add_text(imgui.ImVec2(x, y), col, lines)
            lines_h = imgui.calc_text_size(lines).y + self._spacing_y
            fg.add_text(imgui.get_font(), imgui.get_font_size(), imgui.ImVec2(x, y + lines_h), col, drops, wrap)
            self._status_h = float(lines_h + imgui.calc_text_size(drops, wrap_width=wrap).y)  # the desk's key
        meters = at.get("meters")
        if meters is not None and self._values is not None:
            self._draw_meters(fg, meters)
        where = at.get("values")
        if where is not None and self.selected is not None:
            values = self._selected_values(self.selected)
            if values is not None:
                fg.add_text(imgui.ImVec2(*where), col, _value_text("now", values))

    def _draw_meters(self, dl: Any, layout: tuple) -> None:
        """The bars of the rows in view, into the live layer's draw list ``dl`` (the desk drew their frames):
        per meter a bar as long as its value, a dash for none, clipped to the channel list. Corners on whole
        pixels: ImGui draws a rectangle with a fractional corner as an anti-aliased path (30 indices instead of
        6; llvmpipe's draw call costs by the index)."""
        imgui = self.imgui
        left, top0, pitch, dy, first, last, clip = layout
        rows = self._rows
        vec, rect, line = imgui.ImVec2, dl.add_rect_filled, dl.add_line
        step = METER_W + METER_GAP
        colours, dash_col = self._colours, None
        row_values = self._row_values
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

    # -- edits --------------------------------------------------------------------------------------

    def _config_now(self) -> LiveConfig:
        """The config in force, read once per panel frame (and the one handed over since, after an edit)."""
        if self._config is None:
            self._config = config_in_force(self.pipeline)
        return self._config

    def apply(self, config: LiveConfig) -> None:
        """Hand a changed config to the pipeline (applied at its next tick)."""
        apply_config(self.pipeline, config)
        self._config = config  # a later section of the same frame edits on top of it
        self.edits += 1

    def close(self) -> None:
        if self._context is None:
            return
        for gl in (self.gl, self.gl_settings, self.gl_live):
            gl.release()
        for context in (self._live_context, self._settings_context, self._context):
            self.imgui.destroy_context(context)
        self._context = self._settings_context = self._live_context = None
