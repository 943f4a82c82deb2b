"""Draw on arrival: the sources' wait_for_frame over real UDP on 127.0.0.1, and the frame loop that
sleeps in it (a frame is drawn when it arrives, not at the next tick of a fixed grid)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from facepuppet.runtime.inputs.udp import UdpSource
from facepuppet.runtime.inputs.udp_process import UdpProcessSource
from facepuppet.runtime.inputs.vmc import VmcAdapter
from facepuppet.runtime.live.loop import FrameLoop, WallClock
from facepuppet.runtime.live.sinks import WeightLog
from facepuppet.runtime.mapping.channels import ARKIT_NAMES

from helpers.osc_helpers import vmc_frame

JAW = ARKIT_NAMES.index("jawOpen")
SOURCES = {"process": UdpProcessSource, "thread": UdpSource}


@pytest.mark.parametrize("kind", sorted(SOURCES))
def test_wait_for_frame_wakes_on_a_frame_and_times_out_without(kind, udp_sender):
    with SOURCES[kind](VmcAdapter(), port=0) as source:
        assert source.wait_for_frame(0.05) is False           # nothing sent: the timeout
        assert source.wait_for_frame(0.0) is False
        threading.Timer(0.2, lambda: udp_sender.sendto(vmc_frame(0.7), source.address)).start()
        assert source.wait_for_frame(30.0) is True             # woken by the frame, not the 30 s
        frame, stale = source.latest()
        assert frame.weights[JAW] == pytest.approx(0.7) and stale == 0
        assert source.wait_for_frame(0.05) is False           # the frame was taken: wait again
        udp_sender.sendto(vmc_frame(0.2), source.address)
        deadline = time.monotonic() + 10.0
        while source.counters["frames"] < 2 and time.monotonic() < deadline:
            time.sleep(0.002)
        assert source.wait_for_frame(30.0) is True             # already there: returns at once
        assert source.latest()[0].weights[JAW] == pytest.approx(0.2)


class _Renderer:
    """Stands in for the GPU: the loop's scheduling is what is tested here."""

    def __init__(self):
        self.draws = 0

    def draw(self, weights, rotation, translation):
        self.draws += 1

    def finish(self):
        pass

    def read_pixels(self):
        return np.zeros((1, 1, 3), np.uint8)


@pytest.mark.slow  # the loop runs for 2 s of wall time
@pytest.mark.parametrize("kind", sorted(SOURCES))
def test_the_loop_draws_each_arriving_frame_between_rare_idle_ticks(kind, udp_sender):
    """Frames every 40 ms with an idle redraw of 2 per second: on a fixed 2 fps grid about 3 ticks
    would draw in 2 s; on arrival nearly every frame gets its own tick, labelled on the 1 kHz grid."""
    n_frames = 30
    with SOURCES[kind](VmcAdapter(), port=0) as source:
        stop = threading.Event()

        def send():
            for i in range(n_frames):
                if stop.wait(0.04):
                    return
                udp_sender.sendto(vmc_frame((i + 1) / n_frames), source.address)

        log = WeightLog()
        loop = FrameLoop(ARKIT_NAMES, _Renderer(), WallClock(), observers=[log],
                         fps=1000.0, idle_fps=2.0, log=lambda *a: None)
        thread = threading.Thread(target=send)
        thread.start()
        try:
            result = loop.run(source, duration=2.0)
        finally:
            stop.set()
            thread.join()
    c = result.counters
    assert c["frames_received"] == n_frames                     # sent within 1.2 s of a 2 s run
    drawn_new = result.n_ticks - c["ticks_without_new_frame"]
    assert drawn_new >= 0.8 * n_frames, (drawn_new, c)         # each frame drawn, not dropped as stale
    assert c["ticks_without_new_frame"] <= 8                    # idle redraws at 2 per second, not 1000
    labels = np.rint(log.times * 1000.0)
    assert np.all(np.diff(labels) >= 1) and labels[-1] <= 2000  # increasing grid labels within the run
    assert log.array[-1, JAW] == pytest.approx(1.0)             # the last frame sent is the last drawn


def test_idle_fps_is_checked():
    with pytest.raises(ValueError, match="idle_fps"):
        FrameLoop(("a",), _Renderer(), WallClock(), fps=60.0, idle_fps=120.0)
