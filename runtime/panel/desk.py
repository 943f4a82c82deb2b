"""The operator's panel of one run (:class:`DeskPanel`): its three ImGui contexts, when each is built, its draw.

Two windows, each in its own ImGui context: the desk (input status, channels, the selected channel's response)
and the settings (filters, calibration, face, profile, tracking loss, record, chain and character; at the right
edge of a window wide enough for both and some face, else under the desk). Each is built only when what it shows
changes (its key), when an event arrives (:class:`~facepuppet.runtime.panel.fanout.PanelIO` hands the window's
events to both) and while the operator is on it (:class:`~facepuppet.runtime.panel.retained.Retained`); the
other ticks draw its last frame again. The third context, the live layer, writes what changes every tick into
the room the desk's last frame left: the status lines, the meters' bars, the selected channel's numbers. All
three are drawn into the character's framebuffer (:class:`~facepuppet.runtime.panel.gl.ImguiGL`) as a
:class:`~facepuppet.runtime.live.loop.FrameLoop` overlay: after the character's draw call, before the GPU wait,
with that tick's :class:`~facepuppet.runtime.live.loop.TickInfo`, so the meters show the frame on screen.

What the parts show is in their modules: :mod:`~facepuppet.runtime.panel.status` (Input),
:mod:`~facepuppet.runtime.panel.channels` (the channel list and meters), :mod:`~facepuppet.runtime.panel.sections`
(the sections that edit the run; an edit is a copy of the config in force handed to the pipeline's
``apply_config``: :meth:`DeskPanel.apply`), :mod:`~facepuppet.runtime.panel.ui` (what they draw with). The cost
per frame stays small: windows built only on a change, ImGui frames at most :data:`REBUILD_HZ` a second, status
numbers refreshed twice a second, whole-pixel meters, settings sections out of view built as one blank item.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from facepuppet.runtime.live.mapper import Mapper
from facepuppet.runtime.live.timing import DurationSketch
from facepuppet.runtime.panel import load_imgui
from facepuppet.runtime.panel.apply import apply_config, config_in_force
from facepuppet.runtime.panel.channels import ChannelList, value_text
from facepuppet.runtime.panel.fanout import PanelIO
from facepuppet.runtime.panel.gl import ImguiGL
from facepuppet.runtime.panel.retained import Retained
from facepuppet.runtime.panel.sections.calibration import calibration_section
from facepuppet.runtime.panel.sections.face import face_section
from facepuppet.runtime.panel.sections.filters import filter_section
from facepuppet.runtime.panel.sections.info import info_section
from facepuppet.runtime.panel.sections.profile import ProfileControls
from facepuppet.runtime.panel.sections.record import RecordControls
from facepuppet.runtime.panel.sections.response import response_section
from facepuppet.runtime.panel.sections.tracking_loss import loss_section
from facepuppet.runtime.panel.sections.voice import VoiceControls
from facepuppet.runtime.panel.status import InputStatus
from facepuppet.runtime.panel.ui import Ui

if TYPE_CHECKING:
    import moderngl

    from facepuppet.runtime.live.config import LiveConfig
    from facepuppet.runtime.live.loop import TickInfo
    from facepuppet.runtime.live.pipeline import LivePipeline
    from facepuppet.runtime.live.stages import Chain
    from facepuppet.runtime.live.stats import LiveStats
    from facepuppet.runtime.model.character import Character
    from facepuppet.runtime.recording.recorder import PacketRecorder
    from facepuppet.runtime.recording.switch import SwitchableRecorder

#: ImGui frames per second at most: a tick closer than 0.9 / REBUILD_HZ to the last frame draws that frame
#: again (its buffers are uploaded already; only the draw calls), e.g. every other tick at 120 frames/s on arrival
REBUILD_HZ = 60.0
SETTINGS_MIN_H = 150.0  # the settings' window under the desk's (a narrow window) is at least this tall
PANEL_WIDTH = 430


class _Forward:
    """A public attribute of the panel that one of its parts keeps (``panel.selected`` is the channel list's)."""

    def __init__(self, part: str, name: str) -> None:
        self.part, self.name = part, name

    def __get__(self, panel: Any, owner: type | None = None) -> Any:
        return self if panel is None else getattr(getattr(panel, self.part), self.name)

    def __set__(self, panel: Any, value: Any) -> None:
        setattr(getattr(panel, self.part), self.name, value)


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
    mapper : Mapper, the session's map step (what each channel drives)
    selected : str or None, the channel the Response section edits (a click on a channel row selects it)
    sent_only : bool, channel rows only for the channels the input sends
    profile_name, profile_message, profile_warning : str, the Profile section's Save as field, what its last
        button did, and the warning of a profile made for another character or input
    record_name : str, the Record section's file field (blank: a name from the date and time)
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
    settings_sketch : DurationSketch of the settings' ImGui frames
    """

    selected = _Forward("_list", "selected")
    sent_only = _Forward("_list", "sent_only")
    profile_name = _Forward("_profile", "name")
    profile_message = _Forward("_profile", "message")
    profile_warning = _Forward("_profile", "warning")
    record_name = _Forward("_record", "name")

    def __init__(self, ctx: moderngl.Context, fbo: moderngl.Framebuffer, width: int, height: int, *,
                 pipeline: LivePipeline | None = None, chain: Chain | None = None,
                 character: Character | None = None, counters: Callable[[], dict] | None = None,
                 stats: LiveStats | None = None, recorder: SwitchableRecorder | PacketRecorder | None = None,
                 input_kind: str = "", address: str = "", visible: bool = True,
                 clock: Callable[[], float] = time.monotonic, window_size: tuple[int, int] | None = None,
                 names: tuple[str, ...] | None = None) -> None:
        self.imgui = imgui = load_imgui()
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
        self.pipeline, self.chain, self.character, self.recorder = pipeline, chain, character, recorder
        self.names = tuple(names) if names is not None else tuple(chain.names) if chain is not None else ()
        mapper = getattr(chain, "mapper", None)
        # the session's map step: the meters read what the loop maps each channel to (one cache, one drive)
        self.mapper = mapper if mapper is not None and mapper.names == self.names else Mapper(self.names)
        self.visible = bool(visible)
        self.clock = clock
        self.ui = Ui(imgui)
        self.rects = self.ui.rects
        self._input = InputStatus(counters=counters, stats=stats, recorder=recorder, pipeline=pipeline,
                                  input_kind=input_kind, address=address, voice=getattr(chain, "voice", None))
        self._status = self._input.numbers  # the status numbers (the settings show the recording's)
        self._list = ChannelList(imgui, self.mapper)
        self._profile = ProfileControls()
        self._voice = VoiceControls()
        self._record = RecordControls(self._input)
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
        self._desk = Retained(self._last)
        self._settings = Retained(self._last)
        self._desk_bottom = 0.0  # the desk window's foot when last built (a narrow window: the settings go under)
        #: where the desk's last frame left room for the live layer: "status" (x, y, wrap width), "meters"
        #: (left, row 0's top, row pitch, bar offset, first row, end row, clip rectangle), "values" (x, y)
        self._live_at: dict[str, tuple] = {}
        self._config: LiveConfig | None = None

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
        status = self._input
        status.ticks += 1
        if info.raw is not None:
            status.last_raw_at = now
        if not self.visible:
            self._last = now
            self.draw_calls_s = 0.0
            self._built = False  # the live layer's frame is stale; the windows' are not unless a key or event says
            return
        t0 = time.perf_counter()
        wide = self.window_size[0] >= 2 * PANEL_WIDTH + 200  # room for the settings beside the desk
        build_s = 0.0
        if now >= status.refresh_at:
            self._refresh(now)
        self._list.tick(info)
        desk, settings, imgui = self._desk, self._settings, self.imgui
        if desk.due(self._desk_key(wide), self.io.events):
            t1 = time.perf_counter()
            self._begin_frame(self._context, now - desk.last)
            desk.last = now
            self._config = None  # read afresh this frame
            self._build(wide)
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
            self._settings_window(wide)
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
        rows = self._list
        return (rows.channels, rows.rows, rows.selected, rows.sent_only, id(getattr(self.pipeline, "config", None)),
                self._input.height, self.window_size, wide)

    def _settings_key(self, wide: bool) -> tuple:
        """What the settings show that can change without an event on them: the config in force (an edit in the
        desk's Response, a Revert, a Clear), the calibration's state, the recording's file, size and message,
        the profile's message and warning, the window's size and, in a narrow one, the desk's foot (the
        settings' window goes under it)."""
        p, rec, profile = self.pipeline, self.recorder, self._profile
        return (id(getattr(p, "config", None)), bool(getattr(p, "calibrating", False)),
                getattr(p, "counters", {}).get("calibrations", 0), getattr(p, "neutral_weights", None) is not None,
                self._status.get("record"), getattr(rec, "recording", None), getattr(rec, "message", None),
                getattr(getattr(self.chain, "profile", None), "exists", None), profile.message,
                profile.warning, self.window_size, wide, 0.0 if wide else self._desk_bottom, self._voice.key())

    def _refresh(self, now: float) -> None:
        """The status numbers (rates, drops, latency percentiles, the record size) and their lines."""
        self._input.refresh(now)

    # -- the windows ------------------------------------------------------------------------------

    def _build(self, wide: bool) -> None:
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
        self._live_at = at = {}
        self._input.room(imgui, at)
        self._list.section(self.rects, at, h)
        if self.pipeline is not None:
            elastic = getattr(self.chain, "elastic", None) is not None  # maps through its model: no drives list
            self._edit(response_section, self._list, at, None if elastic else self._drive_choices)
        self._desk_bottom = float(int(imgui.get_window_pos().y + imgui.get_window_height()))
        imgui.end()

    def _drive_choices(self) -> list[str]:
        """What a channel may drive: the rig's shapes, then the drive's expressions not named like a shape."""
        drive = self.mapper.drive
        return list(self.names) + [e for e in (drive.expression_names if drive is not None else ())
                                   if e not in self.names]

    def _settings_window(self, wide: bool) -> None:
        """The settings in a window of their own (their own ImGui context): at the right edge of a ``wide``
        window, else under the desk's (at least :data:`SETTINGS_MIN_H` tall, over the desk's foot if need be).
        Their sections in order; those out of view are built as a blank item (:meth:`Ui.section`)."""
        imgui, ui, pipeline = self.imgui, self.ui, self.pipeline
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
        section, edit = ui.section, self._edit
        if pipeline is not None:  # the sections of the filter stage's config and state
            section("filter", edit, filter_section)
            section("calibration", calibration_section, ui, pipeline)
            section("face", edit, face_section)
            section("profile", self._profile.section, ui, getattr(self.chain, "profile", None), pipeline,
                    self.apply)
            section("loss", edit, loss_section)
        section("record", self._record.section, ui, self.recorder, pipeline)
        if getattr(self.chain, "voice", None) is not None:
            section("voice", self._voice.section, ui, self.chain.voice)
        section("info", info_section, ui, self.chain, self.character)
        imgui.end()

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
            self._input.draw(imgui, fg, col, where, now, self.ui.spacing_y)
        rows = self._list
        meters = at.get("meters")
        if meters is not None and rows.values is not None:
            rows.draw_meters(fg, meters)
        where = at.get("values")
        if where is not None and rows.selected is not None:
            values = rows.values_of(rows.selected)
            if values is not None:
                fg.add_text(imgui.ImVec2(*where), col, value_text("now", values))

    def _selected_values(self, name: str) -> tuple[float, float, float] | None:
        """This frame's raw, filtered and mapped value of channel ``name`` (None: not among the channels)."""
        return self._list.values_of(name)

    def _mapped_index(self, channels: tuple) -> np.ndarray:
        """For each input channel what it drives (-1: none), from the session's map step (the loop's own maps):
        with an expression drive (a VRM character, a ``[mapping]``) the first shape or expression its map sends
        it to (``n_shapes + e`` for expression e: the meters read the shapes' weights followed by the
        expressions' values); else the shape of the same name, or the first the by-name channel map sends it to
        (an unsided browInnerUp drives browInnerUp_L)."""
        return self.mapper.first_targets(channels)[0]

    # -- edits --------------------------------------------------------------------------------------

    def _edit(self, section: Callable[..., LiveConfig | None], *args: Any) -> None:
        """Build a section that edits the config (:mod:`~facepuppet.runtime.panel.sections`); hand the copy it
        edited to the pipeline."""
        config = section(self.ui, self._config_now, *args)
        if config is not None:
            self.apply(config)

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

    def profile_action(self, action: str) -> None:
        """``save``, ``save_as`` (to :attr:`profile_name`) or ``revert`` the run's profile; the outcome (or the
        error, which loses nothing: the config in force stays) in :attr:`profile_message`."""
        self._profile.action(action, self.chain.profile, self.pipeline, self.apply)

    def record_action(self, action: str) -> None:
        """``start`` a recording (to :attr:`record_name`, blank: the default name; the config in force its
        first CONFIG) or ``stop`` it; a failure is in the recorder's message and loses nothing."""
        self._record.action(action, self.recorder, self.pipeline)

    def draw_into(self, fbo: moderngl.Framebuffer) -> None:
        """Draw into ``fbo`` from the next frame on (the renderer's new framebuffer, when it changed samples)."""
        self.fbo = fbo

    def close(self) -> None:
        if self._context is None:
            return
        for gl in (self.gl, self.gl_settings, self.gl_live):
            gl.release()
        for context in (self._live_context, self._settings_context, self._context):
            self.imgui.destroy_context(context)
        self._context = self._settings_context = self._live_context = None
