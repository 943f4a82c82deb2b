"""replay of a long take shows progress (ticks, rate, time left) on a terminal, none when piped."""

from __future__ import annotations

import io
import sys

import numpy as np
import pytest

from facepuppet.runtime import cli
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.recording.session import SessionWriter

from helpers.small_characters import sphere_character


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.gl
@pytest.mark.parametrize("terminal", [True, False])
def test_replay_progress_on_a_terminal_only(tmp_path, monkeypatch, terminal):
    character = sphere_character()
    char_path = character.save(tmp_path / "sphere.npz")
    session = tmp_path / "take.fps"
    name = character.shape_names[0]
    with SessionWriter(session) as w:
        for i in range(120):                              # 2 s at 60 Hz
            w.write_frame(Frame(t=i / 60, source="test", channels=(name,),
                                weights=np.array([0.5 + 0.5 * np.sin(i / 9)], np.float32)))
    err = Terminal() if terminal else io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    assert cli.main(["replay", str(session), "-c", str(char_path), "--headless", "--size", "32x32"]) == 0
    text = err.getvalue()
    if terminal:
        assert "\rreplay: " in text and "/120 ticks" in text and text.endswith("\n")
    else:
        assert "\rreplay" not in text


@pytest.mark.gl
def test_replay_progress_in_a_log_is_whole_lines(tmp_path, monkeypatch):
    """Off a terminal the replay logs its progress now and then as plain lines (every 30 s; every tick here)."""
    from facepuppet.runtime.session import recording_feed

    monkeypatch.setattr(recording_feed, "PIPED_EVERY_S", 0.0)
    character = sphere_character()
    char_path = character.save(tmp_path / "sphere.npz")
    session = tmp_path / "take.fps"
    name = character.shape_names[0]
    with SessionWriter(session) as w:
        for i in range(30):
            w.write_frame(Frame(t=i / 30, source="test", channels=(name,), weights=np.array([i / 30], np.float32)))
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    assert cli.main(["replay", str(session), "-c", str(char_path), "--headless", "--size", "32x32"]) == 0
    text = err.getvalue()
    lines = [line for line in text.splitlines() if line.startswith("replay: ") and "/30 ticks" in line]
    assert "\r" not in text and lines and lines[-1].startswith("replay: 30/30 ticks (100%)")
