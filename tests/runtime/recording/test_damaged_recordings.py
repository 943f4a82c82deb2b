"""A damaged or forged recording is refused by its reader, naming the file, before a replay plays it: header
fields of the wrong type, frames or ticks out of order, packets of an input kind no adapter decodes, JSON or TOML
nested deep enough to exhaust a parser's recursion. (Each of these reached the frame loop, the decoders or the
parsers as a NumPy or Python error, shown as a traceback.)"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.files.json_limits import JsonLimitError
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.kinds import make_adapter
from facepuppet.runtime.recording.records import RecordKind, encode_config, encode_packet_record, encode_tick
from facepuppet.runtime.recording.replay_source import open_recording
from facepuppet.runtime.recording.session import MAGIC, SessionWriter, _check_header, _record, read_session
from facepuppet.runtime.recording.ticked_source import read_live_recording

from helpers.osc_helpers import vmc_frame
from helpers.small_characters import sphere_character


def _write(path, info, frames=(), packets=(), ticks=()):
    with SessionWriter(path, info=info, overwrite=True) as writer:
        for frame in frames:
            writer.write_frame(frame)
        for t, kind, data in packets:
            writer.write_record(RecordKind.PACKET, encode_packet_record(t, kind, data))
        for k, t in ticks:
            writer.write_record(RecordKind.TICK, encode_tick(k, t, 1, t))
    return path


def _frame(t):
    return Frame(t=t, source="vmc", channels=("jawOpen",), weights=np.array([0.3], np.float32))


JAW = vmc_frame(0.5)


@pytest.mark.parametrize("field, value, expected", [
    ("options", "abc", "a JSON object or null"),
    ("inputs", 5, "a list of source names or null"),
    ("inputs", ["vmc", 2], "a list of source names or null"),
    ("mix_sources", [1, 2], "a list of {name, kind} objects or null"),
    ("mix_sources", "ab", "a list of {name, kind} objects or null"),
    ("mix_sources", [{"name": "vmc#2"}], "a list of {name, kind} objects or null"),
])
def test_a_header_field_of_the_wrong_type_is_refused_naming_file_and_field(tmp_path, field, value, expected):
    path = _write(tmp_path / "take.fps", {"fps": 60, "input": "vmc", field: value},
                  packets=[(0.0, "vmc", JAW)], ticks=[(0, 0.0)])
    with pytest.raises(InputFileError, match=rf"take\.fps: session header field 'info\.{field}': expected "
                                             rf"{expected.replace('{', '[{]').replace('}', '[}]')}"):
        read_session(path)


def test_the_header_fields_of_a_real_recording_pass():
    """What ``run --record`` writes for several inputs: a list of names and a list of {name, kind, listen}."""
    info = {"fps": 60.0, "idle_fps": None, "input": "vmc", "options": {"actor": None, "face_id": None},
            "inputs": ["vmc", "vmc#2"], "mix_sources": [{"name": "vmc#2", "kind": "vmc", "listen": "0.0.0.0:1"}]}
    _check_header(Path("take.fps"), {"info": info})


def test_frames_out_of_time_order_are_refused_naming_the_file(tmp_path):
    path = _write(tmp_path / "take.fps", {"fps": 60}, frames=[_frame(0.5), _frame(0.2), _frame(0.3)])
    with pytest.raises(InputFileError, match=r"take\.fps: frame 1 has t=0\.2 after t=0\.5"):
        open_recording(path)


def test_packets_of_an_unknown_input_kind_are_refused_naming_the_file(tmp_path):
    path = _write(tmp_path / "take.fps", {"fps": 60, "input": "bogus"}, packets=[(0.0, "bogus", b"xx")])
    with pytest.raises(InputFileError, match=r"take\.fps: packet 0: unknown input kind 'bogus'"):
        open_recording(path)
    live = _write(tmp_path / "live.fps", {"fps": 60, "input": "bogus"}, packets=[(0.0, "bogus", b"xx")],
                  ticks=[(0, 0.0), (1, 1 / 60)])
    with pytest.raises(InputFileError, match=r"live\.fps: packet 0: unknown input kind 'bogus'"):
        read_live_recording(live, make_adapter)


@pytest.mark.parametrize("ticks, message", [
    ([(5, 0.0), (1, 1 / 60)], r"TICK record 1: tick index 1 \(after 5\)"),
    ([(0, 0.0), (0, 1 / 60)], r"TICK record 1: tick index 0 \(after 0\)"),
    ([(-3, 0.0), (1, 1 / 60)], r"TICK record 0: tick index -3 \(the first\)"),
])
def test_tick_indices_that_do_not_increase_from_0_are_refused_naming_the_file(tmp_path, ticks, message):
    path = _write(tmp_path / "take.fps", {"fps": 60, "input": "vmc"}, packets=[(0.0, "vmc", JAW)], ticks=ticks)
    with pytest.raises(InputFileError, match=rf"take\.fps: {message}"):
        read_live_recording(path, make_adapter)


def test_a_live_recording_with_increasing_ticks_still_reads(tmp_path):
    path = _write(tmp_path / "take.fps", {"fps": 60, "input": "vmc"}, packets=[(0.0, "vmc", JAW)],
                  ticks=[(0, 0.0), (2, 2 / 60), (3, 3 / 60)])
    live = read_live_recording(path, make_adapter)
    assert [t.k for t in live.ticks] == [0, 2, 3] and len(live.frames) == 1


# -- JSON and TOML nested to exhaust a parser's recursion: refused within the limits, naming file and record ----

DEEP_TOML = "a = " + "[" * 50_000 + "]" * 50_000 + "\n"


def _deep(n: int) -> bytes:
    return b"[" * n + b"]" * n


def test_a_header_nested_100000_deep_is_refused_naming_the_file_and_record(tmp_path):
    path = tmp_path / "take.fps"
    path.write_bytes(MAGIC + _record(RecordKind.HEADER, b'{"format": "facepuppet session", "info": {"x": '
                                     + _deep(100_000) + b"}}"))
    with pytest.raises(InputFileError, match=r"take\.fps: HEADER record at byte offset 8: nests 100002 levels "
                                             r"deep; at most 64 allowed"):
        read_session(path)


def test_a_layout_nested_deep_is_refused_naming_the_file_and_record(tmp_path):
    path = _write(tmp_path / "take.fps", {"fps": 60})
    at = path.stat().st_size
    with open(path, "ab") as f:
        f.write(_record(RecordKind.LAYOUT, b'{"id": 0, "source": ' + _deep(5000) + b"}"))
    with pytest.raises(InputFileError, match=rf"take\.fps: LAYOUT record at byte offset {at}: nests 5001 levels"):
        read_session(path)


def test_a_state_record_nested_deep_is_refused_naming_the_file_and_record(tmp_path):
    from facepuppet.runtime.live.pipeline import LivePipeline
    from facepuppet.runtime.session.recording_feed import restore_state

    with pytest.raises(JsonLimitError, match=r"take\.fps: STATE record \(the filter stage's state at t = 1\.250 s\): "
                                             r"nests 50000 levels deep"):
        restore_state(LivePipeline(log=lambda s: None), (1.25, _deep(50_000).decode()), tmp_path / "take.fps",
                      lambda s: None)


def _replay(path, character, *extra):
    return subprocess.run([sys.executable, "-m", "facepuppet", "replay", str(path), "-c", str(character),
                           "--headless", "--size", "32x24", *extra], capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def character(tmp_path_factory):
    path = tmp_path_factory.mktemp("hostile") / "sphere.npz"
    sphere_character().save(path)
    return path


def test_replay_refuses_a_recorded_config_nested_50000_deep_as_config_refuses_it(tmp_path, character):
    """The recorded config (a CONFIG record, the header's info.config) goes through --config's checks: exit 2,
    one line naming the file and the record or field, no RecursionError traceback."""
    change = tmp_path / "change.fps"
    with SessionWriter(change, info={"fps": 60, "input": "vmc", "config": "[face]\n"}) as w:
        w.write_record(RecordKind.PACKET, encode_packet_record(0.0, "vmc", JAW))
        w.write_record(RecordKind.TICK, encode_tick(0, 0.0, 1, 0.0))
        w.write_record(RecordKind.CONFIG, encode_config(0.01, DEEP_TOML))
        w.write_record(RecordKind.TICK, encode_tick(1, 1 / 60, 1, 1 / 60))
    first = _write(tmp_path / "first.fps", {"fps": 60, "input": "vmc", "config": DEEP_TOML},
                   packets=[(0.0, "vmc", JAW)], ticks=[(0, 0.0), (1, 1 / 60)])
    toml = tmp_path / "deep.toml"
    toml.write_text(DEEP_TOML)
    for path, extra, where in ((change, (), r"change\.fps: CONFIG record 0 \(the config change at t=0\.010 s\)"),
                               (first, (), r"first\.fps: session header field 'info\.config' \(the live run's "
                                           r"config\)"),
                               (first, ("--config", str(toml)), r"deep\.toml")):
        done = _replay(path, character, *extra)
        assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
        assert re.search(rf"facepuppet replay: error: \S*{where}: not a config facepuppet can read: arrays or "
                         r"tables nest too deep", done.stderr.splitlines()[-1]), done.stderr


def test_replay_refuses_a_header_nested_100000_deep_with_exit_2(tmp_path, character):
    path = tmp_path / "take.fps"
    path.write_bytes(MAGIC + _record(RecordKind.HEADER, b'{"info": {"fps": 60, "x": ' + _deep(100_000) + b"}}"))
    done = _replay(path, character)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert done.stderr.splitlines()[-1].endswith("take.fps: HEADER record at byte offset 8: nests 100002 levels "
                                                 "deep; at most 64 allowed")
