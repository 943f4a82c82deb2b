"""Tracking loss per region (hold, neutral, voice, idle), the lost/found events and the panel's state.

Driven through the real FrameLoop on recorded time with a stub renderer (the logic needs no GL); the
run over real UDP with an audio file is in tests/runtime/commands/test_run_tracking_loss.py.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.config import FilterSettings, LiveConfig, LiveConfigError, parse_live_config
from facepuppet.runtime.live.loop import FrameLoop, RecordedClock, TickInfo
from facepuppet.runtime.live.pipeline import LivePipeline
from facepuppet.runtime.live.sinks import WeightLog
from facepuppet.runtime.live.tracking_loss import IdleMotion, LossSettings, voice_jaw
from facepuppet.runtime.recording.replay_source import ReplaySource

CHANNELS = ("jawOpen", "eyeBlinkLeft", "browInnerUp")
RIG = CHANNELS
FPS = 60.0
YAW = np.array([0.0, math.sin(0.2), 0.0, math.cos(0.2)])


class StubRenderer:
    def __init__(self):
        self.rotations = []

    def draw(self, weights, head_rotation=None, head_translation=None):
        self.rotations.append(None if head_rotation is None else np.array(head_rotation, dtype=np.float64))

    def finish(self):
        pass


def frames(t0, t1, jaw, blink=0.1, brow=0.4):
    return [Frame(t=t, source="test", channels=CHANNELS, weights=[jaw, blink, brow], head_rotation=YAW)
            for t in np.arange(t0, t1, 1 / FPS)]


def config(**modes) -> LiveConfig:
    fast = FilterSettings(min_cutoff=500.0, beta=0.0)
    loss = LossSettings({**LossSettings().modes, **modes})
    return LiveConfig(filters={r: fast for r in ("eyes", "brows", "mouth", "other", "head")}, timeout_s=0.3,
                      ease_out_s=0.4, ease_in_s=0.25, loss=loss)


def run(pipeline, stream, duration):
    renderer, log, states = StubRenderer(), WeightLog(), []

    def hook(info: TickInfo):
        states.append(pipeline.tracking_state)

    loop = FrameLoop(RIG, renderer, RecordedClock(), observers=[log, hook], fps=FPS, log=lambda s: None,
                     stages=[pipeline])
    loop.run(ReplaySource(stream), duration=duration)
    return log, renderer, states


STREAM = frames(0.0, 1.0, 0.8) + frames(3.0, 4.0, 0.3)  # live, 2 s of nothing, live again
LAST = 1.0 - 1 / FPS
SETTLED = (LAST + 0.3 + 0.4 + 1e-6, 3.0)  # lost, eased out fully


def window(t, lo, hi):
    return (t >= lo) & (t < hi)


def test_hold_keeps_the_last_face_and_pose_while_lost_then_hands_back():
    pipeline = LivePipeline(config(mouth="hold", eyes="hold", brows="hold", head="hold"), log=lambda s: None)
    log, renderer, _ = run(pipeline, STREAM, 4.0)
    t, w = log.times, log.array
    lost = window(t, LAST, 3.0)
    np.testing.assert_allclose(w[lost], np.tile([0.8, 0.1, 0.4], (lost.sum(), 1)), atol=1e-4)
    rot = np.array([renderer.rotations[i] for i in np.flatnonzero(lost)])
    np.testing.assert_allclose(np.abs(rot @ YAW), 1.0, atol=1e-6)  # the head held turned
    np.testing.assert_allclose(w[t >= 3.0 + 0.25 + 2 / FPS, 0], 0.3, atol=1e-3)
    assert pipeline.counters["tracking_lost"] == 1 and pipeline.counters["tracking_found"] == 1


def test_neutral_is_the_default_and_each_region_keeps_its_own_mode():
    pipeline = LivePipeline(config(brows="hold"), log=lambda s: None)  # mouth, eyes: neutral (default)
    log, _, _ = run(pipeline, STREAM, 4.0)
    settled = window(log.times, *SETTLED)
    np.testing.assert_allclose(log.array[settled, 0], 0.0, atol=1e-6)  # jaw to neutral
    np.testing.assert_allclose(log.array[settled, 1], 0.0, atol=1e-6)  # blink to neutral
    np.testing.assert_allclose(log.array[settled, 2], 0.4, atol=1e-4)  # brows held


def test_voice_opens_the_jaw_from_the_level_while_lost_and_hands_back_without_a_jump():
    # a level that rises and falls during the loss (dBFS per tick time), silence before
    def level(t):
        return -60.0 if t < 1.2 else -45.0 + 25.0 * abs(math.sin(2.0 * t))

    cfg = config(mouth="voice")
    pipeline = LivePipeline(cfg, audio_level=level, log=lambda s: None)
    log, _, states = run(pipeline, STREAM, 4.0)
    t, jaw = log.times, log.array[:, 0]
    settled = window(t, *SETTLED)
    expected = np.array([voice_jaw(level(x), cfg.loss) for x in t[settled]])
    np.testing.assert_allclose(jaw[settled], expected, atol=1e-6)
    assert np.ptp(expected) > 0.3  # the level really moves the jaw (not a constant)
    # the easing into the voice and back to the tracker moves at most the smoothstep slope per tick
    # on top of the target's own motion; back on the tracker's value after ease_in_s
    back = window(t, 3.0, 3.0 + 0.25)
    step = np.abs(np.diff(jaw[np.flatnonzero(back)[0] - 1:np.flatnonzero(back)[-1] + 1]))
    out_at_return = jaw[np.flatnonzero(back)[0] - 1]
    assert step.max() <= 1.5 * abs(out_at_return - 0.3) / (0.25 * FPS) + 1e-6
    np.testing.assert_allclose(jaw[t >= 3.0 + 0.25 + 2 / FPS], 0.3, atol=1e-3)
    # the other mouth-less regions: neutral
    np.testing.assert_allclose(log.array[settled, 1:], 0.0, atol=1e-6)
    # the state the panel reads: live, lost, easing, live
    runs = [states[0]] + [b for a, b in zip(states, states[1:]) if a != b]
    assert runs == ["live", "lost", "easing", "live"]


def test_voice_without_a_level_eases_to_neutral():
    pipeline = LivePipeline(config(mouth="voice"), log=lambda s: None)
    log, _, _ = run(pipeline, STREAM, 4.0)
    np.testing.assert_allclose(log.array[window(log.times, *SETTLED), 0], 0.0, atol=1e-6)


def test_idle_blinks_and_sways_the_head_deterministically_while_lost():
    cfg = config(eyes="idle", head="idle")
    cfg = replace(cfg, loss=replace(cfg.loss, idle_blink_s=0.5))
    logs = [run(LivePipeline(cfg, log=lambda s: None), STREAM, 4.0) for _ in range(2)]
    (log, renderer, _), (log2, renderer2, _) = logs
    settled = window(log.times, *SETTLED)
    blink = log.array[settled, 1]
    assert blink.max() > 0.99 and blink.min() < 1e-6  # full blinks, open in between
    rot = np.array([renderer.rotations[i] for i in np.flatnonzero(settled)])
    angles = 2 * np.degrees(np.arccos(np.clip(np.abs(rot[:, 3]), 0, 1)))
    assert 0.2 < angles.max() < 6.0 and np.ptp(angles) > 0.1  # a small head motion, moving
    np.testing.assert_array_equal(log.array, log2.array)  # replayed on the same tick times: the same face
    np.testing.assert_array_equal(np.array([r for r in renderer.rotations if r is not None]),
                                  np.array([r for r in renderer2.rotations if r is not None]))


def test_idle_motion_blink_shape_and_renewal():
    idle = IdleMotion(blink_s=1.0, seed=3)
    t = np.arange(0.0, 60.0, 1 / 240)
    b = np.array([idle.blink(x) for x in t])
    closed = (b > 0.999).astype(int)
    n_blinks = int(np.sum(np.diff(closed) == 1))
    assert 40 <= n_blinks <= 80  # mean gap 1 s over 60 s
    assert b.min() == 0.0 and b.max() == 1.0
    assert len(idle._starts) < 200  # old blinks are dropped: nothing grows with the length of a show


def test_events_are_counted_kept_and_handed_to_listeners():
    pipeline = LivePipeline(config(), log=lambda s: None)
    heard = []
    pipeline.bus.on_tracking(lambda t, found: heard.append((t, found)))
    stream = frames(0.0, 1.0, 0.8) + frames(2.0, 2.5, 0.3) + frames(3.5, 4.0, 0.3)
    run(pipeline, stream, 4.5)
    assert [f for _, f in heard] == [False, True, False, True, False]
    assert list(pipeline.events) == heard
    lost_t = [t for t, f in heard if not f]
    assert all(abs(a - b) < 2 / FPS for a, b in zip(lost_t, [LAST + 0.3, 2.5 - 1 / FPS + 0.3, 4.0 - 1 / FPS + 0.3]))
    assert pipeline.counters["tracking_lost"] == 3 and pipeline.counters["tracking_found"] == 2


@pytest.mark.parametrize("text, message", [
    ('mouth = "sing"', "tracking_loss.mouth': expected one of 'hold', 'neutral', 'voice', 'idle', 'ease'"),
    ('eyes = "voice"', "tracking_loss.eyes': 'voice' drives the mouth only"),
    ("head = 3", "tracking_loss.head': expected one of"),
    ("voice_floor_db = -10.0", "tracking_loss.voice_ceiling_db': expected more than voice_floor_db (-10)"),
    ("idle_blink_s = 0", "tracking_loss.idle_blink_s': expected a finite number > 0"),
    ("idle_seed = -1", "tracking_loss.idle_seed': expected an integer >= 0"),
    ("mouht = \"hold\"", "tracking_loss.mouht': unknown key"),
])
def test_bad_loss_settings_name_the_file_and_key(text, message):
    import tomllib

    with pytest.raises(LiveConfigError, match="live.toml: key '" + message.replace("(", r"\(").replace(")", r"\)")):
        parse_live_config(tomllib.loads("[tracking_loss]\n" + text), "live.toml")


def test_loss_settings_parse():
    import tomllib

    cfg = parse_live_config(tomllib.loads('[tracking_loss]\nmouth = "voice"\neyes = "idle"\nbrows = "ease"\n'
                                          'head = "hold"\nvoice_floor_db = -40\nidle_seed = 7\n'), "x.toml")
    assert cfg.loss.modes == {"eyes": "idle", "brows": "neutral", "mouth": "voice", "other": "neutral",
                              "head": "hold"}
    assert (cfg.loss.voice_floor_db, cfg.loss.idle_seed) == (-40.0, 7)
    assert voice_jaw(-40.0, cfg.loss) == 0.0 and voice_jaw(-15.0, cfg.loss) == 1.0
    assert voice_jaw(-27.5, cfg.loss) == pytest.approx(0.5)


def test_with_gestures_the_lost_mouth_takes_the_gesture_layers_lips(tmp_path):
    """build_chain with --gestures hands the filter the layer's voice face: while lost (mouth = "voice") the
    jaw is the layer's synthesised lips from the voice level, not the built-in level line."""
    from facepuppet.runtime.live.stages import build_chain
    from facepuppet.runtime.session.options import StageOptions

    from helpers.gesture_dbs import small_db
    from helpers.small_characters import sphere_character

    small_db(tmp_path / "gestures.npz")
    config = tmp_path / "live.toml"
    config.write_text("\n".join(f"[filter.{r}]\nmin_cutoff = 500.0\nbeta = 0.0" for r in
                                ("eyes", "brows", "mouth", "other", "head"))
                      + '\n[tracking_loss]\ntimeout_s = 0.3\nease_out_s = 0.4\nmouth = "voice"\n')

    def level(t):
        return -60.0 if t < 1.2 else -30.0 + 20.0 * math.sin(3.0 * t)

    options = StageOptions(config=config, gestures=tmp_path / "gestures.npz", gesture_seed=1)
    chain = build_chain(options, sphere_character(), "vmc", audio_level=level, log=lambda s: None)
    assert chain.filter.generator is not None
    seen = {}
    generator = chain.filter.generator

    def spy(t):
        frame = generator(t)
        seen[round(t, 9)] = float(frame.weights[list(frame.channels).index("jawOpen")])
        return frame

    chain.filter.generator = spy
    renderer, log = StubRenderer(), WeightLog()
    loop = FrameLoop(("jawOpen",), renderer, RecordedClock(), observers=[log], fps=FPS, log=lambda s: None,
                     stages=chain.stages)
    loop.run(ReplaySource(STREAM), duration=4.0)
    t, jaw = log.times, log.array[:, 0]
    settled = window(t, *SETTLED)
    lips = np.array([seen[round(x, 9)] for x in t[settled]])
    np.testing.assert_allclose(jaw[settled], np.clip(lips, 0.0, 1.0), atol=1e-6)
    assert np.ptp(lips) > 0.05  # the synthesised lips move with the voice
    line = np.array([voice_jaw(level(x), chain.config.loss) for x in t[settled]])
    assert np.abs(line - jaw[settled]).max() > 0.05  # and they are not the built-in line


def test_replay_reports_tracking_events_that_differ_from_the_recording():
    from facepuppet.runtime.session.recording_feed import compare_events as _compare_events

    same = _compare_events([(1.5, False), (3.0, True)], [(1.5, False), (3.0, True)])
    assert same == "replay: tracking events as recorded (2: lost at 1.500 s, found at 3.000 s)"
    differ = _compare_events([(1.5, False), (3.0, True)], [(1.5, False)])
    assert differ.startswith("replay: warning: tracking events differ from the recording's: recorded 2 "
                             "(lost at 1.500 s, found at 3.000 s), replayed 1 (lost at 1.500 s)")
    assert _compare_events([], []) == "replay: tracking events as recorded (0)"


def drive(pipeline, until, live_until, jaw=0.8, apply_at=None, new=None):
    """Tick ``pipeline`` at FPS from 0 to ``until``: frames (jaw, blink 0.1, brow 0.4) before ``live_until``,
    none after; ``apply_config(new)`` handed over at the tick at ``apply_at``. (tick times, emitted weights or
    None) per tick."""
    times, out = [], []
    for k in range(int(round(until * FPS))):
        t = k / FPS
        if apply_at is not None and abs(t - apply_at) < 0.5 / FPS:
            pipeline.apply_config(new)
        frame = Frame(t=t, source="test", channels=CHANNELS, weights=[jaw, 0.1, 0.4], head_rotation=YAW) \
            if t < live_until else None
        got = pipeline(frame, t)
        times.append(t)
        out.append(None if got is None else np.array(got.weights, dtype=np.float64))
    return np.array(times), out


def test_apply_config_while_live_changes_the_loss_mode_of_the_next_loss():
    # mouth eases to neutral by default; the operator switches it to hold while the tracker is still live
    pipeline = LivePipeline(config(), log=lambda s: None)
    t, out = drive(pipeline, 3.0, 1.0, apply_at=0.5, new=config(mouth="hold"))
    assert pipeline.tracking_state == "lost"
    when, last = next((tt, w) for tt, w in zip(t[::-1], out[::-1]) if w is not None)  # the settled lost face
    assert when >= SETTLED[0] - 1 / FPS  # emitted once the ease out had run its course
    assert last[0] == pytest.approx(0.8, abs=1e-4)  # the jaw held, not eased to 0
    assert last[1] == pytest.approx(0.0, abs=1e-6)  # the eyes kept their own mode (neutral)
    # the same run without the change: the jaw goes to neutral (what the test above tells apart)
    t, out = drive(LivePipeline(config(), log=lambda s: None), 3.0, 1.0)
    assert next(w for w in out[::-1] if w is not None)[0] == pytest.approx(0.0, abs=1e-6)


def test_apply_config_while_lost_moves_to_the_new_loss_target_from_where_the_face_is():
    # lost and settled at neutral (nothing left to emit); then the eyes are switched to idle blinks
    idle = LiveConfig(**{**vars(config()), "loss": LossSettings({**LossSettings().modes, "eyes": "idle"},
                                                                idle_blink_s=0.5)})
    pipeline = LivePipeline(config(), log=lambda s: None)
    t, out = drive(pipeline, 6.0, 1.0, apply_at=2.5, new=idle)
    assert pipeline.tracking_state == "lost" and pipeline.config.loss.mode("eyes") == "idle"
    before = [w for tt, w in zip(t, out) if 1.0 <= tt < 2.5]
    assert abs([w for w in before if w is not None][-1][1]) < 1e-6  # eased to neutral ...
    assert all(w is None for tt, w in zip(t, out) if SETTLED[0] + 1 / FPS <= tt < 2.5)  # ... then nothing to draw
    after = [(tt, w) for tt, w in zip(t, out) if tt >= 2.5]
    assert all(w is not None for _, w in after)  # the moving target is emitted every tick
    blinks = np.array([w[1] for _, w in after])
    assert blinks.max() > 0.9  # the eyes blink now, while still lost
    steps = np.abs(np.diff(np.concatenate([[0.0], blinks[:3]])))
    assert steps.max() < 0.05  # from where the face was, eased (no jump onto a blink at the switch)
    np.testing.assert_allclose([w[0] for _, w in after], 0.0, atol=1e-6)  # the mouth kept its mode
