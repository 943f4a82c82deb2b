"""What the control verbs do to the show, and what the show tells the control clients.

:class:`ShowActions` carries out ``calibrate``, ``profile``, ``record`` and ``framing`` on the frame loop's
thread (the control stage calls them at the tick it applies them); each returns "" when done, else why not.
:class:`ShowState` is a tick observer that keeps the newest tick's figures (one tuple, swapped whole, so the
server's thread reads a consistent one) and builds the ``list``, ``status`` and ``weights`` replies from them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from facepuppet.runtime.control.commands import Command
from facepuppet.runtime.live.profiles import Profile, config_to_toml, profile_path, profiles_dir
from facepuppet.runtime.render.camera import Camera
from facepuppet.runtime.render.framing import frame_character

if TYPE_CHECKING:
    from facepuppet.runtime.control.stage import ControlStage
    from facepuppet.runtime.live.loop import TickInfo
    from facepuppet.runtime.live.stages import Chain
    from facepuppet.runtime.model.character import Character
    from facepuppet.runtime.protocols import Renderer
    from facepuppet.runtime.recording.switch import SwitchableRecorder

MAX_PROFILES_LISTED = 200


def trigger_names(chain: Chain) -> tuple[str, ...]:
    """What may be triggered: the character's VRM expressions, else the channels the renderer draws."""
    drive = chain.drive
    if drive is not None and drive.expression_names:
        return tuple(drive.expression_names)
    return tuple(chain.names)


class ShowActions:
    """The verbs other than ``expression`` (see the module docstring).

    Parameters
    ----------
    chain : Chain, the session's (its filter stage, its profile, its known channels)
    recorder : SwitchableRecorder or None
    renderer : Renderer, whose camera ``framing`` moves
    character : Character, what the framing fits
    """

    def __init__(self, chain: Chain, recorder: SwitchableRecorder | None, renderer: Renderer, character: Character,
                 log: Callable[[str], None]) -> None:
        self.chain, self.recorder, self.renderer, self.character, self.log = chain, recorder, renderer, character, log
        self.profile_name: str | None = chain.profile.path.stem if chain.profile is not None else None

    def table(self) -> dict[str, Callable[[Command], str]]:
        return {"calibrate": self.calibrate, "profile": self.profile, "record": self.record, "framing": self.framing}

    def calibrate(self, command: Command) -> str:
        if self.chain.filter is None:
            return "no filter stage in this session, nothing to calibrate"
        self.chain.filter.request_calibration()
        return ""

    def profile(self, command: Command) -> str:
        pipeline = self.chain.filter
        if pipeline is None:
            return "no filter stage in this session to take a profile"
        path = profile_path(command.args["name"])
        if not path.is_file():
            return f"no profile {command.args['name']!r} in {profiles_dir()}"
        profile = Profile(path, character=getattr(self.character, "name", "") or "", input_kind=self.chain.input,
                          known_channels=self.chain.known_channels, log=self.log)
        pipeline.apply_config(profile.load())
        self.chain.profile = profile  # the panel's Save and --save-profile write to the profile in force
        self.profile_name = path.stem
        return ""

    def record(self, command: Command) -> str:
        recorder = self.recorder
        if recorder is None:
            return "no recording possible in this session"
        if command.args["action"] == "stop":
            recorder.stop()
            return ""
        text = config_to_toml(self.chain.filter.current_config()) if self.chain.filter is not None else None
        try:
            recorder.start(command.args.get("name", ""), config_text=text)
        except (OSError, ValueError) as exc:
            return str(exc)
        return ""

    def framing(self, command: Command) -> str:
        inner = getattr(self.renderer, "renderer", self.renderer)  # the elastic path wraps a FaceRenderer
        if not hasattr(inner, "camera"):
            return "this renderer has no camera to frame"
        a = command.args
        name = a["framing"] or getattr(inner, "framing", "head")
        base = frame_character(self.character, name, inner.width / inner.height)
        # zoom and pan after the projection: x_ndc' = zoom * x_ndc + pan_x (pan in halves of the view)
        m = np.eye(4)
        m[0, 0] = m[1, 1] = a["zoom"]
        m[0, 3], m[1, 3] = a["pan"]
        inner.camera = Camera(base.eye, base.view, (m @ base.projection).astype(np.float32))
        inner.framing = name
        return ""


class ShowState:
    """The newest tick's figures for the control clients (a tick observer; see the module docstring).

    Parameters
    ----------
    chain : Chain; stage : ControlStage; actions : ShowActions; recorder : SwitchableRecorder or None
    loop_counters : callable() -> dict, the frame loop's counters (frames received, late ticks)
    """

    def __init__(self, chain: Chain, stage: ControlStage, actions: ShowActions, recorder: SwitchableRecorder | None,
                 loop_counters: Callable[[], dict] = dict) -> None:
        self.chain, self.stage, self.actions, self.recorder = chain, stage, actions, recorder
        self.loop_counters = loop_counters
        self.shapes = tuple(chain.names)
        drive = chain.drive
        self.expression_names = tuple(drive.expression_names) if drive is not None else ()
        self.latest: tuple = (-1, 0.0, None, None, math.nan, math.nan)
        self._fps = 0.0
        self._last_clock: float | None = None

    def __call__(self, info: TickInfo) -> None:
        """The tick observer: the tick's weights (copied), its draw time and the frame's age when drawn."""
        now = time.monotonic()
        if self._last_clock is not None and now > self._last_clock:
            self._fps += 0.1 * (1.0 / (now - self._last_clock) - self._fps)
        self._last_clock = now
        raw = info.raw
        age_ms = (info.stamps[4] - raw.t) * 1e3 if raw is not None and 0 < raw.t <= info.stamps[4] else math.nan
        expressions = None if info.expressions is None else np.array(info.expressions, dtype=np.float32)
        self.latest = (info.k, info.t, np.array(info.weights, dtype=np.float32), expressions,
                       (info.stamps[4] - info.stamps[0]) * 1e3, age_ms)

    def answer(self, verb: str) -> dict[str, Any]:
        if verb == "list":
            return {"expressions": list(self.stage.triggers.names), "profiles": self._profiles(),
                    "profile": self.actions.profile_name, "shapes": list(self.shapes)}
        k, t, weights, expressions, tick_ms, age_ms = self.latest
        if verb == "weights":
            return {"tick": k, "t": t,
                    "weights": {} if weights is None else dict(zip(self.shapes, map(float, weights))),
                    "expressions": {} if expressions is None else dict(zip(self.expression_names,
                                                                          map(float, expressions))),
                    "triggered": self.stage.triggers.active()}
        pipeline, rec = self.chain.filter, self.recorder
        return {"tick": k, "t": t, "fps": round(self._fps, 2), "tick_ms": tick_ms, "latency_ms": age_ms,
                "tracking": pipeline.tracking_state if pipeline is not None else None,
                "calibrating": bool(pipeline.calibrating) if pipeline is not None else False,
                "recording": bool(rec is not None and rec.recording),
                "recording_path": str(rec.path) if rec is not None and rec.path is not None else None,
                "profile": self.actions.profile_name, "loop": dict(self.loop_counters()),
                "control": self.stage.status()}

    @staticmethod
    def _profiles() -> list[str]:
        folder = profiles_dir()
        if not folder.is_dir():
            return []
        names = []
        for path in folder.iterdir():
            if path.suffix == ".toml" and path.is_file():
                names.append(path.stem)
                if len(names) >= MAX_PROFILES_LISTED:
                    break
        return sorted(names)
