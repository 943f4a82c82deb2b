"""The filter stage's state as a recording started mid-run keeps it (LivePipeline.state_snapshot / restore_state):
a stage restored from a snapshot goes on exactly as the one it was taken from, live, while tracking is lost
(easing out to the voice and idle targets, or done), while frames come back (easing in) and while a neutral
is being captured; a snapshot that is not one is refused naming the field, changing nothing."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.config import FilterSettings, LiveConfig
from facepuppet.runtime.live.pipeline import LivePipeline
from facepuppet.runtime.live.tracking_loss import LossSettings

CHANNELS = ("jawOpen", "eyeBlinkLeft", "browInnerUp")
SMOOTH = LiveConfig(filters={r: FilterSettings(min_cutoff=1.0, beta=0.3) for r in
                             ("eyes", "brows", "mouth", "other", "head")})


def _frames(n, start=0):
    rng = np.random.default_rng(7)
    out = []
    for i in range(start + n):
        yaw = 0.4 * math.sin(i / 9)
        f = Frame(t=i / 60, source="test", channels=CHANNELS, weights=rng.uniform(0, 1, 3),
                  head_rotation=np.array([0.0, math.sin(yaw / 2), 0.0, math.cos(yaw / 2)]),
                  head_translation=np.array([0.01 * i, 0.0, 0.0]), number=i)
        if i >= start:
            out.append(f)
    return out


def _outputs(pipeline, frames, k0):
    """Per tick k (from ``k0``) the stage's output for ``frames[k - k0]`` (None: a tick without a new frame),
    NaN where it emitted nothing."""
    got = []
    for k, f in enumerate(frames, start=k0):
        out = pipeline(f, k / 60)
        got.append(np.full(10, np.nan) if out is None else
                   np.concatenate([out.weights, out.head_rotation, out.head_translation]))
    return np.array(got)


def _voice(t):
    """A level (dBFS) that swings, so a jaw following the voice moves every tick."""
    return -40.0 + 20.0 * math.sin(3.0 * t)


LOSS = LiveConfig(filters=SMOOTH.filters, loss=LossSettings(
    modes={"eyes": "idle", "brows": "hold", "mouth": "voice", "other": "neutral", "head": "idle"}, idle_blink_s=0.5))


def _pipeline(config=SMOOTH):
    return LivePipeline(config, audio_level=_voice, log=lambda s: None)


def _goes_on_alike(config, ticks, cut):
    """Run one stage over ``ticks`` (frames or None); a second, restored from the first's snapshot (through
    JSON) after ``cut`` ticks, must give the same outputs from there on. Returns the first's state at the cut."""
    run = _pipeline(config)
    _outputs(run, ticks[:cut], 0)
    state = run.state
    doc = json.loads(json.dumps(run.state_snapshot(), allow_nan=False))  # as the file holds it
    resumed = _pipeline(config)
    resumed.restore_state(doc)
    np.testing.assert_array_equal(_outputs(resumed, ticks[cut:], cut), _outputs(run, ticks[cut:], cut))
    return state, doc


def test_a_restored_stage_goes_on_as_the_one_it_was_taken_from():
    frames = _frames(90)
    run = LivePipeline(SMOOTH, log=lambda s: None)
    _outputs(run, frames[:40], 0)
    doc = json.loads(json.dumps(run.state_snapshot(), allow_nan=False))  # through JSON, as the file holds it
    resumed = LivePipeline(SMOOTH, log=lambda s: None)
    resumed.restore_state(doc)
    np.testing.assert_array_equal(_outputs(resumed, frames[40:], 40), _outputs(run, frames[40:], 40))
    fresh = LivePipeline(SMOOTH, log=lambda s: None)  # what a replay did before: the filters start afresh
    run2 = LivePipeline(SMOOTH, log=lambda s: None)
    _outputs(run2, frames[:40], 0)
    assert np.abs(_outputs(fresh, frames[40:50], 40) - _outputs(run2, frames[40:50], 40)).max() > 0.05


def test_a_waiting_stage_has_no_snapshot():
    p = LivePipeline(SMOOTH, log=lambda s: None)
    assert p.state_snapshot() is None  # waiting: a fresh stage is that state
    p(_frames(1)[0], 0.0)
    assert p.state_snapshot()["state"] == "live"


# 40 ticks of frames, a silence (tracking lost after 0.5 s, then the ease out to the loss targets over 0.6 s),
# 30 ticks of frames again (the ease in over 0.25 s)
LOST_TICKS = _frames(40) + [None] * 100 + _frames(30, start=40)


@pytest.mark.parametrize("cut, state", [(60, "live"),  # silent, not yet lost: the last frame held
                                        (75, "lost"),  # in the ease out
                                        (125, "lost"),  # eased out: voice and idle go on
                                        (145, "returning")])  # in the ease in
def test_a_stage_restored_around_a_loss_goes_on_alike(cut, state):
    got, doc = _goes_on_alike(LOSS, LOST_TICKS, cut)
    assert got == doc["state"] == state


def test_a_restored_loss_is_not_a_fresh_stage():
    """What a replay did before: the stage started afresh (waiting) emits nothing while the run's followed the
    voice, then takes the returning frames without the run's ease in."""
    run = _pipeline(LOSS)
    _outputs(run, LOST_TICKS[:75], 0)
    fresh = _pipeline(LOSS)
    a, b = _outputs(run, LOST_TICKS[75:], 75), _outputs(fresh, LOST_TICKS[75:], 75)
    assert np.isnan(b[:65]).all() and np.isfinite(a[:65]).all()
    assert np.abs(a[65:70] - b[65:70]).max() > 0.05


def test_a_stage_restored_while_capturing_the_neutral_captures_the_same_one():
    frames = _frames(90)
    run = _pipeline()
    _outputs(run, frames[:20], 0)
    run.request_calibration()
    _outputs(run, frames[20:30], 20)  # 10 of the capture's 30 frames (0.5 s at 60 Hz)
    assert run.calibrating
    doc = json.loads(json.dumps(run.state_snapshot(), allow_nan=False))
    assert doc["capture"]["n"] == 10
    resumed = _pipeline()
    resumed.restore_state(doc)
    np.testing.assert_array_equal(_outputs(resumed, frames[30:], 30), _outputs(run, frames[30:], 30))
    assert resumed.current_config().neutral == run.current_config().neutral is not None
    # requested but not begun (the request waits for the next frame): kept too
    run = _pipeline()
    _outputs(run, frames[:20], 0)
    run.request_calibration()
    doc = json.loads(json.dumps(run.state_snapshot(), allow_nan=False))
    resumed = _pipeline()
    resumed.restore_state(doc)
    assert resumed.calibrating
    np.testing.assert_array_equal(_outputs(resumed, frames[20:], 20), _outputs(run, frames[20:], 20))
    assert resumed.current_config().neutral == run.current_config().neutral is not None


def test_a_version_1_snapshot_still_restores():
    """Recordings of stop 25 hold version 1 (live only, no ease or capture fields)."""
    frames = _frames(60)
    run = _pipeline()
    _outputs(run, frames[:30], 0)
    doc = json.loads(json.dumps(run.state_snapshot(), allow_nan=False))
    for key in ("state", "held", "ease_start", "loss_from", "lost_done", "calib_pending", "capture"):
        doc.pop(key)
    doc["version"] = 1
    resumed = _pipeline()
    resumed.restore_state(doc)
    np.testing.assert_array_equal(_outputs(resumed, frames[30:], 30), _outputs(run, frames[30:], 30))


@pytest.mark.parametrize("change, match", [
    (lambda d: d.update(version=3), "expected a version 1 or 2 snapshot"),
    (lambda d: d.update(state="asleep"), "'state' is not live, returning or lost"),
    (lambda d: d.update(held=[[0.1], None, None]), r"'held\[0\]' is not a list of 3 numbers"),
    (lambda d: d.update(loss_from=None), "'loss_from' is not a number"),
    (lambda d: d.update(lost_done=1), "'lost_done' and 'calib_pending' must be true or false"),
    (lambda d: d.update(state="lost", out=None), "'lost' needs 'out'"),
    (lambda d: d.update(capture={"n": 3, "ntr": 0}), "'capture' lacks its start"),
    (lambda d: d.update(capture={"t0": 0.1, "n": 3, "ntr": 0, "channels": ["jawOpen"], "w": [0.1], "wn": [1],
                                 "q": [0, 0, 0, 1], "tr": [0, 0]}), r"'capture.tr' is not a list of 3 numbers"),
    (lambda d: d.update(channels="jawOpen"), "'channels' is not a list of names"),
    (lambda d: d["filters"].pop("rotation"), r"'filters.rotation' is not \[x_hat, dx_hat\]"),
    (lambda d: d["filters"]["weights"][0].append(0.5), "'filters.weights' is not a list of 3 numbers"),
    (lambda d: d["filters"]["weights"][1].__setitem__(0, None), "finite dX̂"),
    (lambda d: d["last_frame"].pop("t"), "'last_frame' lacks its time and number"),
    (lambda d: d.update(last_tick="soon"), "'last_tick' is not a number"),
    (lambda d: d.update(out=[[0.1, 0.2], None, None]), r"'out\[0\]' is not a list of 3 numbers"),
])
def test_a_snapshot_that_is_not_one_is_refused_naming_the_field_and_changes_nothing(change, match):
    run = LivePipeline(SMOOTH, log=lambda s: None)
    _outputs(run, _frames(5), 0)
    doc = json.loads(json.dumps(run.state_snapshot(), allow_nan=False))
    change(doc)
    other = LivePipeline(SMOOTH, log=lambda s: None)
    with pytest.raises(ValueError, match=match):
        other.restore_state(doc)
    assert other.state == "waiting" and other.state_snapshot() is None


@pytest.mark.parametrize("text", ["not json {", '{"version": 1, "channels": 3}', "[]"])
def test_replay_says_a_state_record_it_cannot_use_and_starts_the_stage_afresh(text, tmp_path):
    from facepuppet.runtime.session.recording_feed import restore_state

    lines: list[str] = []
    p = LivePipeline(SMOOTH, log=lambda s: None)
    restore_state(p, (1.25, text), tmp_path / "take.fps", lines.append)
    assert len(lines) == 1 and "warning" in lines[0] and "take.fps" in lines[0] and "t = 1.250 s" in lines[0]
    assert p.state == "waiting"


def test_the_same_config_again_while_lost_changes_nothing_and_a_new_one_eases_to_its_targets():
    """A replay applies a recording's first CONFIG record (the config in force, read from the file) at its
    first tick: while lost that restarted the ease out from what was shown, so the voice's jaw came in late."""
    from dataclasses import replace

    a, b, c = _pipeline(LOSS), _pipeline(LOSS), _pipeline(LOSS)
    base = _outputs(a, LOST_TICKS[:75], 0)
    _outputs(b, LOST_TICKS[:75], 0)
    _outputs(c, LOST_TICKS[:75], 0)
    b.apply_config(replace(LOSS, path="recorded.toml"))
    other = replace(LOSS, loss=replace(LOSS.loss, modes={**LOSS.loss.modes, "mouth": "neutral"}))
    c.apply_config(other)
    rest_a, rest_b, rest_c = (_outputs(p, LOST_TICKS[75:140], 75) for p in (a, b, c))
    assert np.isfinite(base[-1]).all()
    np.testing.assert_array_equal(rest_b, rest_a)
    assert np.abs(rest_c[:, 0] - rest_a[:, 0]).max() > 0.05  # jawOpen: the voice's no more


def test_the_config_in_force_with_a_captured_neutral_again_while_lost_changes_nothing():
    """What a profile Save or a recording started mid-run hands back is ``current_config()``: its neutral is the
    one captured during the run, which the stage's own ``config`` does not hold."""
    frames = LOST_TICKS
    a, b = _pipeline(LOSS), _pipeline(LOSS)
    for p in (a, b):
        _outputs(p, frames[:5], 0)
        p.request_calibration()
        _outputs(p, frames[5:75], 5)  # the neutral captured from frames 5..35, then lost in the silence
        assert p.current_config().neutral is not None and p.state == "lost"
    b.apply_config(b.current_config())
    np.testing.assert_array_equal(_outputs(b, frames[75:140], 75), _outputs(a, frames[75:140], 75))
