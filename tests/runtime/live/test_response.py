"""The per-channel response (range, curve, clamp), blink linking, mirror, and live config changes.

Expected values are worked by hand from the formulas in runtime/live/response.py's docstring.
"""

from __future__ import annotations

import math
import threading
from dataclasses import replace

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.config import ChannelSettings, FilterSettings, LiveConfig, Neutral
from facepuppet.runtime.live.pipeline import LivePipeline
from facepuppet.runtime.live.response import Response, mirror_permutation

FAST = FilterSettings(min_cutoff=1e6, beta=0.0)  # alpha ~ 1: the filter passes the value through


def fast_config(**kw) -> LiveConfig:
    return LiveConfig(filters={r: FAST for r in ("eyes", "brows", "mouth", "other", "head")}, **kw)


CH = ("jawOpen", "eyeBlinkLeft", "mouthSmileLeft", "tongueOut", "cheekPuff", "browInnerUp")


def test_each_curve_against_hand_computed_values():
    cfg = LiveConfig(channels={
        "jawOpen": ChannelSettings(gain=2.0, input_range=(0.1, 0.5), output_range=(0.0, 0.8)),  # linear
        "eyeBlinkLeft": ChannelSettings(curve="ease"),
        "mouthSmileLeft": ChannelSettings(curve="threshold", threshold=0.1),
        "tongueOut": ChannelSettings(gain=0.5, clamp=(-1.0, 1.0)),  # no range, no curve: no remap
        "cheekPuff": ChannelSettings(output_range=(1.0, 0.0)),  # an inverted output
        "browInnerUp": ChannelSettings(input_range=(0.2, 0.6), curve="ease", output_range=(0.0, 0.5)),
    })
    r = Response(CH, cfg)
    # jaw: v = 2 * 0.15 = 0.3, u = (0.3 - 0.1) / 0.4 = 0.5 -> 0.4; blink: u = 0.25 -> 3/16 - 2/64 = 0.15625;
    # smile 0.08 < 0.1 -> 0; tongue: -0.6 * 0.5 = -0.3 (inside its clamp, not held at 0); puff: 1 - 0.25 = 0.75;
    # brow: u = (0.5 - 0.2) / 0.4 = 0.75 -> 3 * 0.5625 - 2 * 0.421875 = 0.84375 -> 0.421875
    np.testing.assert_allclose(r(np.array([0.15, 0.25, 0.08, -0.6, 0.25, 0.5])),
                               [0.4, 0.15625, 0.0, -0.3, 0.75, 0.421875], rtol=0, atol=1e-12)
    # jaw held at the input range's ends: 2 * 0.01 = 0.02 < 0.1 -> 0; 2 * 0.4 = 0.8 > 0.5 -> 0.8;
    # smile at the threshold passes as it is (0.3); tongue -3 -> clamp -1; NaN (not sent) stays NaN
    out = r(np.array([0.01, 1.0, 0.3, -6.0, math.nan, 0.1]))
    np.testing.assert_allclose(out[[0, 1, 2, 3, 5]], [0.0, 1.0, 0.3, -1.0, 0.0], rtol=0, atol=1e-12)
    assert math.isnan(out[4])
    np.testing.assert_allclose(r(np.array([0.4, 0.0, 0.12, 0.0, 0.0, 0.0]))[[0, 2]], [0.8, 0.12])


def test_default_channels_keep_the_old_gain_then_clamp():
    r = Response(("jawOpen", "cheekPuff"), LiveConfig(channels={"jawOpen": ChannelSettings(gain=2.0,
                                                                                        clamp=(0.0, 0.9))}))
    np.testing.assert_allclose(r(np.array([0.3, 1.4])), [0.6, 1.0])
    np.testing.assert_allclose(r(np.array([0.6, -0.2])), [0.9, 0.0])


def test_blink_linking_takes_the_stronger_eye_and_only_when_asked():
    ch = ("eyeBlinkLeft", "jawOpen", "eyeBlinkRight")
    linked = Response(ch, LiveConfig(link_blinks=True))
    np.testing.assert_allclose(linked(np.array([0.2, 0.5, 0.7])), [0.7, 0.5, 0.7])
    np.testing.assert_allclose(linked(np.array([0.9, 0.5, 0.1])), [0.9, 0.5, 0.9])
    np.testing.assert_allclose(linked(np.array([math.nan, 0.5, 0.4])), [0.4, 0.5, 0.4])  # one eye not sent
    np.testing.assert_allclose(Response(ch, LiveConfig())(np.array([0.2, 0.5, 0.7])), [0.2, 0.5, 0.7])
    # linked after each eye's own response: the left's gain halves it before the stronger is taken
    tuned = Response(ch, LiveConfig(link_blinks=True, channels={"eyeBlinkLeft": ChannelSettings(gain=0.5)}))
    np.testing.assert_allclose(tuned(np.array([0.8, 0.0, 0.3])), [0.4, 0.0, 0.4])


def test_mirror_swaps_sides_and_directions_and_settings_follow_the_target_channel():
    ch = ("eyeBlinkLeft", "eyeBlinkRight", "jawLeft", "jawRight", "jawOpen", "eyeLookInLeft", "eyeLookInRight",
          "browInnerUp")
    np.testing.assert_array_equal(mirror_permutation(ch), [1, 0, 3, 2, 4, 6, 5, 7])
    assert mirror_permutation(("jawOpen", "eyeBlinkLeft")) is None  # a side without its other side stays
    cfg = LiveConfig(mirror=True, channels={"eyeBlinkLeft": ChannelSettings(gain=0.5)})
    out = Response(ch, cfg)(np.array([0.1, 0.9, 0.3, 0.0, 0.5, 0.2, 0.6, 0.4]))
    # the right eye's 0.9 lands on the left, whose gain 0.5 then applies: 0.45
    np.testing.assert_allclose(out, [0.45, 0.1, 0.0, 0.3, 0.5, 0.6, 0.2, 0.4])


def _frame(t, weights, channels=("jawOpen", "eyeBlinkLeft", "eyeBlinkRight"), rotation=None, translation=None):
    return Frame(t=t, source="test", channels=channels, weights=np.array(weights, dtype=np.float64),
                 head_rotation=None if rotation is None else np.array(rotation, dtype=np.float64),
                 head_translation=None if translation is None else np.array(translation, dtype=np.float64))


def test_mirror_negates_head_yaw_and_roll_keeps_pitch_and_negates_x_through_the_pipeline():
    p = LivePipeline(fast_config(mirror=True))
    a = 0.15
    yaw_roll = [0.0, math.sin(a), 0.0, math.cos(a)]
    out = p(_frame(0.0, [0.2, 0.1, 0.8], rotation=yaw_roll, translation=[0.01, 0.02, 0.03]), 0.0)
    np.testing.assert_allclose(out.head_rotation, [0.0, -math.sin(a), 0.0, math.cos(a)], atol=1e-12)
    np.testing.assert_allclose(out.head_translation, [-0.01, 0.02, 0.03], atol=1e-12)
    np.testing.assert_allclose(out.weights, [0.2, 0.8, 0.1], atol=1e-12)  # the eyes swapped
    roll = [0.0, 0.0, math.sin(a), math.cos(a)]
    pitch = [math.sin(a), 0.0, 0.0, math.cos(a)]
    q = LivePipeline(fast_config(mirror=True))
    np.testing.assert_allclose(q(_frame(0.0, [0, 0, 0], rotation=roll), 0.0).head_rotation,
                               [0.0, 0.0, -math.sin(a), math.cos(a)], atol=1e-12)
    r = LivePipeline(fast_config(mirror=True))
    np.testing.assert_allclose(r(_frame(0.0, [0, 0, 0], rotation=pitch), 0.0).head_rotation, pitch, atol=1e-12)


def test_apply_config_takes_effect_at_the_next_tick_not_before():
    p = LivePipeline(fast_config())
    assert p(_frame(0.0, [0.3, 0.0, 0.0]), 0.0).weights[0] == pytest.approx(0.3)
    p.apply_config(fast_config(channels={"jawOpen": ChannelSettings(gain=2.0)}))
    assert p.config.channel("jawOpen").gain == 1.0  # handed over, not yet in force
    assert p(_frame(1 / 60, [0.3, 0.0, 0.0]), 1 / 60).weights[0] == pytest.approx(0.6)
    # a tick without a new frame takes the change too (the next frame is drawn with it)
    p.apply_config(fast_config(channels={"jawOpen": ChannelSettings(gain=3.0)}))
    assert p(None, 2 / 60) is None and p.config.channel("jawOpen").gain == 3.0
    assert p(_frame(3 / 60, [0.3, 0.0, 0.0]), 3 / 60).weights[0] == pytest.approx(0.9)


def test_a_changed_filter_keeps_its_state_so_the_output_does_not_jump():
    slow = FilterSettings(min_cutoff=1.0, beta=0.0)
    cfg = LiveConfig(filters={**LiveConfig().filters, "mouth": slow})
    p = LivePipeline(cfg)
    dt = 1 / 60
    p(_frame(0.0, [0.0, 0.0, 0.0]), 0.0)
    # alpha = 1 / (1 + 1 / (2 pi f_c dt)): f_c = 1 Hz -> 1 / (1 + 60 / 2pi) = 0.0947932...
    a1 = 1 / (1 + 60 / (2 * math.pi))
    y1 = p(_frame(dt, [1.0, 0.0, 0.0]), dt).weights[0]
    assert y1 == pytest.approx(a1, abs=1e-12)
    p.apply_config(replace(cfg, filters={**cfg.filters, "mouth": FilterSettings(min_cutoff=10.0, beta=0.0)}))
    y2 = p(_frame(2 * dt, [1.0, 0.0, 0.0]), 2 * dt).weights[0]
    a10 = 1 / (1 + 60 / (20 * math.pi))  # 0.511534...
    assert y2 == pytest.approx(y1 + a10 * (1.0 - y1), abs=1e-12)  # from where it was, at the new cutoff
    assert y2 < 0.6  # a reset filter would have jumped to the raw 1.0


def test_apply_config_from_another_thread_and_the_last_of_several_wins():
    p = LivePipeline(fast_config())
    heard = []
    p.bus.on_config(lambda t, c: heard.append((t, c.channel("jawOpen").gain)))
    p(_frame(0.0, [0.3, 0.0, 0.0]), 0.0)

    def panel():
        p.apply_config(fast_config(channels={"jawOpen": ChannelSettings(gain=2.0)}))
        p.apply_config(fast_config(channels={"jawOpen": ChannelSettings(gain=0.5)}))

    thread = threading.Thread(target=panel)
    thread.start()
    thread.join(timeout=10)
    assert not thread.is_alive()
    assert p(_frame(0.1, [0.3, 0.0, 0.0]), 0.1).weights[0] == pytest.approx(0.15)
    assert heard == [(0.1, 0.5)]
    with pytest.raises(TypeError, match="expected a LiveConfig"):
        p.apply_config({"gain": 2})


def test_a_schedule_replays_changes_at_their_tick_times():
    later = fast_config(channels={"jawOpen": ChannelSettings(gain=2.0)})
    p = LivePipeline(fast_config(), schedule=[(0.5, later)])
    got = [p(_frame(t, [0.3, 0.0, 0.0]), t).weights[0] for t in (0.0, 0.25, 0.5, 0.75)]
    np.testing.assert_allclose(got, [0.3, 0.3, 0.6, 0.6])


def test_the_captured_neutral_is_in_the_config_in_force_and_a_new_pipeline_starts_from_it():
    p = LivePipeline(fast_config(capture_s=0.1))
    p.request_calibration()
    yaw = [0.0, math.sin(0.1), 0.0, math.cos(0.1)]
    t = 0.0
    while p.counters["calibrations"] == 0:
        p(_frame(t, [0.2, 0.1, 0.0], rotation=yaw, translation=[0.0, 0.05, 0.0]), t)
        t += 1 / 60
    n = p.current_config().neutral
    assert n.channels == ("jawOpen", "eyeBlinkLeft", "eyeBlinkRight")
    np.testing.assert_allclose(n.weights, [0.2, 0.1, 0.0], atol=1e-7)
    np.testing.assert_allclose(n.rotation, yaw, atol=1e-7)
    np.testing.assert_allclose(n.translation, [0.0, 0.05, 0.0], atol=1e-7)
    # a pipeline given that config (a loaded profile) subtracts it from its first frame, no capture needed
    fresh = LivePipeline(p.current_config())
    out = fresh(_frame(0.0, [0.5, 0.1, 0.0], rotation=yaw, translation=[0.0, 0.05, 0.0]), 0.0)
    np.testing.assert_allclose(out.weights, [0.3, 0.0, 0.0], atol=1e-7)
    np.testing.assert_allclose(out.head_rotation, [0, 0, 0, 1], atol=1e-7)
    np.testing.assert_allclose(out.head_translation, [0, 0, 0], atol=1e-7)
    # the neutral matches channels by name, whatever the order or spelling of this input's channels
    other = LivePipeline(fast_config(neutral=Neutral(("JawOpen",), (0.25,))))
    w = other(_frame(0.0, [0.1, 0.5], channels=("eyeBlink_L", "jawOpen")), 0.0).weights
    np.testing.assert_allclose(w, [0.1, 0.25])
    # clearing it (a config without neutral) gives the raw values back at the next tick
    fresh.apply_config(replace(fresh.current_config(), neutral=None))
    np.testing.assert_allclose(fresh(_frame(1 / 60, [0.5, 0.1, 0.0]), 1 / 60).weights, [0.5, 0.1, 0.0], atol=1e-7)


def test_a_captured_neutral_is_heard_as_a_change_and_its_schedule_replays_it_without_a_request():
    """Key C is not in a recording; the neutral it captured is (a CONFIG record): a replay that is not asked to
    calibrate draws the same values."""
    heard = []
    live = LivePipeline(fast_config(capture_s=0.1))
    live.bus.on_config(lambda t, c: heard.append((t, c)))
    ticks = [k / 60 for k in range(30)]
    stream = [_frame(t, [0.2 + 0.1 * (t > 0.3), 0.1, 0.0]) for t in ticks]
    out_live = []
    for k, (t, f) in enumerate(zip(ticks, stream)):
        if k == 3:
            live.request_calibration()
        out_live.append(live(f, t).weights.copy())
    assert len(heard) == 1 and heard[0][1].neutral is not None
    assert heard[0][1].neutral.weights[0] == pytest.approx(0.2)
    replayed = LivePipeline(fast_config(capture_s=0.1), schedule=heard)
    out_replay = [replayed(f, t).weights.copy() for t, f in zip(ticks, stream)]
    np.testing.assert_array_equal(np.array(out_replay), np.array(out_live))
    assert out_live[-1][0] == pytest.approx(0.1)  # 0.3 - the neutral 0.2
