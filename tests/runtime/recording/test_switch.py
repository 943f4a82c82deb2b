"""SwitchableRecorder: recordings started and stopped during a run, real files."""

from __future__ import annotations

from pathlib import Path

import pytest

from facepuppet.runtime.recording.recorder import PacketRecorder
from facepuppet.runtime.recording.session import read_session
from facepuppet.runtime.recording.switch import SwitchableRecorder, default_name

CLOCK = 1_800_000_000.0  # a fixed wall-clock time for the default names


def _holder(tmp_path, **kw):
    return SwitchableRecorder(lambda path: PacketRecorder(path, "vmc", info={"what": "test"}), tmp_path,
                              clock=lambda: CLOCK, **kw)


def test_nothing_is_recorded_before_start_nor_after_stop_and_each_start_is_a_new_complete_file(tmp_path):
    rec = _holder(tmp_path)
    rec.put(b"before", 1.0)
    rec.put_tick(0, 0.0, 1, 1.0)
    assert not rec.recording and rec.path is None
    first = rec.start("", config_text="[face]\nmirror = true\n")
    rec.put(b"one", 2.0)
    rec.put_tick(1, 0.1, 2, 2.0)
    rec.put_event(0.1, False)
    assert rec.stop() == first
    rec.put(b"between", 3.0)
    second = rec.start("")
    rec.put(b"two", 4.0)
    rec.tagged("vmc#2")(b"other", 4.5)
    rec.close()
    assert first.name == default_name(CLOCK) and second.name == default_name(CLOCK)[:-4] + "-2.fps"
    a, b = read_session(first), read_session(second)
    assert a.complete and b.complete
    assert [p.data for p in a.packets] == [b"one"]
    assert [t.k for t in a.ticks] == [1] and a.events == [(0.1, False)]
    assert a.configs == [(0.0, "[face]\nmirror = true\n")]
    assert [(p.kind, p.data) for p in b.packets] == [("vmc", b"two"), ("vmc#2", b"other")]
    assert b.header["info"]["what"] == "test"
    counters = dict(rec.counters)
    assert counters["packets_recorded"] == 3 and counters["recordings"] == 2 and counters["record_dropped"] == 0


def test_a_name_goes_into_the_folder_gets_the_extension_and_an_existing_file_is_refused(tmp_path):
    rec = _holder(tmp_path)
    assert rec.start("take1") == tmp_path / "take1.fps"
    rec.stop()
    with pytest.raises(FileExistsError):
        rec.start("take1")
    assert "take1.fps" in rec.message and rec.counters["record_failed"] == 1
    assert not rec.recording
    other = tmp_path / "sub" / "x.fps"
    other.parent.mkdir()
    assert rec.start(str(other)) == other
    rec.close()
    assert read_session(tmp_path / "take1.fps").complete and read_session(other).complete


def test_a_run_with_several_inputs_refuses_a_start_once_it_ticks_with_the_reason(tmp_path):
    rec = _holder(tmp_path, refuse_midrun="not with several inputs")
    assert rec.start(Path(tmp_path / "from-start.fps")).name == "from-start.fps"  # --record: before the first tick
    rec.stop()
    rec.saw_tick(0.5)
    with pytest.raises(ValueError, match="several inputs"):
        rec.start("")
    rec.close()
    assert not list(tmp_path.glob("facepuppet-*"))


def test_a_replay_in_real_time_of_a_recording_started_mid_run_starts_at_its_first_tick():
    from facepuppet.runtime.session.recording_feed import replay_wall_clock

    now = [100.0]
    clock = replay_wall_clock([6000, 6001], 1000.0)  # the panel's recording began 6 s into the run
    clock._monotonic = lambda: now[0]
    clock.start()
    assert clock.now() == pytest.approx(6.0)  # the loop's wait for tick 6000 is over at once
    assert clock.wait_until(6.0) == pytest.approx(0.0)
    plain = replay_wall_clock([0, 1], 1000.0)
    plain._monotonic = lambda: now[0]
    plain.start()
    assert plain.now() == 0.0
