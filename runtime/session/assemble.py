"""One assembler for every session that plays a character: ``run``, ``replay``, ``demo`` and the benchmarks.

:func:`open_session` builds, in this order and inside one ``contextlib.ExitStack`` that owns everything it
opened:

1. the feed's inputs (:meth:`~facepuppet.runtime.session.feeds.Feed.prepare`: input kind, audio level, a
   recorded config) and the session's :class:`~facepuppet.runtime.live.bus.SessionBus`;
2. the stage chain (:func:`~facepuppet.runtime.live.stages.build_chain`), whose filter stage publishes config
   changes and tracking events on the bus;
3. the feed's frame sources (:meth:`~facepuppet.runtime.session.feeds.Feed.open`: receivers, a recording,
   the mix, the recorder), which subscribe to the bus;
4. the GL context and the renderer;
5. the outputs (:func:`~facepuppet.runtime.session.outputs.open_outputs`: weights, PNGs, video, VMC, Live
   Link Face, tracking events), the live stats and the operator's panel;
6. the frame loop, with one list of tick observers.

Whatever fails on the way closes what was opened before it, in reverse order; a video being written is
removed rather than left half-written. The caller runs the loop (:meth:`Session.run`) inside the ``with``
and reports after it, once every file is complete::

    with open_session(character, feed, stages=..., outputs=..., picture=...) as session:
        result = session.run()
    print(...)
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from facepuppet.runtime.control.session import open_control
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.live.bus import SessionBus
from facepuppet.runtime.live.draw_budget import DrawBudgetWatch
from facepuppet.runtime.live.loop import FrameLoop
from facepuppet.runtime.live.stages import build_chain
from facepuppet.runtime.live.stats import LiveStats
from facepuppet.runtime.render.gl_context import create_context
from facepuppet.runtime.render.quality import budget_note, choose_quality
from facepuppet.runtime.session.options import OutputOptions, PanelOptions, PictureOptions, StageOptions
from facepuppet.runtime.session.outputs import Outputs, open_outputs

if TYPE_CHECKING:
    from facepuppet.runtime.cli.progress import Progress
    from facepuppet.runtime.control.options import ControlOptions
    from facepuppet.runtime.live.loop import LoopResult
    from facepuppet.runtime.live.sinks import WeightLog
    from facepuppet.runtime.live.stages import Chain
    from facepuppet.runtime.model.character import Character
    from facepuppet.runtime.protocols import Renderer, TickObserver
    from facepuppet.runtime.render.gl_context import GLTarget
    from facepuppet.runtime.session.feeds import Feed, FeedParts

logger = logging.getLogger(__name__)

NO_STAGES, NO_OUTPUTS, DEFAULT_PICTURE, NO_PANEL = StageOptions(), OutputOptions(), PictureOptions(), PanelOptions()


@dataclass
class SessionResult:
    """What one session did.

    Attributes
    ----------
    loop : LoopResult, ticks, counters and timings of the frame loop
    path : str, the deformation path drawn on
    chain : str, the stage chain as printed at start
    outputs : Outputs, what was written and sent (``weights``: the WeightLog, when kept)
    counters : dict of counter group -> counters at the end (the loop's, the receivers', the outputs', ...)
    stats : LiveStats or None (a live feed's latencies)
    address : (host, port) or None, where a live feed listened
    panel : DeskPanel or None (closed)
    fps : float, ticks per second of the tick grid
    recorder : the feed's SwitchableRecorder or None (closed once the session's block ends; its ``failure``
        says when a recording could not be written to its end, which stopped the run)
    saturation : SaturationCount or None, the marker solve's frames at its limits (None without a solve)
    """

    loop: LoopResult
    path: str
    chain: str
    outputs: Outputs
    counters: dict
    stats: LiveStats | None
    address: tuple | None
    panel: Any
    fps: float
    recorder: Any = None
    saturation: Any = None

    @property
    def weights(self) -> WeightLog | None:
        return self.outputs.weights


@dataclass
class Session:
    """The parts :func:`open_session` assembled (see the module docstring); :meth:`run` runs the loop."""

    character: Character
    feed: Feed
    bus: SessionBus
    chain: Chain
    parts: FeedParts
    target: GLTarget
    renderer: Renderer
    outputs: Outputs
    stats: LiveStats | None
    panel: Any
    loop: FrameLoop
    counters: dict
    on_ready: Callable[[tuple], None] | None = None

    def run(self) -> SessionResult:
        """Run the frame loop to its end (the source's, ``--duration``, the window closing, a stop)."""
        if self.on_ready is not None:
            self.on_ready(self.parts.address)
        result = self.feed.run(self.loop, self.parts)
        self.counters["loop"] = result.counters
        counters = (self.stats.counter_snapshot() if self.stats is not None
                    else {group: dict(values) for group, values in self.counters.items()})
        return SessionResult(result, self.renderer.path, self.chain.describe(), self.outputs, counters, self.stats,
                             self.parts.address, self.panel, self.parts.fps, self.parts.recorder,
                             self.chain.saturation)


@contextlib.contextmanager
def open_session(character: Character, feed: Feed, *, stages: StageOptions = NO_STAGES,
                 outputs: OutputOptions = NO_OUTPUTS, picture: PictureOptions = DEFAULT_PICTURE,
                 panel: PanelOptions = NO_PANEL, observers: Sequence[TickObserver] = (),
                 keep_weights: bool = False, stats_interval_s: float | None = None,
                 on_chain: Callable[[Chain], None] | None = None, on_panel: Callable[[Any], None] | None = None,
                 on_ready: Callable[[tuple], None] | None = None, progress: Progress | None = None,
                 log: Callable[[str], None] = logger.info, context: GLTarget | None = None,
                 keeps_pictures: bool = False, control: ControlOptions | None = None) -> Iterator[Session]:
    """Assemble a session (see the module docstring); everything opened is closed when the block ends.

    Parameters
    ----------
    character : Character, what is drawn
    feed : Feed, what feeds the frames (:class:`~facepuppet.runtime.session.live_feed.LiveFeed`,
        :class:`~facepuppet.runtime.session.recording_feed.RecordingFeed`, a
        :class:`~facepuppet.runtime.session.feeds.FramesFeed`)
    stages, outputs, picture, panel : the option groups
    observers : tick observers of the caller's (a benchmark's probe, a test's hook), called after the
        pictures and the live stats, before what is sent
    keep_weights : bool, keep every tick's weights (``SessionResult.weights``) even without ``--dump-weights``
    stats_interval_s : float or None, a live feed's stats line every this many seconds (``--stats``)
    on_chain : called with the stage chain once built (tests drive its filter, benchmarks read it)
    on_panel : called with the panel once made (tests and benchmarks drive it)
    on_ready : called with the feed's address once everything is open, before the first tick
    progress : Progress or None, told the count of video frames written
    context : GLTarget or None, a headless context of the caller's to draw in instead of a new one, left open
        when the session ends (a batch worker draws job after job in one: making an EGL context costs more
        than a short take's replay)
    keeps_pictures : bool, an observer of the caller's keeps pictures as files (a batch job's frames at chosen
        times): they are drawn at full quality, as ``--out`` and ``--video`` are, not at a live budget
    control : ControlOptions or None, ``run --web``: the control API (:mod:`~facepuppet.runtime.control`); a
        replay of recorded control commands gets the control stage without it

    Raises
    ------
    ValueError, FileNotFoundError
        for bad options or files (named); OSError when an address cannot be bound;
        GLUnavailable when no OpenGL context can be made.
    """
    with contextlib.ExitStack() as stack:
        if character.credits:
            log(f"credits: {character.credits}")
        inputs = feed.prepare(character, stack, log)
        bus = SessionBus(packets=inputs.packets)
        chain = build_chain(stages, character, inputs.kind, bus=bus, filtered=inputs.filtered,
                            audio_level=inputs.audio_level, voice_only=inputs.voice_only, label=inputs.label,
                            log=log, config_text=inputs.config_text, schedule=inputs.schedule,
                            keep_snapshots=inputs.keep_snapshots, voice=inputs.voice)
        parts = feed.open(stack, chain, bus, log)
        log(chain.describe())
        if on_chain is not None:
            on_chain(chain)
        # pictures kept as files are drawn at full quality
        live = outputs.out is None and outputs.video is None and not keeps_pictures
        target, renderer = _open_picture(stack, picture, feed.title, chain, character, live, parts.fps, log,
                                         context)
        watch = None
        if live and picture.render.msaa is None and picture.render.quality == "auto" \
                and getattr(renderer, "samples", 0):
            watch = DrawBudgetWatch(renderer, 1e3 / parts.fps, log)
        counters = dict(parts.counters)
        stats = None
        if parts.live:
            stats = LiveStats(counters, log=log, interval_s=stats_interval_s)
            observers = (stats.on_tick, *observers)
        paced = outputs.sends and not parts.live
        opened = open_outputs(outputs, stack, chain, bus, parts.fps, keep_weights=keep_weights, paced=paced,
                              progress=progress, extra=observers, log=log)
        counters.update(opened.counters)
        shown = _open_panel(stack, panel, picture, target, renderer, chain, character, stats, parts, log) \
            if parts.live else None
        if shown is not None and on_panel is not None:
            on_panel(shown)
        if shown is not None and watch is not None:
            watch.retarget.append(shown.draw_into)
        if shown is None and not target.headless and chain.filter is not None:
            _bind_calibrate_key(target, chain.filter)
        controlled = open_control(stack, control, chain, bus, parts, renderer, character, log,
                                  loop_counters=lambda: counters.get("loop", {}), target=target, panel=shown)
        if controlled is not None:
            counters.update(controlled.counters)
        loop = FrameLoop(chain.names, renderer, feed.clock(parts, target, paced),
                         observers=[*opened.observers, *parts.observers, *([watch] if watch else []),
                                    *(controlled.observers if controlled is not None else ())],
                         fps=parts.fps, log=log, target=target,
                         stages=chain.stages, stop=getattr(feed, "stop", None), catch_up=parts.catch_up,
                         idle_fps=parts.idle_fps,
                         overlays=(*(controlled.overlays if controlled is not None else ()),
                                   *(() if shown is None else (shown.overlay,))),
                         wake=parts.wake, mapper=chain.mapper)
        counters["loop"] = loop.counters
        if stats is not None:
            stats.counters = feed.counters_view(parts, counters, chain)
            if chain.saturation is not None:
                stats.sections["saturation"] = chain.saturation.fractions
        yield Session(character, feed, bus, chain, parts, target, renderer, opened, stats, shown, loop, counters,
                      on_ready)


def _open_picture(stack: contextlib.ExitStack, picture: PictureOptions, title: str, chain: Chain,
                  character: Character, live: bool, fps: float, log: Callable[[str], None],
                  given: GLTarget | None = None) -> tuple[GLTarget, Renderer]:
    """The GL context (a window, or headless) and the renderer, at the picture quality of
    :mod:`~facepuppet.runtime.render.quality`: a window is opened again without multisampling when its
    renderer turns out to be a software rasteriser; an offscreen picture is drawn without MSAA when a few
    timed frames take more than the live share of the frame budget. A ``given`` context (headless, the
    caller's) is drawn in and left open."""
    render = picture.render
    asked = choose_quality(render.msaa, render.quality, None, live=False).msaa  # before the renderer is known

    def context(samples: int) -> GLTarget:
        return create_context(headless=True if picture.headless else None, width=picture.width,
                              height=picture.height, title=title, log=log, samples=samples,
                              transparent=render.transparent)

    target = context(asked) if given is None else given
    quality = choose_quality(render.msaa, render.quality, target.ctx.info.get("GL_RENDERER"), live)
    if quality.note:
        log(quality.note)
        if not target.headless and target.samples and target.samples != quality.msaa:
            target.close()
            target = context(quality.msaa)
    if given is None:
        stack.callback(target.close)
    screen = None if target.headless else target.ctx.screen

    def renderer_at(samples: int) -> Renderer:
        return chain.renderer(target.ctx, character, picture.width, picture.height, picture.path, screen, log,
                              **render.renderer_kwargs(dataclasses.replace(quality, msaa=samples)),
                              credits=character.credits if render.credits else None, springs=picture.springs)

    renderer = renderer_at(quality.msaa)
    budgeted = live and render.msaa is None and render.quality == "auto"
    if budgeted and getattr(renderer, "samples", 0):
        note = budget_note(renderer.median_draw_ms(), 1e3 / fps, renderer.samples)
        if note:
            log(note)
            renderer.close()
            renderer = renderer_at(0)
    stack.callback(renderer.close)
    return target, renderer


def _open_panel(stack: contextlib.ExitStack, options: PanelOptions, picture: PictureOptions, target: GLTarget,
                renderer: Renderer, chain: Chain, character: Character, stats: LiveStats | None,
                parts: FeedParts, log: Callable[[str], None]):
    """The operator's panel (:mod:`~facepuppet.runtime.panel`): in a window always (Tab toggles), headless only
    with ``--panel``. Without imgui-bundle a window runs without it (said once); ``--panel`` is then an error."""
    from facepuppet.runtime.panel import PanelUnavailable  # the panel is an optional extra (imgui-bundle)

    if target.headless and not options.panel:
        return None
    try:
        from facepuppet.runtime.panel.desk import DeskPanel

        window_size = None
        if not target.headless:
            import glfw

            window_size = glfw.get_window_size(target.window)
        address = parts.address
        panel = DeskPanel(target.ctx, renderer.fbo, picture.width, picture.height, pipeline=chain.filter,
                          chain=chain, character=character, counters=lambda: stats.counters, stats=stats,
                          recorder=parts.recorder, input_kind=parts.input_name,
                          address=f"{address[0]}:{address[1]}" if address else "", window_size=window_size,
                          visible=not options.hidden)
    except PanelUnavailable as exc:
        if options.panel:
            raise UsageError(f"--panel: {exc}") from None
        log(f"run: no panel: {exc}; the run goes on without it")
        return None
    stack.callback(panel.close)
    if not target.headless:
        from facepuppet.runtime.panel.glfw_input import bind_window

        bind_window(target.window, panel,
                    on_calibrate=chain.filter.request_calibration if chain.filter is not None else None)
        log("run: the panel is shown; Tab hides or shows it")
    return panel


def _bind_calibrate_key(target: GLTarget, pipeline) -> None:
    """In a window without the panel, the key C requests a calibration."""
    import glfw

    def on_key(window, key, scancode, action, mods):
        if key == glfw.KEY_C and action == glfw.PRESS:
            pipeline.request_calibration()

    glfw.set_key_callback(target.window, on_key)
