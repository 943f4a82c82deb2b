"""The panel's Input section: what the run listens to and how the input is doing.

Kind, listening address and the frames' source, packets/s and frames drawn/s (over the last half second), drops
by reason (every non-zero drop counter of the receiver and the loop, the kernel's ``kernel_dropped`` among them,
said unknown where the system does not report it), age of the last new frame, tracking state
(waiting / live / lost / easing back), receive→draw latency p50/p99 (``end_to_end`` of the live stats over the
last half second), and with ``--voice`` the voice's mouth channels this tick.

The numbers that need a percentile or a file size are refreshed twice a second (:meth:`InputStatus.refresh`),
not every frame, and so are the lines made of them; the desk's window leaves room for the lines
(:meth:`InputStatus.room`) and the live layer writes them every tick (:meth:`InputStatus.draw`), with the age
of the last frame and the tracking state of that tick.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from facepuppet.runtime.live.pipeline import LivePipeline
    from facepuppet.runtime.live.stats import LiveStats
    from facepuppet.runtime.recording.recorder import PacketRecorder
    from facepuppet.runtime.recording.switch import SwitchableRecorder

REFRESH_S = 0.5  # status numbers (rates, percentiles, file size) are recomputed this often
#: a counter is a drop reason when its name has one of these (malformed, unknown_address, non_finite, oversized,
#: filtered_sender, internal_error, stale_dropped, nonfinite_rejected, record_dropped, ...)
DROP_WORDS = ("drop", "malformed", "unknown", "finite", "oversized", "filtered", "error", "rejected", "truncated",
              "invalid", "bad")


class InputStatus:
    """The status numbers of one run and the lines the panel shows of them.

    Parameters
    ----------
    counters : callable returning the run's counter groups (``{"udp": {...}, "loop": {...}, ...}``) or None
    stats : LiveStats or None, for the receive→draw latency
    recorder : SwitchableRecorder, PacketRecorder or None, for the recording's file and size
    pipeline : LivePipeline or None, for the tracking state and its last event
    input_kind, address : str, what the run listens to and where
    voice : VoiceStage or None, the voice's mouth channels (``--voice``): a line of their values each tick

    Attributes
    ----------
    numbers : dict of the last refresh's numbers: ``packets_s``, ``drawn_s``, ``drops`` (name -> count),
        ``kernel_unknown`` (the receiver's kernel drop count is not reported here),
        ``latency`` ((p50 ms, p99 ms, frames) or None), ``record`` ((path, size in bytes or None), only while
        there is a recording), ``stats_n``
    ticks : int, the panel's ticks so far (counted by the panel, shown or not: the frames drawn/s)
    last_raw_at : float or None, when a tick last brought a new raw frame (the panel's clock)
    refresh_at : float, when the numbers are due again
    height : float, the height of the status lines in pixels, as the live layer last wrote them
    """

    def __init__(self, *, counters: Callable[[], dict] | None = None, stats: LiveStats | None = None,
                 recorder: SwitchableRecorder | PacketRecorder | None = None, pipeline: LivePipeline | None = None,
                 input_kind: str = "", address: str = "", voice: Any = None) -> None:
        self.counters, self.stats, self.recorder, self.pipeline = counters, stats, recorder, pipeline
        self.voice = voice
        # the voice's channels, shortened (mouthFunnel -> Funnel, mouthSmileLeft -> SmileL) to fit the panel
        self._voice_names = tuple(n.removeprefix("mouth").replace("Left", "L").replace("Right", "R")
                                  for n in getattr(voice, "outputs", ()))
        self.input_kind, self.address = input_kind, address
        self.numbers: dict[str, Any] = {}
        self.ticks = 0
        self.last_raw_at: float | None = None
        self.refresh_at = -math.inf
        self.height = 0.0
        self._rate_base: tuple[float, int, int] | None = None
        self._lines: dict[str, str] = {}  # lines built at each refresh, not every frame

    def refresh(self, now: float) -> None:
        """Rates, drops, latency percentiles and the record size: twice a second."""
        self.refresh_at = now + REFRESH_S
        groups = dict(self.counters().items()) if self.counters is not None else {}  # items(): fresh udp
        udp = dict(groups.get("udp", {}))
        packets = int(udp.get("packets", 0))
        s = self.numbers
        if self._rate_base is not None and now > self._rate_base[0]:
            dt = now - self._rate_base[0]
            s["packets_s"] = (packets - self._rate_base[1]) / dt
            s["drawn_s"] = (self.ticks - self._rate_base[2]) / dt
        self._rate_base = (now, packets, self.ticks)
        drops = {}
        for group in ("udp", "loop"):
            for name, value in dict(groups.get(group, {})).items():
                if group == "loop" and name in drops:
                    continue  # the loop's stale_dropped counts the frames the receiver superseded: shown once
                if any(w in name for w in DROP_WORDS) and isinstance(value, (int, np.integer)) and value:
                    drops[f"{name}" if group == "udp" else f"{group}.{name}"] = int(value)
        s["drops"] = drops
        s["kernel_unknown"] = "kernel_dropped" in udp and udp["kernel_dropped"] is None  # the OS does not say
        s["latency"] = None
        if self.stats is not None:
            since = s.get("stats_n", 0)
            lat = self.stats.latency(since=since, stages=("end_to_end",)).get("end_to_end", {})  # one: not all
            s["stats_n"] = getattr(self.stats, "_n", 0)
            if lat.get("n"):
                s["latency"] = (lat["p50_ms"], lat["p99_ms"], lat["n"])
        self.refresh_record()
        self._make_lines()

    def refresh_record(self) -> None:
        """The recording's file and its size on disk."""
        s = self.numbers
        path = getattr(self.recorder, "path", None) if self.recorder is not None else None
        if path is not None:
            try:
                s["record"] = (str(path), os.path.getsize(path))
            except OSError:
                s["record"] = (str(path), None)
        else:
            s.pop("record", None)

    def _make_lines(self) -> None:
        """The lines that change only with the status numbers (at each refresh)."""
        s = self.numbers
        lat = s.get("latency")
        drops = s.get("drops") or {}
        self._lines = {
            "where": f"{self.input_kind or '-'} on {self.address or '-'}",
            "rates": (f"{s['packets_s']:.1f} packets/s, {s['drawn_s']:.1f} frames drawn/s" if "packets_s" in s
                      else "packets/s and frames drawn/s: measuring"),
            "latency": ("receive->draw: no frames in the last 0.5 s" if lat is None
                        else f"receive->draw p50 {lat[0]:.2f} ms, p99 {lat[1]:.2f} ms ({lat[2]} frames)"),
            "drops": "drops: " + (", ".join(f"{k} {v}" for k, v in sorted(drops.items())) or "none")
                     + ("; kernel_dropped unknown (this system does not report it)" if s.get("kernel_unknown") else "")}

    def room(self, imgui: Any, live_at: dict[str, tuple]) -> None:
        """In the desk's window: the Input header and room for the status lines, where the live layer writes
        them (``live_at["status"]``: x, y, wrap width)."""
        if not imgui.collapsing_header("Input", imgui.TreeNodeFlags_.default_open):
            return
        p = imgui.get_cursor_screen_pos()
        wrap = imgui.get_content_region_avail().x
        imgui.dummy(imgui.ImVec2(wrap, max(self.height, imgui.get_text_line_height())))
        live_at["status"] = (float(int(p.x)), float(int(p.y)), wrap)

    def text(self, now: float) -> tuple[str, str]:
        """The status lines (where, rates, last frame and tracking, latency) and the drops line, this tick."""
        if not self._lines:
            self._make_lines()
        lines = self._lines
        age = "no frame yet" if self.last_raw_at is None else f"{(now - self.last_raw_at) * 1e3:.0f} ms"
        state = getattr(self.pipeline, "tracking_state", "-")  # waiting / live / lost / easing
        events = getattr(self.pipeline, "events", ())
        last = (f" ({'found' if events[-1][1] else 'lost'} at {events[-1][0]:.1f} s)" if events else "")
        return (f"{lines['where']}\n{lines['rates']}\nlast frame: {age}   tracking: {state}{last}\n{lines['latency']}",
                lines["drops"] + self.voice_line())

    def voice_line(self) -> str:
        """A line ``voice: jawOpen 0.42  Funnel 0.10 ...`` of this tick's values after the drops ("" without
        ``--voice``; ``voice: -`` before its first tick)."""
        if self.voice is None:
            return ""
        values = self.voice.values
        if values is None:
            return "\nvoice: -"
        return "\nvoice: " + "  ".join(f"{n} {float(v):.2f}" for n, v in zip(self._voice_names, values))

    def draw(self, imgui: Any, dl: Any, colour: int, where: tuple, now: float, spacing_y: float) -> None:
        """In the live layer: this tick's lines into the draw list ``dl`` at ``where`` (the room the desk left),
        and their height (:attr:`height`: when it differs from the room, the desk is built again)."""
        x, y, wrap = where
        lines, drops = self.text(now)
        dl.add_text(imgui.ImVec2(x, y), colour, lines)
        lines_h = imgui.calc_text_size(lines).y + spacing_y
        dl.add_text(imgui.get_font(), imgui.get_font_size(), imgui.ImVec2(x, y + lines_h), colour, drops, wrap)
        self.height = float(lines_h + imgui.calc_text_size(drops, wrap_width=wrap).y)
