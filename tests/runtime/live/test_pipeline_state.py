"""The filter stage's state as a recording started mid-run keeps it (LivePipeline.state_snapshot / restore_state):
a stage restored from a snapshot goes on exactly as the one it was taken from; a snapshot that is not one is
refused naming the field, changing nothing."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.config import FilterSettings, LiveConfig
from facepuppet.runtime.live.pipeline import LivePipeline

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
    got = []
    for k, f in enumerate(frames, start=k0):
        out = pipeline(f, k / 60)
        got.append(np.concatenate([out.weights, out.head_rotation, out.head_translation]))
    return np.array(got)


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


def test_a_stage_not_live_has_no_snapshot():
    p = LivePipeline(SMOOTH, log=lambda s: None)
    assert p.state_snapshot() is None  # waiting: nothing to go on from
    p(_frames(1)[0], 0.0)
    assert p.state_snapshot() is not None
    p.request_calibration()
    assert p.state_snapshot() is None  # a capture in progress is not kept


@pytest.mark.parametrize("change, match", [
    (lambda d: d.update(version=2), "expected a version 1 snapshot"),
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
    from facepuppet.runtime.commands.replay import _restore_state

    lines: list[str] = []
    p = LivePipeline(SMOOTH, log=lambda s: None)
    _restore_state(p, (1.25, text), tmp_path / "take.fps", lines.append)
    assert len(lines) == 1 and "warning" in lines[0] and "take.fps" in lines[0] and "t = 1.250 s" in lines[0]
    assert p.state == "waiting"
