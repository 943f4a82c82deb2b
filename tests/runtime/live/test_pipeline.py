"""Live pipeline: tracking loss and recovery, calibration, gain/clamp, non-finite frames.

Driven through the real FrameLoop on recorded time with a stub renderer (no GL needed for the logic).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.bus import SessionBus
from facepuppet.runtime.live.config import ChannelSettings, FilterSettings, LiveConfig
from facepuppet.runtime.live.loop import FrameLoop, RecordedClock
from facepuppet.runtime.live.pipeline import LivePipeline
from facepuppet.runtime.live.sinks import WeightLog
from facepuppet.runtime.recording.replay_source import ReplaySource

RIG = SimpleNamespace(shape_names=("jawOpen", "eyeBlink_L"))
CHANNELS = ("jawOpen", "eyeBlinkLeft", "tongueOut")
FPS = 60.0


class StubRenderer:
    def __init__(self):
        self.rotations = []

    def draw(self, weights, head_rotation=None, head_translation=None):
        self.rotations.append(None if head_rotation is None else np.array(head_rotation, dtype=np.float64))

    def finish(self):
        pass


def frames(t0, t1, jaw, blink=0.0, rotation=None, translation=None, rate=FPS):
    return [Frame(t=t, source="test", channels=CHANNELS, weights=[jaw, blink, math.nan],
                  head_rotation=rotation, head_translation=translation)
            for t in np.arange(t0, t1, 1 / rate)]


def run(pipeline, stream, duration):
    renderer, log = StubRenderer(), WeightLog()
    loop = FrameLoop(RIG.shape_names, renderer, RecordedClock(), observers=[log], fps=FPS, log=lambda s: None,
                     stages=[pipeline])
    result = loop.run(ReplaySource(stream), duration=duration)
    return log, renderer, result


def passthrough_config(**kw) -> LiveConfig:
    """Filters fast enough to be pass-through after a tick or two, so easing is what is measured."""
    fast = FilterSettings(min_cutoff=500.0, beta=0.0)
    return LiveConfig(filters={r: fast for r in ("eyes", "brows", "mouth", "other", "head")}, **kw)


def test_tracking_loss_eases_to_neutral_never_freezes_and_recovers_without_a_jump():
    cfg = passthrough_config(timeout_s=0.5, ease_out_s=0.6, ease_in_s=0.25)
    yaw = np.array([0.0, math.sin(0.3), 0.0, math.cos(0.3)])
    # live 0..1 s at jaw 0.8; nothing from 1 s to 3 s; live again from 3 s at jaw 0.3
    stream = frames(0.0, 1.0, 0.8, rotation=yaw) + frames(3.0, 4.0, 0.3, rotation=yaw)
    pipeline = LivePipeline(cfg, log=lambda s: None)
    log, renderer, _ = run(pipeline, stream, duration=4.0)
    jaw, t = log.array[:, 0], log.times
    last_frame = 1.0 - 1 / FPS
    # before the timeout: hold
    hold = (t > last_frame) & (t <= last_frame + 0.5)
    np.testing.assert_allclose(jaw[hold], 0.8, atol=1e-3)
    # easing: strictly decreasing, never frozen, to neutral (0) by timeout + ease
    easing = (t > last_frame + 0.5 + 1e-9) & (t < last_frame + 0.5 + 0.6)
    assert easing.sum() > 20 and np.all(np.diff(jaw[easing]) < 0)
    lost = (t >= last_frame + 1.1 + 1e-6) & (t < 3.0)
    np.testing.assert_allclose(jaw[lost], 0.0, atol=1e-6)
    rot_lost = np.array([renderer.rotations[i] for i in np.flatnonzero(lost)])
    np.testing.assert_allclose(np.abs(rot_lost[:, 3]), 1.0, atol=1e-6)  # head back to identity
    # recovery: blends in over ease_in_s, no tick jumps more than the smoothstep slope allows
    step = np.abs(np.diff(jaw))
    bound = 1.5 * 0.8 / (0.6 * FPS)  # max slope of smoothstep x |0.8 - 0| per tick of the ease-out
    assert step.max() <= bound + 1e-6
    back = t >= 3.0 + 0.25 + 2 / FPS
    np.testing.assert_allclose(jaw[back], 0.3, atol=1e-3)
    assert pipeline.counters["tracking_lost"] == 1 and pipeline.state == "live"


def test_frames_returning_mid_ease_blend_from_where_the_output_is():
    cfg = passthrough_config(timeout_s=0.2, ease_out_s=1.0, ease_in_s=0.3)
    stream = frames(0.0, 0.5, 1.0) + frames(1.0, 2.0, 1.0)  # back while half eased out
    log, _, _ = run(LivePipeline(cfg, log=lambda s: None), stream, duration=2.0)
    jaw = log.array[:, 0]
    assert jaw.min() > 0.2 and jaw.min() < 0.9  # it had eased part way
    assert np.abs(np.diff(jaw)).max() <= 1.5 * 1.0 / (0.3 * FPS) + 1e-6
    assert jaw[-1] == pytest.approx(1.0, abs=1e-3)


def test_calibration_removes_the_neutral_offset_of_weights_and_head():
    cfg = passthrough_config(capture_s=0.5)
    tilt = np.array([math.sin(0.1), 0.0, 0.0, math.cos(0.1)])
    stream = (frames(0.0, 1.0, 0.2, blink=0.1, rotation=tilt, translation=[1.0, 2.0, 3.0])
              + frames(1.0, 2.0, 0.7, blink=0.1, rotation=tilt, translation=[1.5, 2.0, 3.0]))
    pipeline = LivePipeline(cfg, log=lambda s: None)
    pipeline.request_calibration()
    log, renderer, _ = run(pipeline, stream, duration=2.0)
    assert pipeline.counters["calibrations"] == 1
    np.testing.assert_allclose(pipeline.neutral_weights[:2], [0.2, 0.1], atol=1e-6)
    np.testing.assert_allclose(log.array[-1], [0.5, 0.0], atol=1e-3)
    np.testing.assert_allclose(renderer.rotations[-1], [0, 0, 0, 1], atol=1e-5)


def test_gain_and_clamp_per_channel():
    cfg = passthrough_config(channels={"jawOpen": ChannelSettings(gain=2.0, clamp=(0.0, 0.9)),
                                       "eyeBlinkLeft": ChannelSettings(gain=0.5)})
    log, _, _ = run(LivePipeline(cfg, log=lambda s: None), frames(0.0, 0.5, 0.6, blink=0.6), duration=0.5)
    np.testing.assert_allclose(log.array[-1], [0.9, 0.3], atol=1e-4)


def test_default_filter_smooths_jitter_and_mouth_more_than_eyes():
    rng = np.random.default_rng(1)
    stream = [Frame(t=k / FPS, source="test", channels=CHANNELS,
                    weights=[0.5 + rng.normal(0, 0.05), 0.5 + rng.normal(0, 0.05), math.nan]) for k in range(240)]
    log, _, _ = run(LivePipeline(log=lambda s: None), stream, duration=4.0)
    jaw_sd, blink_sd = log.array[60:, 0].std(), log.array[60:, 1].std()
    assert jaw_sd < 0.3 * 0.05 and jaw_sd < blink_sd < 0.05


def test_non_finite_frames_are_rejected_once_by_the_loop_before_any_stage():
    good = frames(0.0, 0.2, 0.4)
    bad = Frame(t=0.2, source="test", channels=CHANNELS, weights=[math.inf, 0.0, 0.0])
    bad_pose = Frame(t=0.25, source="test", channels=CHANNELS, weights=[0.9, 0.0, 0.0],
                     head_rotation=[0, 0, math.nan, 1])
    pipeline = LivePipeline(passthrough_config(), log=lambda s: None)
    seen = []
    original = pipeline.__call__

    class Spy:
        name = "filter"

        def __call__(self, frame, t):
            seen.append(frame)
            return original(frame, t)

    renderer, log = StubRenderer(), WeightLog()
    result = FrameLoop(RIG.shape_names, renderer, RecordedClock(), observers=[log], fps=FPS, log=lambda s: None,
                       stages=[Spy()]).run(ReplaySource(good + [bad, bad_pose]), duration=0.3)
    np.testing.assert_allclose(log.array[:, 0], 0.4, atol=1e-6)
    assert result.counters["nonfinite_rejected"] == 2       # one counter, in the loop
    assert all(f is None or f.is_finite() for f in seen)      # no stage sees a non-finite frame
    assert "nonfinite_rejected" not in pipeline.counters     # and none counts them a second time


def test_a_growing_request_count_calibrates_and_nothing_calls_into_the_stage():
    count = {"n": 0}
    bus = SessionBus()
    bus.count_requests(lambda: count["n"])
    pipeline = LivePipeline(passthrough_config(capture_s=0.1), log=lambda s: None, bus=bus)
    one = lambda t: Frame(t=t, source="test", channels=CHANNELS, weights=[0.3, 0.0, math.nan])  # noqa: E731
    pipeline(one(0.0), 0.0)
    assert not pipeline.calibrating
    count["n"] = 2                                           # two calibrate messages since the last tick
    pipeline(None, 1 / FPS)
    assert pipeline.calibrating                              # one request, read by the stage itself
    for k in range(2, 12):
        pipeline(one(k / FPS), k / FPS)
    assert pipeline.counters["calibrations"] == 1 and not pipeline.calibrating


def test_calibration_request_from_another_thread_is_a_flag():
    pipeline = LivePipeline(passthrough_config(capture_s=0.1), log=lambda s: None)
    pipeline.request_calibration()
    assert pipeline.calibrating
    for k, f in enumerate(frames(0.0, 0.3, 0.25)):
        pipeline(f, k / FPS)
    assert not pipeline.calibrating and pipeline.neutral_weights[0] == pytest.approx(0.25)
