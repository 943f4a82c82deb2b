"""A program that plays timed tone onsets into a sound device and says when each one left it.

Run as ``python -m facepuppet.offline.voice.onset_player DEVICE RATE ONSETS``: it opens DEVICE for output
through PortAudio, plays :func:`burst_signal` (silence, then ONSETS tone bursts a second apart) and prints
one JSON object: for each onset, ``handed`` (the ``time.perf_counter`` second its block was handed to
PortAudio, plus the onset's offset in the block) and ``played`` (PortAudio's estimate of when that sample
leaves the device: the block's output DAC time plus the offset). It is a process of its own so that the
player is a separate program, as a real sound source is, and does not share the listener's interpreter lock;
``time.perf_counter`` is CLOCK_MONOTONIC on Linux, one clock for every process of the machine.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
from types import ModuleType

import numpy as np

LEAD_S = 0.8  # silence before the first onset: the listener's first ticks, and the card settling
BURST_S = 0.3
PERIOD_S = 1.0  # the mouth closes again in the silence between bursts
BLOCK_S = 0.02  # the player's block
AMPLITUDE = 0.3


def burst_signal(rate: int, onsets: int) -> tuple[np.ndarray, list[int]]:
    """Silence, then ``onsets`` tone bursts (a 700 Hz tone keyed at 150 Hz, 0.3 of full scale), PERIOD_S apart;
    the samples (float32) and each onset's sample index. Every 10 ms of a burst holds samples near its peak."""
    n = int(rate * (LEAD_S + onsets * PERIOD_S))
    x = np.zeros(n, np.float32)
    t = np.arange(int(rate * BURST_S)) / rate
    burst = (AMPLITUDE * np.sign(np.sin(2 * np.pi * 150 * t)) * np.sin(2 * np.pi * 700 * t)).astype(np.float32)
    burst[0] = AMPLITUDE  # the onset is its first sample, whatever the phase
    at = [int(rate * (LEAD_S + k * PERIOD_S)) for k in range(onsets)]
    for i in at:
        x[i:i + len(burst)] = burst
    return x, at


class OnsetPlayer:
    """Plays :func:`burst_signal` from a PortAudio output stream, noting each onset's handed and played times."""

    def __init__(self, sd: ModuleType, device: str, rate: int, onsets: int) -> None:
        self.signal, self.onsets = burst_signal(rate, onsets)
        self.rate = rate
        self.handed = [math.nan] * onsets
        self.played = [math.nan] * onsets
        self.underruns = 0
        self._pos = 0
        self._next = 0
        self.done = threading.Event()
        self._stop = sd.CallbackStop
        self.stream = sd.OutputStream(device=device, channels=1, samplerate=rate, blocksize=int(rate * BLOCK_S),
                                      dtype="float32", callback=self._callback, finished_callback=self.done.set)

    def _callback(self, outdata, frames, time_info, status) -> None:
        now = time.perf_counter()
        if status.output_underflow:
            self.underruns += 1
        dac = time_info.outputBufferDacTime - time_info.currentTime + now
        end = min(self._pos + frames, len(self.signal))
        outdata[:end - self._pos, 0] = self.signal[self._pos:end]
        outdata[end - self._pos:, 0] = 0.0
        while self._next < len(self.onsets) and self.onsets[self._next] < end:
            offset = (self.onsets[self._next] - self._pos) / self.rate
            self.handed[self._next] = now + offset
            self.played[self._next] = dac + offset
            self._next += 1
        self._pos = end
        if end >= len(self.signal):
            raise self._stop

    def play(self) -> dict:
        """Play to the end; the onsets' times and what PortAudio said of the stream."""
        self.stream.start()
        self.done.wait(len(self.signal) / self.rate + 10.0)
        time.sleep(0.1)
        latency = float(self.stream.latency)
        self.stream.close()
        return {"handed": self.handed, "played": self.played, "underruns": self.underruns,
                "portaudio_output_latency_s": latency}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m facepuppet.offline.voice.onset_player", description=__doc__)
    p.add_argument("device")
    p.add_argument("rate", type=int)
    p.add_argument("onsets", type=int)
    a = p.parse_args(argv)
    if not (8000 <= a.rate <= 192000 and 1 <= a.onsets <= 100):
        p.error("rate: 8000..192000 Hz, onsets: 1..100")
    try:
        import sounddevice as sd
    except (ImportError, OSError) as exc:  # OSError: the PortAudio library is missing
        print(json.dumps({"error": f"no sounddevice/PortAudio ({exc})"}))
        return 1
    try:
        out = OnsetPlayer(sd, a.device, a.rate, a.onsets).play()
    except (ValueError, sd.PortAudioError) as exc:  # no such device, or the stream refused
        print(json.dumps({"error": f"{a.device}: {exc}"}))
        return 1
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
