"""Latency of the microphone path through a virtual sound card: a played onset to the drawn jawOpen.

The ``--audio-file`` figure of ``bench voice`` lives on the run's own clock; this one has a separate program
(:mod:`~facepuppet.offline.voice.onset_player`) play tone bursts into
:class:`~facepuppet.offline.voice.virtual_card.VirtualSoundCard` in real time while ``run --input audio
--audio CARD --voice TABLE`` listens to it through PortAudio, and times every onset on one clock
(``time.perf_counter``: CLOCK_MONOTONIC, the loop's stamps' clock, shared by the processes); the player starts
once the run ticks and its capture has read a first block (the run starts the stream when its loop is about
to tick, and the card's monitor delivers its first block only about 2 s after a capture stream starts,
measured even in an idle process):

* ``handed``: the player's callback handed the block holding the onset to PortAudio (plus the onset's offset
  in the block);
* ``played``: PortAudio's estimate of when that sample leaves the sink (the block's output DAC time, which
  the ALSA pulse plugin derives from the latency PulseAudio reports for the stream);
* ``arrived``: the run's capture callback received the block holding the onset (the first loud block after
  a quiet stretch, seen by wrapping the microphone's block hook);
* ``drawn``: the GPU finished the first tick whose jawOpen left its silent value after a closed stretch.

Each onset played is matched with the first arrival after it and before the next onset (the microphone drops
blocks further behind the capture clock than its bound, so an onset arrives within it or not at all), and each
arrival with the first rise of the drawn jawOpen after it (the counts are reported). Reported as median
and p99 over the onsets: ``played -> drawn`` (held against the goal of one audio block plus one frame),
``handed -> drawn``, and the split ``played -> arrived`` (PulseAudio between the sink and the capture, and
any backlog of the capture callback) and ``arrived -> drawn`` (the runtime: the hop, the next tick, the
draw). ``capture_backlog_ms``: how far the capture callback's samples (read or dropped) fell behind the wall
clock (a callback kept from running, e.g. by a busy machine, makes PulseAudio hold the samples back instead of
dropping them); ``microphone``: the run's microphone counters (blocks read, dropped as stale, the bound).
Not available, with the reason, where pulseaudio or ALSA's pulse plugin is absent.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import math
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import numpy as np

from facepuppet.runtime.commands.run import plan_from_argv, run_live
from facepuppet.runtime.demo.head import build_demo_character
from facepuppet.runtime.inputs.audio import AudioUnavailable, MicLevel

from facepuppet.offline.voice.onset_player import LEAD_S, PERIOD_S
from facepuppet.offline.voice.virtual_card import CardUnavailable, VirtualSoundCard, missing, visible

logger = logging.getLogger(__name__)

LOUD = 0.02  # a captured block with a sample beyond this holds sound (the card's silence is exact zeros)
QUIET_S = 0.2  # an onset follows at least this much quiet (a player underrun inside a burst is not one)
MOVED = 0.01  # jawOpen this far from its silent value has moved


class ArrivalWatch:
    """Wraps a microphone's block hook: when each onset arrived (perf_counter s) and how far the samples
    received fell behind the wall clock since the first block (the capture's backlog, seconds)."""

    def __init__(self, mic: MicLevel | _Hook, rate: float) -> None:
        self.mic = mic
        self.inner = mic.on_block
        self.rate = float(rate)
        self.times: list[float] = []
        self.backlog_s: list[float] = []  # at each block
        self._quiet_n = math.inf
        self._first = math.nan
        self._n = 0
        self._dropped0 = 0
        mic.on_block = self

    def __call__(self, samples: np.ndarray) -> None:
        now = time.perf_counter()
        counters = getattr(self.mic, "counters", None)  # a MicLevel: the blocks it dropped as stale count too
        dropped = counters["stale_dropped"] * len(samples) if counters is not None else 0
        if self._n == 0:
            self._first = now
            self._dropped0 = dropped
        self._n += len(samples)
        self.backlog_s.append(now - self._first - (self._n + dropped - self._dropped0) / self.rate)
        loud = bool(len(samples)) and float(np.max(np.abs(samples))) > LOUD
        if loud:
            if self._quiet_n >= QUIET_S * self.rate:
                self.times.append(now)
            self._quiet_n = 0
        else:
            self._quiet_n += len(samples)
        if self.inner is not None:
            self.inner(samples)


def rises(ticks: list[tuple[float, float, float]]) -> list[float]:
    """The GPU-finished times of the ticks where jawOpen leaves its silent value (its median over the run: the
    bursts fill under a third of it) after at least QUIET_S of ticks within MOVED of it."""
    if not ticks:
        return []
    base = float(np.median([w for _, _, w in ticks]))
    out, closed_since = [], ticks[0][0]
    for t0, t4, w in ticks:
        if abs(w - base) <= MOVED:
            if closed_since is None:
                closed_since = t0
        else:
            if closed_since is not None and t0 - closed_since >= QUIET_S:
                out.append(t4)
            closed_since = None
    return out


def after(events: list[float], starts: list[float]) -> list[float]:
    """For each start, the first event at or after it and before the next (finite) start (nan where none, and
    for a nan start)."""
    out = []
    for k, s in enumerate(starts):
        end = next((x for x in starts[k + 1:] if math.isfinite(x)), math.inf)
        hits = [e for e in events if s <= e < end] if math.isfinite(s) else []
        out.append(hits[0] if hits else math.nan)
    return out


def _stats(values: list[float]) -> dict:
    v = np.array([x for x in values if math.isfinite(x)])
    if not len(v):
        return {"median_ms": math.nan, "p99_ms": math.nan, "n": 0}
    return {"median_ms": float(np.median(v) * 1e3), "p99_ms": float(np.percentile(v, 99) * 1e3),
            "min_ms": float(v.min() * 1e3), "max_ms": float(v.max() * 1e3), "n": int(len(v))}


def _pairs(a: list[float], b: list[float]) -> list[float]:
    """``a[k] - b[k]`` over the onsets both have (by order)."""
    return [x - y for x, y in zip(a, b)]


def card_latency(table_path: Path, tmp: Path, onsets: int = 10, fps: float = 60.0,
                 log: Callable[[str], None] = logger.info) -> dict:
    """Onset -> drawn jawOpen through ``run`` on a virtual sound card (see the module docstring); with
    ``available: False`` and the reason where no card can be had."""
    why = missing()
    if why is not None:
        return {"available": False, "reason": why}
    try:
        import sounddevice  # noqa: F401  (an optional extra: loaded where it is used)
    except (ImportError, OSError) as exc:  # OSError: the PortAudio library is missing
        return {"available": False, "reason": f"no sounddevice/PortAudio ({exc})"}
    char = build_demo_character().save(tmp / "demo.npz")
    jaw = build_demo_character().shape_names.index("jawOpen")
    config = tmp / "raw.toml"  # the filter's smoothing left out: the latency of the voice, not of the filter
    config.write_text("\n".join(f"[filter.{r}]\nmin_cutoff = 500.0\nbeta = 0.0" for r in
                                ("eyes", "brows", "mouth", "other", "head")) + "\n")
    try:
        with VirtualSoundCard(tmp / "vcard") as card, visible(card) as sd:
            try:
                alone = card_alone(sd, card, onsets, log)
            except (ValueError, sd.PortAudioError) as exc:  # the card's device missing or refusing the stream
                return {"available": False, "reason": f"{card.name}: {exc}"}
            result = _measure(card, table_path, char, jaw, config, onsets, fps, log)
            result["card_alone"] = alone
            return result
    except (CardUnavailable, AudioUnavailable) as exc:
        return {"available": False, "reason": str(exc)}


def _play(card: VirtualSoundCard, onsets: int) -> dict:
    """Run the onset player on the card's playing device; its JSON (``error`` in words if it failed)."""
    try:
        proc = subprocess.run([sys.executable, "-m", "facepuppet.offline.voice.onset_player", card.play_device,
                               str(card.rate), str(onsets)], env=card.env, capture_output=True, text=True,
                              timeout=LEAD_S + onsets * PERIOD_S + 60.0)
        lines = proc.stdout.strip().splitlines()
        return json.loads(lines[-1]) if lines else {"error": proc.stderr[-500:] or f"exit status {proc.returncode}"}
    except (subprocess.TimeoutExpired, json.JSONDecodeError) as exc:
        return {"error": f"the player failed: {exc}"}


class _Hook:
    """A stand-in microphone for :class:`ArrivalWatch` where no run listens (the card alone)."""

    on_block = None


def card_alone(sd: ModuleType, card: VirtualSoundCard, onsets: int, log: Callable[[str], None]) -> dict:
    """The card's own delay, with nobody else in the listening process: the player's onsets to a capture
    stream's callback (the same device, rate and block as the run's microphone, PortAudio's default latency)."""
    info = sd.query_devices(card.name, "input")
    rate = float(info["default_samplerate"])
    watch = ArrivalWatch(_Hook(), rate)
    stream = sd.InputStream(device=card.name, channels=1, samplerate=rate, blocksize=int(rate * 0.01),
                            callback=lambda indata, frames, t, status: watch(indata[:, 0]))
    with stream:
        time.sleep(0.3)
        played = _play(card, onsets)
        time.sleep(0.3)
    if "error" in played:
        return {"available": False, "reason": f"{card.play_device}: {played['error']}"}
    backlog = np.array(watch.backlog_s) * 1e3
    out = {"played_to_arrived": _stats(_pairs(watch.times, played["played"])),
           "handed_to_arrived": _stats(_pairs(watch.times, played["handed"])),
           "detected": len(watch.times), "capture_backlog_ms": {"median": float(np.median(backlog)),
                                                              "max": float(backlog.max())},
           "portaudio_input_latency_ms": float(stream.latency) * 1e3}
    log(f"the virtual card alone: played onset -> capture callback median {out['played_to_arrived']['median_ms']:.1f} "
        f"ms, p99 {out['played_to_arrived']['p99_ms']:.1f} ms ({len(watch.times)}/{onsets} onsets); handed -> "
        f"callback median {out['handed_to_arrived']['median_ms']:.1f} ms")
    return out


def _measure(card: VirtualSoundCard, table_path: Path, char: Path, jaw: int, config: Path, onsets: int,
             fps: float, log: Callable[[str], None]) -> dict:
    ticks: list[tuple[float, float, float]] = []
    stop, first_tick = threading.Event(), threading.Event()
    watch: dict = {}
    played: dict = {}

    def on_chain(chain) -> None:
        mic = getattr(getattr(chain.voice, "source", None), "mic", None)
        if mic is not None:
            rate = float(mic.stream.samplerate)
            watch.update(arrivals=ArrivalWatch(mic, rate), rate=rate, block=int(mic.stream.blocksize),
                         input_latency_s=float(mic.stream.latency))

    def hook(info) -> None:
        ticks.append((info.stamps[0], info.stamps[4], float(info.weights[jaw])))
        first_tick.set()

    def play() -> None:
        try:
            if not first_tick.wait(60.0):
                return
            # and the capture's first block read: the card's monitor starts delivering about 2 s after a
            # capture stream starts, which would hide the first onsets
            heard = time.perf_counter() + 30.0
            while not getattr(watch.get("arrivals"), "_n", 0) and time.perf_counter() < heard:
                time.sleep(0.01)
            played.update(_play(card, onsets))
            time.sleep(0.5)  # the last burst's ticks
        finally:
            stop.set()

    duration = LEAD_S + onsets * PERIOD_S + 90.0  # a cap: the player's end stops the run
    plan = plan_from_argv(["-c", str(char), "--input", "audio", "--voice", str(table_path), "--audio", card.name,
                           "--headless", "--size", "64x48", "--fps", f"{fps:g}", "--config", str(config),
                           "--duration", f"{duration:g}"])
    thread = threading.Thread(target=play, daemon=True)
    thread.start()
    said = io.StringIO()
    try:
        with contextlib.redirect_stdout(said):
            run_live(plan, stop_event=stop, hooks=[hook], on_chain=on_chain)
    finally:
        stop.set()
        thread.join(timeout=LEAD_S + onsets * PERIOD_S + 90.0)
    if "arrivals" not in watch:
        reason = next((m for m in said.getvalue().splitlines() if "no audio" in m), "the run opened no microphone")
        return {"available": False, "reason": f"{card.name}: {reason}"}
    if "error" in played:
        return {"available": False, "reason": f"{card.play_device}: {played['error']}"}
    handed, on_card = played["handed"], played["played"]
    arrived = after(watch["arrivals"].times, on_card)
    drawn = after(rises(ticks), arrived)
    backlog = np.array(watch["arrivals"].backlog_s) * 1e3
    result = {
        "available": True, "device": card.name, "onsets": onsets, "fps": fps,
        "detected": {"arrived": int(np.isfinite(arrived).sum()), "drawn": int(np.isfinite(drawn).sum())},
        "microphone": dict(watch["arrivals"].mic.counters),
        "capture": {"rate_hz": watch["rate"], "block": watch["block"], "block_ms": watch["block"] / watch["rate"] * 1e3,
                    "portaudio_input_latency_ms": watch["input_latency_s"] * 1e3,
                    "capture_backlog_ms": {"median": float(np.median(backlog)), "max": float(backlog.max())}},
        "playback": {"portaudio_output_latency_ms": played["portaudio_output_latency_s"] * 1e3,
                     "underruns": played["underruns"]},
        "played_to_drawn": _stats(_pairs(drawn, on_card)),
        "handed_to_drawn": _stats(_pairs(drawn, handed)),
        "played_to_arrived": _stats(_pairs(arrived, on_card)),
        "arrived_to_drawn": _stats(_pairs(drawn, arrived)),
        "ticks": len(ticks),
    }
    pd = result["played_to_drawn"]
    result["goal<=40ms"] = bool(pd["n"] == onsets and pd["median_ms"] <= 40.0)
    log(f"latency through a virtual sound card ({card.name}, a PulseAudio null sink): played onset -> drawn jawOpen "
        f"median {pd['median_ms']:.1f} ms, p99 {pd['p99_ms']:.1f} ms ({pd['n']}/{onsets} onsets drawn, "
        f"{result['detected']['arrived']} arrived); of which sink -> capture callback median "
        f"{result['played_to_arrived']['median_ms']:.1f} ms, callback -> drawn "
        f"{result['arrived_to_drawn']['median_ms']:.1f} ms; capture blocks of {result['capture']['block_ms']:.1f} ms, "
        f"the capture's backlog median {np.median(backlog):.1f} ms, max {backlog.max():.1f} ms; "
        f"{result['microphone']['stale_dropped']} of {result['microphone']['blocks']} blocks dropped as stale "
        f"(bound {result['microphone']['bound_ms']} ms); PortAudio reports "
        f"{watch['input_latency_s'] * 1e3:.1f} ms in, {played['portaudio_output_latency_s'] * 1e3:.1f} ms out")
    return result
