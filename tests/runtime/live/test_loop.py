"""Frame loop logic with a fake clock and a recording stub renderer (no GL here; see test_replay.py)."""

from __future__ import annotations

import gc
import math
from types import SimpleNamespace

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.loop import FrameLoop, RecordedClock, WallClock
from facepuppet.runtime.live.sinks import WeightLog
from facepuppet.runtime.live.timing import StageTimer
from facepuppet.runtime.recording.replay_source import ReplaySource

RIG = SimpleNamespace(shape_names=("jawOpen", "eyeBlink_L", "eyeBlink_R", "cheekRaiser_L"))


class StubRenderer:
    """Records every draw call; stands in for FaceRenderer only to test the loop's logic."""

    def __init__(self):
        self.draws = []
        self.finishes = 0

    def draw(self, weights, head_rotation=None, head_translation=None):
        self.draws.append((np.array(weights), None if head_rotation is None else np.array(head_rotation)))

    def finish(self):
        self.finishes += 1

    def read_pixels(self):
        return np.zeros((2, 2, 3), np.uint8)


def _frame(t, jaw, blink=0.0, **kw):
    return Frame(t=t, source="test", channels=("JawOpen", "EyeBlinkLeft", "TongueOut"),
                 weights=[jaw, blink, 0.0], **kw)


def test_newest_frame_wins_stale_frames_are_dropped_and_counted():
    # 4 frames arrive between tick 1 (t=0.1) and tick 2 (t=0.2); none between ticks 2 and 3
    frames = [_frame(0.0, 0.0), _frame(0.11, 0.1), _frame(0.13, 0.2), _frame(0.15, 0.3), _frame(0.19, 0.4),
              _frame(0.31, 0.5)]
    renderer, log = StubRenderer(), WeightLog()
    loop = FrameLoop(RIG.shape_names, renderer, RecordedClock(), observers=[log], fps=10.0, log=lambda s: None)
    result = loop.run(ReplaySource(frames), duration=0.4)
    assert result.n_ticks == 5  # t = 0, 0.1, 0.2, 0.3, 0.4
    np.testing.assert_array_equal(log.times, [0.0, 0.1, 0.2, 0.3, 0.4])
    # tick 2 shows the newest (0.4); tick 3 has no new frame and keeps it; tick 4 gets 0.5
    np.testing.assert_allclose(log.array[:, 0], [0.0, 0.0, 0.4, 0.4, 0.5], atol=0)
    assert result.counters["frames_received"] == 6
    assert result.counters["stale_dropped"] == 3
    assert result.counters["ticks_without_new_frame"] == 2
    assert len(renderer.draws) == renderer.finishes == 5
    assert set(result.timings) == {"snapshot", "map", "draw_submit", "gpu_finish", "sink"}
    assert all(s["n"] == 5 for s in result.timings.values())


def test_non_finite_frames_are_rejected_not_drawn():
    frames = [_frame(0.0, 0.25), _frame(0.1, math.inf), _frame(0.2, 0.5, head_rotation=[0, 0, math.nan, 1]),
              _frame(0.3, 0.75, head_rotation=[0, 0, 0, 1])]
    renderer, log = StubRenderer(), WeightLog()
    result = FrameLoop(RIG.shape_names, renderer, RecordedClock(), observers=[log], fps=10.0, log=lambda s: None).run(
        ReplaySource(frames))
    assert result.counters["nonfinite_rejected"] == 2
    np.testing.assert_array_equal(log.array[:, 0], np.float32([0.25, 0.25, 0.25, 0.75]))
    assert renderer.draws[2][1] is None and np.array_equal(renderer.draws[3][1], [0, 0, 0, 1])


def test_channels_mapped_by_name_and_report_logged_once_per_channel_tuple():
    other = ("jawOpen", "eyeBlinkRight")
    frames = [_frame(0.0, 0.5, 0.25), _frame(0.1, 0.6, 0.35),
              Frame(t=0.2, source="other", channels=other, weights=[0.9, 0.8]), _frame(0.3, 0.7, 0.45)]
    messages = []
    log = WeightLog()
    FrameLoop(RIG.shape_names, StubRenderer(), RecordedClock(), observers=[log], fps=10.0, log=messages.append).run(
        ReplaySource(frames))
    assert len(messages) == 2  # one per distinct channel tuple, not per frame
    assert "TongueOut" in messages[0] and "cheekRaiser_L" in messages[0]
    # rig order: jawOpen, eyeBlink_L, eyeBlink_R, cheekRaiser_L
    np.testing.assert_array_equal(log.array, np.float32([[0.5, 0.25, 0, 0], [0.6, 0.35, 0, 0],
                                                         [0.9, 0, 0.8, 0], [0.7, 0.45, 0, 0]]))


def test_a_character_with_expressions_is_mapped_through_them_and_the_report_names_the_routes():
    from facepuppet.runtime.mapping.expressions import make_drive

    from helpers.vrm_characters import preset_character

    c = preset_character()
    channels = ("EyeBlinkLeft", "EyeBlinkRight", "aa", "ah", "TongueOut")
    frames = [Frame(t=0.0, source="vmc", channels=channels, weights=[0.8, 0.8, 0.5, 0.1, 0.3]),
              Frame(t=0.1, source="vmc", channels=channels, weights=[0.0, 0.0, 0.2, 0.0, 0.0])]
    messages, log, seen = [], WeightLog(), []
    drive = make_drive(c.shape_names, c.expressions)
    loop = FrameLoop(c.shape_names, StubRenderer(), RecordedClock(),
                     observers=[log, lambda info: seen.append(np.array(info.expressions))], fps=10.0,
                     log=messages.append, drive=drive)
    loop.run(ReplaySource(frames))
    assert len(messages) == 1
    assert "default preset mapping (2): EyeBlinkLeft→Blink+Blink_L, EyeBlinkRight→Blink+Blink_R" in messages[0]
    assert "expression (1): aa→A" in messages[0] and "morph (1): ah→ah" in messages[0]
    assert "ignored: TongueOut" in messages[0]
    at = {n: i for i, n in enumerate(c.shape_names)}
    # tick 0: Blink = 0.8 -> both lids 0.8; A = 0.5 but ah is driven directly (0.1): the direct value wins
    assert log.array[0, at["blink_left"]] == pytest.approx(0.8) and log.array[0, at["ah"]] == pytest.approx(0.1)
    assert log.array[1, at["blink_left"]] == 0.0
    names = c.expressions.names
    assert seen[0][names.index("Blink")] == pytest.approx(0.8) and seen[1][names.index("A")] == pytest.approx(0.2)


def test_a_frame_loop_without_a_drive_reports_no_expressions():
    seen = []
    FrameLoop(RIG.shape_names, StubRenderer(), RecordedClock(), fps=10.0, log=lambda s: None,
              observers=[lambda info: seen.append(info.expressions)]).run(ReplaySource([_frame(0.0, 0.5)]))
    assert seen == [None]


class FakeTime:
    def __init__(self):
        self.now = 100.0
        self.slept = []

    def monotonic(self):
        return self.now

    def sleep(self, dt):
        self.slept.append(dt)
        self.now += dt


def test_wall_clock_sleeps_to_each_tick_and_counts_late_ones():
    fake = FakeTime()

    class SlowRenderer(StubRenderer):
        def finish(self):
            super().finish()
            fake.now += 0.15 if len(self.draws) == 2 else 0.01  # the 2nd tick overruns

    frames = [_frame(i / 10, 0.1 * i) for i in range(5)]
    clock = WallClock(monotonic=fake.monotonic, sleep=fake.sleep)
    log = WeightLog()
    result = FrameLoop(RIG.shape_names, SlowRenderer(), clock, observers=[log], fps=10.0, log=lambda s: None).run(
        ReplaySource(frames))
    assert result.counters["late_ticks"] == 1
    # late or not, each tick shows the recording at its own recorded time
    np.testing.assert_allclose(log.array[:, 0], [0, 0.1, 0.2, 0.3, 0.4], rtol=1e-6)
    assert fake.slept[0] == pytest.approx(0.09)


def test_window_target_is_polled_swapped_and_can_close():
    class Window:
        headless = False

        def __init__(self):
            self.polls = self.swaps = 0

        def poll(self):
            self.polls += 1

        def should_close(self):
            return self.polls > 3

        def swap(self):
            self.swaps += 1

    win = Window()
    result = FrameLoop(RIG.shape_names, StubRenderer(), RecordedClock(), fps=10.0, log=lambda s: None, target=win).run(
        ReplaySource([_frame(0.1 * i, 0.0) for i in range(10)]))
    assert result.closed_by_window and result.n_ticks == 3 and win.swaps == 3


def test_replay_source_latest_and_done():
    src = ReplaySource([_frame(5.0, 0.1), _frame(5.5, 0.2), _frame(6.0, 0.3)])  # rebased to t = 0
    assert src.duration == 1.0
    assert src.latest(-0.1) == (None, 0)
    f, stale = src.latest(0.75)
    assert f.weights[0] == np.float32(0.2) and stale == 1
    assert not src.done(0.9)
    assert src.latest(0.9) == (None, 0)
    f, stale = src.latest(1.0)
    assert f.weights[0] == np.float32(0.3) and stale == 0 and src.done(1.0)
    with pytest.raises(ValueError, match="time order"):
        ReplaySource([_frame(1.0, 0), _frame(0.5, 0)])
    with pytest.raises(ValueError, match="at least one frame"):
        ReplaySource([])


def test_stage_timer_summary():
    ticks = iter(range(100))
    timer = StageTimer(["a", "b"], clock=lambda: next(ticks) * 0.001)
    for ms in range(1, 101):
        timer.add("a", ms / 1000)
    with timer.measure("b"):
        pass
    s = timer.summary()
    assert s["a"]["n"] == 100 and s["a"]["max_ms"] == pytest.approx(100)
    assert s["a"]["p50_ms"] == pytest.approx(50.5) and s["a"]["p99_ms"] == pytest.approx(99.01)
    assert s["b"]["p50_ms"] == pytest.approx(1.0)
    assert timer.table().splitlines()[0].split()[:2] == ["stage", "n"]
    with pytest.raises(ValueError, match="fps"):
        FrameLoop(RIG.shape_names, StubRenderer(), RecordedClock(), fps=0)


def test_default_duration_reaches_the_last_frame():
    frames = [_frame(0.0, 0.1), _frame(0.1, 0.2), _frame(0.25, 0.3)]  # the last falls between ticks
    src, log = ReplaySource(frames), WeightLog()
    loop = FrameLoop(RIG.shape_names, StubRenderer(), RecordedClock(), observers=[log], fps=10.0, log=lambda s: None)
    result = loop.run(src)
    assert result.n_ticks == 4 and result.counters["frames_received"] == 3 and src.done(0.3)
    assert log.array[-1, 0] == np.float32(0.3)


def test_stages_run_in_order_and_the_last_frame_is_mapped_by_name():
    """Each tick runs the stages in order on the new frame; the last one's channels are mapped by name;
    a tick whose stages give nothing keeps the previous weights."""
    calls = []

    class Halve:
        name = "halve"

        def __call__(self, frame, t):
            calls.append(("halve", t, frame is not None))
            if frame is None or frame.weights is None:
                return None
            return Frame(t=frame.t, channels=("b", "a"), weights=np.asarray(frame.weights[:2], np.float32) * 0.5)

    class AddOne:
        name = "add_one"

        def __call__(self, frame, t):
            calls.append(("add_one", t, frame is not None))
            if frame is None:
                return None
            return Frame(t=frame.t, channels=frame.channels, weights=np.asarray(frame.weights) + 1.0)

    class NullRenderer:
        def draw(self, weights, rotation, translation):
            pass

        def finish(self):
            pass

    frames = [Frame(t=0.0, channels=("x", "y"), weights=[1.0, 0.4]), Frame(t=0.1)]
    log = WeightLog()
    FrameLoop(("a", "b"), NullRenderer(), RecordedClock(), observers=[log], fps=10, log=lambda s: None,
              stages=[Halve(), AddOne()]).run(ReplaySource(frames), duration=0.2)
    # halve then add one: b = 1.0 * 0.5 + 1, a = 0.4 * 0.5 + 1 (the stage renamed the channels)
    np.testing.assert_allclose(log.array, [[1.2, 1.5]] * 3)
    assert [c[0] for c in calls] == ["halve", "add_one"] * 3          # every tick, in order
    assert [c[2] for c in calls[::2]] == [True, True, False]          # the frame without weights, then none
    with pytest.raises(ValueError, match="names"):
        FrameLoop("ab", NullRenderer(), RecordedClock())


def test_a_renderer_with_advance_gets_each_tick_time_and_new_frame_before_its_draw():
    """The spring bones step on these times (recorded time on replay) and the eyes look by these frames."""
    class MovingRenderer(StubRenderer):
        def __init__(self):
            super().__init__()
            self.advances = []

        def advance(self, t, frame):
            self.advances.append((t, None if frame is None else frame.t, len(self.draws)))

    frames = [_frame(0.0, 0.1), _frame(0.13, 0.2), _frame(0.31, 0.3)]
    renderer = MovingRenderer()
    FrameLoop(RIG.shape_names, renderer, RecordedClock(), fps=10.0, log=lambda s: None).run(ReplaySource(frames),
                                                                                               duration=0.4)
    assert [t for t, _, _ in renderer.advances] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4])
    assert [f for _, f, _ in renderer.advances] == [0.0, None, 0.13, None, 0.31]
    assert [n for _, _, n in renderer.advances] == [0, 1, 2, 3, 4]  # each before its tick's draw


def test_what_was_built_before_the_first_tick_is_frozen_for_the_run_and_thawed_after():
    """A full collection during a show does not scan the session's long-lived objects (tables, GL objects,
    modules): they are frozen while the loop runs, and given back to the collector when it returns."""
    class CountingRenderer(StubRenderer):
        def __init__(self):
            super().__init__()
            self.frozen = []

        def draw(self, weights, head_rotation=None, head_translation=None):
            self.frozen.append(gc.get_freeze_count())
            super().draw(weights, head_rotation, head_translation)

    before = gc.get_freeze_count()
    renderer = CountingRenderer()
    FrameLoop(RIG.shape_names, renderer, RecordedClock(), fps=10.0, log=lambda s: None).run(
        ReplaySource([_frame(0.0, 0.1)]), duration=0.2)
    assert len(renderer.frozen) == 3 and min(renderer.frozen) > before + 1000  # the process's objects, frozen
    assert gc.get_freeze_count() == before
