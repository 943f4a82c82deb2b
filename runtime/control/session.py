"""The control API in a session: the ``control`` stage, and with ``--web`` its servers, opened in one place.

:func:`open_control` is called by the session assembler once the renderer exists (framing moves its camera,
the view page reads its frames) and before the frame loop is made (the stage joins the chain). A live run
with ``--web`` gets the stage, the WebSocket server with its pages, the OSC port and the hotkeys of a window;
a replay of a recording with CONTROL records gets the stage alone, applying the recorded commands at their
ticks. Anything else gets nothing: the chain and its printed line stay as they were.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib.util import find_spec
from typing import TYPE_CHECKING, Any

from facepuppet.runtime.control.hotkeys import bind_hotkeys
from facepuppet.runtime.control.options import ControlOptions
from facepuppet.runtime.control.osc_server import OscControl
from facepuppet.runtime.control.server import ControlServer, describe
from facepuppet.runtime.control.show import ShowActions, ShowState, trigger_names
from facepuppet.runtime.control.stage import ControlStage
from facepuppet.runtime.control.view_frames import grab
from facepuppet.runtime.errors import UsageError

if TYPE_CHECKING:
    from facepuppet.runtime.live.bus import SessionBus
    from facepuppet.runtime.live.loop import TickInfo
    from facepuppet.runtime.live.stages import Chain
    from facepuppet.runtime.model.character import Character
    from facepuppet.runtime.protocols import Renderer
    from facepuppet.runtime.render.gl_context import GLTarget
    from facepuppet.runtime.session.feeds import FeedParts

logger = logging.getLogger(__name__)


@dataclass
class ControlParts:
    """What :func:`open_control` opened.

    Attributes
    ----------
    stage : ControlStage, in the chain
    server : ControlServer or None; osc : OscControl or None; show : ShowState or None
    observers : list of TickObserver, for the frame loop (the show's figures)
    overlays : list of loop overlays, called before the panel's (the view frames: read back before the panel
        is drawn over the picture, so the view page never shows the panel)
    counters : dict of counter group -> counters (``control``, ``web``, ``osc_control``)
    """

    stage: ControlStage
    server: ControlServer | None = None
    osc: OscControl | None = None
    show: ShowState | None = None
    observers: list = field(default_factory=list)
    overlays: list = field(default_factory=list)
    counters: dict = field(default_factory=dict)


def open_control(stack: contextlib.ExitStack, options: ControlOptions | None, chain: Chain, bus: SessionBus,
                 parts: FeedParts, renderer: Renderer, character: Character, log: Callable[[str], None] = logger.info,
                 loop_counters: Callable[[], dict] = dict, target: GLTarget | None = None,
                 panel: Any = None) -> ControlParts | None:
    """The control stage (and ``--web``'s servers, a window's ``[hotkeys]``), or None when the session has no
    control at all. ``target``: the session's GL target (its window takes the hotkeys); ``panel``: the shown
    DeskPanel or None (its text fields keep the keys)."""
    web = options.web if options is not None else None
    schedule = list(getattr(parts, "controls", ()) or ())
    config = chain.config
    hotkeys = tuple(getattr(config, "hotkeys", ()) or ()) if parts.live else ()
    window = target is not None and not target.headless
    if hotkeys and not window:
        log("control: [hotkeys] are keys of the window; a headless run has none")
    if web is None and not schedule and not (hotkeys and window):
        return None
    actions = ShowActions(chain, parts.recorder, renderer, character, log)
    names = trigger_names(chain)
    shapes = names == tuple(chain.names)  # no VRM expressions: the shapes are triggered, over the mapped frame
    stage = ControlStage(names, actions.table(), publish=bus.publish_control, schedule=schedule, log=log,
                         mapper=chain.mapper if shapes else None)
    chain.stages = (*chain.stages, stage)
    opened = ControlParts(stage, counters={"control": stage.counters})
    if hotkeys and window:
        typing = (lambda: bool(panel.visible and panel.io.want_text_input)) if panel is not None else (lambda: False)
        bind_hotkeys(target.window, hotkeys, stage.submit, typing)
        log(f"control: hotkeys {', '.join(key for key, _ in hotkeys)} (the config's [hotkeys])")
    if web is None:
        return opened
    if find_spec("websockets") is None:
        raise UsageError("--web: needs the web extra (the websockets package): pip install 'facepuppet[web]'")
    show = ShowState(chain, stage, actions, parts.recorder, loop_counters)
    server = ControlServer(web[0], web[1], token=options.token, submit=stage.submit, answer=show.answer,
                           view_fps=options.view_fps, log=log)
    try:
        address = server.start()
    except OSError as exc:
        raise UsageError(f"--web {web[0]}:{web[1]}: cannot listen there: {exc.strerror or exc}") from None
    stack.callback(server.close)
    try:
        osc = OscControl(address[0], address[1], token=options.token, submit=stage.submit, log=log)
    except OSError as exc:
        raise UsageError(f"--web {address[0]}:{address[1]}: cannot take UDP port {address[1]} for OSC: "
                         f"{exc.strerror or exc}") from None
    stack.callback(osc.close)
    log(describe(address, options.token))
    if options.generated:
        log(f"web: the token of this run (listening on {address[0]}, not loopback): {options.token}")
    opened.server, opened.osc, opened.show = server, osc, show
    opened.observers = [show]
    opened.overlays = [view_grabber(server)]
    opened.counters.update(web=server.counters, osc_control=osc.counters)
    return opened


def view_grabber(server: ControlServer) -> Callable[[TickInfo], None]:
    """The loop overlay that reads the drawn frame back for the view pages when one is due (else costs one
    check); as an overlay it runs after the character's draw and before the panel's."""
    def observe(info: TickInfo) -> None:
        now = time.monotonic()
        if server.wants_frame(now):
            width, height, flags, rgba = grab(info.renderer)
            server.offer_frame(width, height, flags, info.k, rgba, now)
    return observe
