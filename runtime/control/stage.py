"""The ``control`` stage: commands applied at the next tick, and the triggered expressions laid over the face.

The servers (WebSocket, OSC) and the hotkeys run on threads of their own; they only append checked
:class:`~facepuppet.runtime.control.commands.Command` objects to :attr:`ControlStage.inbox` (a deque: an append
is atomic and never blocks). The frame loop's thread takes them at the start of its next tick, applies them
and publishes each on the session's bus at that tick's time, where the recorder writes it as a CONTROL record.
A replay hands the recorded commands in as :attr:`schedule` and applies each at the tick of its time, so it
computes what the live run drew.

**Stacking with the tracker's channels.** The stage runs last in the chain, after the filter, calibration,
tracking loss, gestures and kernel PLS, so a triggered value is exactly what was asked for (never filtered,
offset by the neutral or eased by a tracking loss). While every expression is at rest the frames pass through
untouched: a run with the control API and nothing triggered draws what it draws without it. While one is not:

* a character with VRM expressions gets each triggered expression written into the frame as a channel of the
  expression's name: where the frame already has that channel (a VMC sender naming ``Joy``) the two combine by
  their maximum, a trigger never lowers what the tracker does; where it has not, the channel is added (NaN,
  not sent, for the expressions at rest). A named expression channel wins over the default ARKit to VRM
  preset mapping in every frame that sends it (:mod:`~facepuppet.runtime.mapping.expressions`), so while
  ``Blink`` is triggered the tracker's eyeBlink channels do not also drive ``Blink``;
* a character without VRM expressions (its shapes are what is triggered) gets the frame mapped onto its
  shapes here, by the session's own map (the one the loop would use), each triggered shape raised to its
  value where the tracker drives it less, and the frame handed on in the shapes' own layout. Adding a shape's
  name as a channel instead would change how the tracker's other channels map (an unsided ``browInnerUp``
  no longer split onto ``browInnerUp_L``).

Every command applied is recorded; a replay applies ``expression`` and ``framing`` again. ``calibrate`` and
``profile`` reach a replay through what they did: the config they put in force (a CONFIG record, neutral
included). ``record`` is not part of the show (a start is the first CONTROL record of the file it starts).
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from facepuppet.runtime.control.commands import Command, CommandError, parse_command
from facepuppet.runtime.control.triggers import ExpressionTriggers
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.mapper import Mapper
from facepuppet.runtime.mapping.channels import canonical

logger = logging.getLogger(__name__)

REPLAYED_VERBS = ("expression", "framing")
MAX_INBOX = 256  # commands waiting for a tick; the servers' rate limits keep far below this
APPLIED_KEPT = 32


class ControlStage:
    """The ``control`` stage (see the module docstring).

    Parameters
    ----------
    names : sequence of str, the triggerable expressions (the character's VRM expression names, else its shapes)
    actions : mapping of verb -> callable(Command) for the verbs other than ``expression`` (calibrate, profile,
        record, framing); a missing verb is answered "not available in this session"
    publish : callable(t, dict) or None, the bus's :meth:`~facepuppet.runtime.live.bus.SessionBus.publish_control`
    schedule : sequence of (tick time, JSON object), recorded commands to apply at those ticks (a replay)
    mapper : Mapper or None, the session's map step when ``names`` are the shapes it maps onto (a character
        without VRM expressions): triggered shapes are laid over the mapped frame (see the module docstring)

    Attributes
    ----------
    inbox : deque of Command, what the servers and hotkeys hand over
    counters : ``commands_applied``, ``commands_failed``, ``commands_dropped`` (inbox full)
    applied : deque of (t, dict, str), the last commands applied, with what they did ("" when fine)
    """

    name = "control"

    def __init__(self, names: Sequence[str], actions: dict[str, Callable[[Command], str]] | None = None,
                 publish: Callable[[float, dict], None] | None = None,
                 schedule: Sequence[tuple[float, dict]] = (), log: Callable[[str], None] = logger.info,
                 mapper: Mapper | None = None) -> None:
        self.triggers = ExpressionTriggers(names)
        self.actions = dict(actions or {})
        self.publish = publish
        self.log = log
        self.inbox: deque[Command] = deque()
        self.schedule = sorted(((float(t), doc) for t, doc in schedule), key=lambda item: item[0])
        self._next = 0
        self.counters = {"commands_applied": 0, "commands_failed": 0, "commands_dropped": 0}
        self.applied: deque[tuple[float, dict, str]] = deque(maxlen=APPLIED_KEPT)
        self._applied_lock = threading.Lock()  # the servers' threads read it for status
        self._values = np.full(len(self.triggers.names), np.nan, dtype=np.float32)
        self._shown = self._values.copy()
        self._last_in: Frame | None = None
        self._layouts: dict[tuple[str, ...] | None, tuple[tuple[str, ...], np.ndarray]] = {}
        self._folded = [canonical(n) for n in self.triggers.names]
        self.mapper = mapper

    # -- from other threads ------------------------------------------------------------------------

    def submit(self, command: Command) -> bool:
        """Queue a show command for the next tick (any thread; never blocks). False when the inbox is full."""
        if len(self.inbox) >= MAX_INBOX:
            self.counters["commands_dropped"] += 1
            return False
        self.inbox.append(command)
        return True

    # -- on the frame loop's thread ----------------------------------------------------------------

    def __call__(self, frame: Frame | None, t: float) -> Frame | None:
        self._take_commands(t)
        values = self.triggers.values(t, self._values)
        if frame is not None:
            self._last_in = frame
            out = self._compose(frame, values)
        elif not np.array_equal(values, self._shown, equal_nan=True):
            base = self._last_in if self._last_in is not None else \
                Frame(t=t, source="control", channels=(), weights=np.zeros(0, dtype=np.float32))
            out = self._compose(replace(base, t=t), values)
        else:
            out = None
        np.copyto(self._shown, values)
        return out

    def _take_commands(self, t: float) -> None:
        while self._next < len(self.schedule) and self.schedule[self._next][0] <= t + 1e-9:
            doc = self.schedule[self._next][1]
            self._next += 1
            try:
                command = parse_command(doc, f"CONTROL record at t={t:.3f} s")
            except CommandError as exc:
                self.log(f"control: {exc}; not applied")
                continue
            if command.verb in REPLAYED_VERBS:
                self._apply(command, t, publish=False)
        while self.inbox:
            self._apply(self.inbox.popleft(), t, publish=True)

    def _apply(self, command: Command, t: float, publish: bool) -> None:
        try:
            if command.verb == "expression":
                note = self._expression(command, t)
            else:
                action = self.actions.get(command.verb)
                note = "not available in this session" if action is None else (action(command) or "")
        except (CommandError, ValueError, OSError) as exc:  # a profile that does not load, a record that fails
            note = str(exc)
        doc = command.to_json()
        with self._applied_lock:
            self.applied.append((t, doc, note))
        if note:
            self.counters["commands_failed"] += 1
            self.log(f"control: {command.verb}: {note}")
        else:
            self.counters["commands_applied"] += 1
        if publish and self.publish is not None and not note:
            self.publish(t, doc)

    def _expression(self, command: Command, t: float) -> str:
        a = command.args
        i = self.triggers.find(a["name"])
        if i is None:
            return f"no expression named {a['name']!r} (list gives the names)"
        self.triggers.apply(i, a["action"], t, a["value"], a["fade"], a.get("seconds"))
        return ""

    def _compose(self, frame: Frame, values: np.ndarray) -> Frame:
        """``frame`` with each triggered expression laid over it (see the module docstring); as it is while every
        expression is at rest."""
        active = np.flatnonzero(~np.isnan(values))
        if frame.weights is None or active.size == 0:
            return frame
        if self.mapper is not None:
            shapes = self.mapper.map_for(frame.channels, frame.source).apply(frame.weights)
            shapes = np.array(shapes, dtype=np.float32)
            shapes[active] = np.maximum(shapes[active], values[active])
            return replace(frame, channels=self.triggers.names, weights=shapes)
        channels, where = self._layout(frame.channels)
        n = len(frame.weights)
        weights = np.full(len(channels), np.nan, dtype=np.float32)
        weights[:n] = frame.weights
        for j in active:
            i, v = where[j], values[j]
            weights[i] = v if np.isnan(weights[i]) else max(weights[i], v)
        return replace(frame, channels=channels, weights=weights)

    def _layout(self, channels: tuple[str, ...] | None) -> tuple[tuple[str, ...], np.ndarray]:
        """(the channels with the expressions the frame lacks added, each expression's index in them)."""
        known = self._layouts.get(channels)
        if known is None:
            have = {canonical(c): i for i, c in enumerate(channels or ())}
            out, where = list(channels or ()), []
            for name, folded in zip(self.triggers.names, self._folded):
                if folded not in have:
                    have[folded] = len(out)
                    out.append(name)
                where.append(have[folded])
            if len(self._layouts) > 16:
                self._layouts.clear()
            known = self._layouts[channels] = (tuple(out), np.array(where, dtype=np.int64))
        return known

    # -- what the status shows -----------------------------------------------------------------------

    def status(self) -> dict[str, Any]:
        """What is triggered, the counters and the last commands applied (any thread)."""
        with self._applied_lock:
            last = list(self.applied)[-5:]
        return {"active": self.triggers.active(), "counters": dict(self.counters),
                "last": [{"t": t, "command": doc, "error": note} for t, doc, note in last]}
