"""The handoff between the frame loop and a live output's thread: the loop never waits on the consumer; a slow
consumer loses the older waiting picture (counted), a failing one is stopped and the run goes on."""

from __future__ import annotations

import threading

import numpy as np

from facepuppet.runtime.live.frame_handoff import FrameHandoff, TickReadback, live_picture, over_key


def _picture(k: int) -> np.ndarray:
    return np.full((4, 6, 3), k, np.uint8)


def test_a_stalled_consumer_keeps_only_the_newest_waiting_picture():
    entered, release = threading.Event(), threading.Event()
    got: list[int] = []

    def consume(k, t, stamp, pixels):
        got.append(k)
        entered.set()
        release.wait()

    handoff = FrameHandoff(consume, "test")
    assert handoff.offer(0, 0.0, 0.0, _picture(0))
    assert entered.wait(30)              # the worker holds picture 0 and is stalled
    kept = [handoff.offer(k, k / 10, 0.0, _picture(k)) for k in range(1, 6)]  # returns at once each time
    assert kept == [True, False, False, False, False]
    release.set()
    handoff.drain()
    handoff.close()
    assert got == [0, 5]                 # the newest waiting picture went out; 1..4 were replaced
    assert handoff.counters == {"offered": 6, "sent": 2, "dropped": 4, "failed": 0, "over_rate": 0}
    assert handoff.delay.n == handoff.work.n == 2


def test_a_consumer_that_raises_is_stopped_and_the_offers_go_on_counted():
    def consume(k, t, stamp, pixels):
        raise OSError("network unreachable")

    handoff = FrameHandoff(consume, "test")
    handoff.offer(0, 0.0, 0.0, _picture(0))
    handoff.drain()
    for k in range(1, 4):
        handoff.offer(k, 0.0, 0.0, _picture(k))  # no exception reaches the loop
    handoff.close()
    assert handoff.failure == "OSError: network unreachable"
    assert handoff.counters["failed"] == 1 and handoff.counters["sent"] == 0
    assert handoff.counters["dropped"] == 4 and handoff.counters["offered"] == 4


def test_close_sends_the_picture_still_waiting():
    got = []
    handoff = FrameHandoff(lambda k, t, s, p: got.append(k), "test")
    for k in range(3):
        handoff.offer(k, 0.0, 0.0, _picture(k))
    handoff.close()
    assert got[-1] == 2 and handoff.counters["sent"] + handoff.counters["dropped"] == 3


class _Renderer:
    def __init__(self):
        self.reads = 0

    def read_pixels(self):
        self.reads += 1
        return _picture(self.reads)


class _Info:
    def __init__(self, renderer, k):
        self.renderer, self.k, self.t, self.stamps = renderer, k, k / 10, (0.0, 0.0, 0.0, 0.0, float(k))


def test_the_pixels_of_a_tick_are_read_once_for_every_output():
    renderer, readback = _Renderer(), TickReadback()
    a = readback.pixels(_Info(renderer, 1))
    b = readback.pixels(_Info(renderer, 1))
    c = readback.pixels(_Info(renderer, 2))
    assert a is b and renderer.reads == 2 and int(c[0, 0, 0]) == 2
    stored, finish = readback.stored(_Info(renderer, 2))   # no read_rgba: the finished picture, made live
    assert stored is c and renderer.reads == 2 and finish(stored).shape == (4, 6, 4)


def test_a_live_picture_with_alpha_goes_over_the_key_colour():
    rgba = np.zeros((2, 3, 4), np.uint8)   # colour x alpha, as the framebuffer holds it
    rgba[0, 0] = (200, 100, 50, 255)     # opaque: as drawn
    rgba[0, 1] = (0, 0, 0, 0)            # nothing drawn: the key
    rgba[0, 2] = (128, 128, 128, 128)    # white at half alpha: between them
    out = over_key(rgba, (0, 255, 0))
    assert out.shape == (2, 3, 3) and out.dtype == np.uint8
    assert tuple(out[0, 0]) == (200, 100, 50) and tuple(out[0, 1]) == (0, 255, 0)
    assert tuple(out[0, 2]) == (128, 255, 128)
    rgb = rgba[:, :, :3].copy()
    assert over_key(rgb, (0, 255, 0)) is rgb


def test_a_finished_picture_becomes_a_live_one():
    """A renderer without read_rgba: its RGB gains an opaque alpha, its straight RGBA is multiplied by alpha."""
    rgb = np.full((2, 2, 3), 90, np.uint8)
    assert live_picture(rgb).tolist() == [[[90, 90, 90, 255]] * 2] * 2
    straight = np.array([[[200, 100, 50, 128], [10, 20, 30, 0]]], np.uint8)
    assert live_picture(straight).tolist() == [[[100, 50, 25, 128], [0, 0, 0, 0]]]


def test_an_output_at_a_frame_rate_takes_one_tick_per_slot_of_it():
    """Ticks of a 120 Hz tracker drawn on arrival (times jittered by up to a tenth of a slot early or late) to an
    output at 60 fps: every other tick, and the ticks left out are never read back."""
    renderer, readback = _Renderer(), TickReadback()
    got = []
    handoff = FrameHandoff(lambda k, t, s, p: got.append(k), "test", fps=60.0)
    jitter = np.random.default_rng(0).uniform(-0.08, 0.08, 240) / 60
    for k in range(240):
        info = _Info(renderer, k)
        info.t = 5.0 + k / 120 + jitter[k]
        handoff.take(info, readback)
        handoff.drain()
    handoff.close()
    c = handoff.counters
    assert c["offered"] == 120 and c["over_rate"] == 120 and renderer.reads == 120
    assert c["sent"] == len(got) == 120 and got == list(range(0, 240, 2))


def test_close_does_not_hang_on_a_consumer_that_never_returns():
    stuck = threading.Event()
    handoff = FrameHandoff(lambda k, t, s, p: stuck.wait(), "test")
    handoff.CLOSE_WAIT_S = 0.2
    handoff.offer(0, 0.0, 0.0, _picture(0))
    assert handoff.close() is False       # said and left behind
    stuck.set()
