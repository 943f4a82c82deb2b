"""``replay`` without ``--fps`` draws a take at its own rate: each frame once, no tick without a new frame."""

from __future__ import annotations

import re

import numpy as np
import pytest

from facepuppet.runtime import cli
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.recording.session import SessionWriter

from helpers.small_characters import sphere_character

pytestmark = pytest.mark.gl  # replays draw headless (EGL)

N = 90  # 3 s at 30 Hz


def _take(tmp_path, rate=30.0, drop=()):
    character = sphere_character()
    char_path = character.save(tmp_path / "sphere.npz")
    rng = np.random.default_rng(7)
    name = character.shape_names[0]
    session = tmp_path / "take.fps"
    with SessionWriter(session) as w:
        for i in range(N):
            if i in drop:
                continue
            t = 50.0 + i / rate + rng.uniform(-1e-3, 1e-3)   # a timecode's millisecond sub-frame jitter
            w.write_frame(Frame(t=t, source="test", channels=(name,),
                                weights=np.array([0.5 + 0.5 * np.sin(i / 7)], np.float32)))
    return session, char_path


def _summary(text):
    m = re.search(r"replay: (\d+) ticks at ([\d.]+) fps.*frames received (\d+), stale dropped (\d+).*"
                  r"ticks without a new frame (\d+)", text)
    assert m, text
    ticks, fps, received, stale, empty = m.groups()
    return int(ticks), float(fps), int(received), int(stale), int(empty)


def test_a_30_hz_take_is_drawn_at_30_fps_each_frame_once(tmp_path, capsys):
    session, char_path = _take(tmp_path)
    assert cli.main(["replay", str(session), "-c", str(char_path), "--headless", "--size", "32x32",
                     "--out", str(tmp_path / "png")]) == 0
    out, err = capsys.readouterr()
    assert _summary(out) == (N, 30.0, N, 0, 0)
    assert "at the take's own rate, 30 fps" in err
    assert len(list((tmp_path / "png").glob("frame_*.png"))) == N


def test_dropped_frames_are_ticks_without_a_new_frame_and_the_rate_holds(tmp_path, capsys):
    session, char_path = _take(tmp_path, drop=(40, 41, 60))
    assert cli.main(["replay", str(session), "-c", str(char_path), "--headless", "--size", "32x32"]) == 0
    assert _summary(capsys.readouterr().out) == (N, 30.0, N - 3, 0, 3)


def test_fps_given_is_kept(tmp_path, capsys):
    session, char_path = _take(tmp_path)
    assert cli.main(["replay", str(session), "-c", str(char_path), "--headless", "--size", "32x32",
                     "--fps", "60"]) == 0
    ticks, fps, received, stale, empty = _summary(capsys.readouterr().out)
    assert (fps, received, stale) == (60.0, N, 0) and ticks == 2 * N - 1 and empty == ticks - N
