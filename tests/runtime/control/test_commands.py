"""The control verbs checked at the door, the expression ramps, the control stage's stacking over the tracker's
channels and its replay schedule, the rate limit, the view frames' encoding and ``--web``'s options."""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest
from pythonosc.osc_message_builder import OscMessageBuilder

from facepuppet.runtime.control.commands import Command, CommandError, parse_command, parse_osc
from facepuppet.runtime.control.limits import RateLimit
from facepuppet.runtime.control.options import ControlOptions
from facepuppet.runtime.control.osc_server import OscControl
from facepuppet.runtime.control.stage import ControlStage
from facepuppet.runtime.control.triggers import ExpressionTriggers
from facepuppet.runtime.control.view_frames import HEADER, decode, encode
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.frames import Frame


def test_a_command_is_checked_with_its_defaults_and_recorded_as_it_reads_back():
    c = parse_command({"verb": "expression", "name": "Joy", "action": "for", "seconds": 2, "id": "a"})
    assert c == Command("expression", {"name": "Joy", "action": "for", "value": 1.0, "fade": 0.15, "seconds": 2.0},
                        "a")
    assert parse_command(c.to_json()).args == c.args
    assert parse_command({"verb": "framing", "zoom": 2, "pan": [0.5, -0.25]}).args == \
        {"framing": None, "zoom": 2.0, "pan": [0.5, -0.25]}


@pytest.mark.parametrize(("doc", "match"), [
    ([1, 2], "expected a JSON object"),
    ({"verb": "explode"}, "field 'verb': expected one of"),
    ({"verb": "expression", "name": "Joy", "action": "on", "fade": math.inf}, "field 'fade'"),
    ({"verb": "expression", "name": "Joy", "action": "on", "value": 2}, "field 'value'"),
    ({"verb": "expression", "name": "Joy", "action": "for"}, "field 'seconds'"),
    ({"verb": "expression", "name": "Joy", "action": "on", "seconds": 1}, "only with action 'for'"),
    ({"verb": "expression", "name": "x" * 200, "action": "on"}, "field 'name'"),
    ({"verb": "calibrate", "now": True}, "field 'now': unknown"),
    ({"verb": "profile", "name": "/etc/passwd"}, "never a path"),
    ({"verb": "record", "action": "start", "name": "../x"}, "field 'name'"),
    ({"verb": "framing", "pan": [1]}, "field 'pan'"),
    ({"verb": "subscribe", "rate": 1000}, "field 'rate'"),
    ({"verb": "status", "id": [1]}, "field 'id'"),
    ({"verb": "expression", "name": "Joy", "action": "on", "value": True}, "field 'value'"),
])
def test_a_bad_command_is_refused_naming_the_field(doc, match):
    with pytest.raises(CommandError, match=match):
        parse_command(doc)


def test_the_osc_addresses_are_the_same_verbs():
    assert parse_osc("/facepuppet/expression/on", ["Joy", 0.5]).args["fade"] == 0.5
    assert parse_osc("/facepuppet/expression/for", ["Fun", 3.0]).args["seconds"] == 3.0
    assert parse_osc("/facepuppet/calibrate", []).verb == "calibrate"
    assert parse_osc("/facepuppet/record/start", ["take"]).args == {"action": "start", "name": "take"}
    assert parse_osc("/facepuppet/framing", ["face", 1.5, 0.1, 0.2]).args == \
        {"framing": "face", "zoom": 1.5, "pan": [0.1, 0.2]}
    with pytest.raises(CommandError, match="unknown control address"):
        parse_osc("/facepuppet/explode", [])
    with pytest.raises(CommandError, match="field 'action'"):
        parse_osc("/facepuppet/expression/maybe", ["Joy"])


def test_ramps_fade_hold_and_toggle_in_tick_time():
    tr = ExpressionTriggers(("Joy", "Angry"))
    assert np.isnan(tr.values(0.0)).all()  # at rest: not sent
    tr.apply(0, "on", 1.0, fade=0.5)
    assert tr.values(1.25)[0] == pytest.approx(0.5) and tr.values(1.5)[0] == 1.0
    tr.apply(0, "toggle", 2.0, fade=1.0)  # on -> off, from 1.0
    assert tr.values(2.5)[0] == pytest.approx(0.5)
    assert np.isnan(tr.values(3.0)[0])
    tr.apply(1, "for", 4.0, value=0.8, fade=0.0, seconds=1.0)
    assert tr.values(4.0)[1] == pytest.approx(0.8) and tr.values(4.99)[1] == pytest.approx(0.8)
    assert np.isnan(tr.values(5.0)[1])
    assert tr.find("joy") == 0 and tr.find("Sad") is None


def _frame(t, **weights):
    return Frame(t=t, source="vmc", channels=tuple(weights), weights=np.array(list(weights.values()), np.float32))


def test_the_stage_stacks_by_maximum_adds_missing_channels_and_keeps_moving_without_new_frames():
    published = []
    stage = ControlStage(("Joy", "Blink"), publish=lambda t, doc: published.append((t, doc)))
    first = _frame(0.0, jawOpen=0.3, Joy=0.6)
    assert stage(first, 0.0) is first  # nothing triggered: the frame as it came
    stage.submit(parse_command({"verb": "expression", "name": "Joy", "action": "on", "value": 0.4, "fade": 0}))
    stage.submit(parse_command({"verb": "expression", "name": "Blink", "action": "on", "fade": 0.1}))
    out = stage(_frame(0.1, jawOpen=0.3, Joy=0.6), 0.1)
    assert out.channels == ("jawOpen", "Joy", "Blink")  # Blink added, Joy the tracker's own channel
    assert out.weights.tolist()[:2] == pytest.approx([0.3, 0.6])  # the tracker's 0.6 over the trigger's 0.4
    assert out.weights[2] == 0.0  # Blink ramps from 0 over 0.1 s
    moving = stage(None, 0.15)  # no new frame: the ramp is drawn anyway, over the last frame
    assert moving is not None and moving.weights[2] == pytest.approx(0.5) and moving.weights[0] == pytest.approx(0.3)
    assert stage(None, 0.2).weights[2] == pytest.approx(1.0)
    assert stage(None, 0.3) is None  # nothing moves: what is on screen stays
    assert [doc["name"] for _, doc in published] == ["Joy", "Blink"] and published[0][0] == 0.1
    stage.submit(parse_command({"verb": "expression", "name": "Nobody", "action": "on"}))
    stage.submit(parse_command({"verb": "calibrate"}))
    stage(None, 0.4)
    assert stage.counters == {"commands_applied": 2, "commands_failed": 2, "commands_dropped": 0}
    assert len(published) == 2  # what failed is not recorded


def test_a_rig_without_expressions_gets_its_shapes_raised_over_the_mapped_frame():
    from facepuppet.runtime.live.mapper import Mapper

    rig = ("browInnerUp_L", "browInnerUp_R", "jawOpen")
    stage = ControlStage(rig, mapper=Mapper(rig, None, log=lambda s: None))
    frame = _frame(0.0, browInnerUp=0.5, jawOpen=0.3)  # an unsided channel split onto both sides
    assert stage(frame, 0.0) is frame
    stage.submit(parse_command({"verb": "expression", "name": "jawOpen", "action": "on", "value": 0.8, "fade": 0}))
    out = stage(_frame(0.1, browInnerUp=0.5, jawOpen=0.3), 0.1)
    assert out.channels == rig and out.weights.tolist() == pytest.approx([0.5, 0.5, 0.8])
    stage.submit(parse_command({"verb": "expression", "name": "browInnerUp_L", "action": "on", "value": 0.2,
                                "fade": 0}))
    out = stage(None, 0.2)  # no new frame: the last one, mapped again; the tracker's 0.5 over the trigger's 0.2
    assert out.weights.tolist() == pytest.approx([0.5, 0.5, 0.8])


def test_a_replay_schedule_applies_the_recorded_commands_at_their_ticks():
    live = ControlStage(("Joy",))
    recorded = []
    live.publish = lambda t, doc: recorded.append((t, doc))
    frames = [_frame(k / 10, jawOpen=k / 10) for k in range(10)]
    drawn_live = []
    for k, f in enumerate(frames):
        if k == 3:
            live.submit(parse_command({"verb": "expression", "name": "Joy", "action": "for", "seconds": 0.3,
                                       "fade": 0.1}))
        drawn_live.append(live(f if k % 2 == 0 else None, k / 10))
    replay = ControlStage(("Joy",), schedule=recorded)
    drawn_back = [replay(f if k % 2 == 0 else None, k / 10) for k, f in enumerate(frames)]
    for a, b in zip(drawn_live, drawn_back):
        assert (a is None) == (b is None)
        if a is not None:
            np.testing.assert_array_equal(a.weights, b.weights)
    assert any(d is not None and d.channels == ("jawOpen", "Joy") and d.weights[1] == pytest.approx(1.0)
               for d in drawn_back)


def test_the_rate_limit_lets_a_burst_through_then_its_rate():
    limit = RateLimit(rate=10, burst=5)
    assert [limit.take(0.0) for _ in range(7)] == [True] * 5 + [False] * 2
    assert limit.take(0.1) and not limit.take(0.1)


def test_osc_control_counts_what_it_refuses_and_hands_over_the_show_verbs():
    got = []
    osc = OscControl("127.0.0.1", 0, token=None, submit=lambda c: got.append(c) or True, log=lambda s: None)
    try:
        osc.handle(b"garbage", 0.0)
        osc.handle(OscMessageBuilder("/facepuppet/nothing").build().dgram, 0.0)
        m = OscMessageBuilder("/facepuppet/expression/toggle")
        m.add_arg("Joy")
        osc.handle(m.build().dgram, 0.0)
    finally:
        osc.close()
    assert [c.args["action"] for c in got] == ["toggle"]
    assert osc.counters["malformed"] == 1 and osc.counters["bad_commands"] == 1 and osc.counters["commands"] == 1


def test_a_view_frame_reads_back_as_sent():
    rgba = np.random.default_rng(1).integers(0, 255, (6, 8, 4), dtype=np.uint8)
    message = encode(8, 6, 3, 42, 1234.5, rgba.tobytes())
    assert HEADER.size == 28  # what view.html reads
    w, h, flags, k, t, back = decode(message)
    assert (w, h, flags, k, t) == (8, 6, 3, 42, 1234.5)
    np.testing.assert_array_equal(back, rgba)
    with pytest.raises(ValueError, match="not a view frame"):
        decode(b"XXXX" + message[4:])


def _options(*argv):
    parser = argparse.ArgumentParser()
    ControlOptions.add_arguments(parser)
    return ControlOptions.from_args(parser.parse_args(list(argv)))


def test_web_listens_on_loopback_by_default_and_another_host_needs_a_token():
    assert _options().web is None
    plain = _options("--web")
    assert plain.web == ("127.0.0.1", 8765) and plain.token is None
    lan = _options("--web", "0.0.0.0:9000")
    assert lan.generated and len(lan.token) >= 16
    assert _options("--web", "0.0.0.0:9000", "--web-token", "a" * 20).token == "a" * 20
    with pytest.raises(UsageError, match="--web-token: 16 to 128"):
        _options("--web", "--web-token", "short")
    with pytest.raises(UsageError, match="--web: expected HOST:PORT"):
        _options("--web", "nowhere")
    with pytest.raises(UsageError, match="--web-token: only with --web"):
        _options("--web-token", "a" * 20)


def test_hotkeys_in_a_config_are_checked_and_saved_back_with_it():
    from facepuppet.runtime.live.config import LiveConfigError
    from facepuppet.runtime.live.profiles import config_to_toml, parse_config_text

    text = '[hotkeys]\nj = { verb = "expression", name = "Joy", action = "toggle" }\nF5 = { verb = "calibrate" }\n'
    config = parse_config_text(text, "live.toml")
    assert config.hotkeys == (("J", {"verb": "expression", "name": "Joy", "action": "toggle"}),
                              ("F5", {"verb": "calibrate"}))
    assert parse_config_text(config_to_toml(config), "saved.toml").hotkeys == config.hotkeys
    for bad, match in (('C = { verb = "calibrate" }', "hotkeys.C': C is the window's calibrate key"),
                       ('F13 = { verb = "calibrate" }', "hotkeys.F13': a hotkey is a letter"),
                       ('J = { verb = "status" }', "verb 'status' answers a client"),
                       ('J = { verb = "expression", name = "Joy" }', "hotkeys.J': field 'action'")):
        with pytest.raises(LiveConfigError, match=match):
            parse_config_text("[hotkeys]\n" + bad, "live.toml")
