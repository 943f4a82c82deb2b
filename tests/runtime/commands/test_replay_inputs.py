"""replay refuses unusable inputs with exit code 2 and a message naming the file, before any GL context.

Every case fails before the first frame would be drawn, so none needs EGL.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from facepuppet.runtime.cli import main
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.recording.session import SessionWriter

from helpers.file_fuzz import swap_session_header

CHARACTER = Path(__file__).resolve().parents[1] / "files" / "data" / "tables_v1" / "character.npz"


def take(path: Path) -> Path:
    with SessionWriter(path, info={"fps": 60, "input": "vmc"}) as writer:
        for i in range(5):
            writer.write_frame(Frame(t=i / 60, source="vmc", channels=("jawOpen",),
                                     weights=np.array([i / 5], np.float32)))
    return path


def replay(capsys, *args: str) -> tuple[int, str]:
    rc = main(["replay", *args, "-c", str(CHARACTER), "--headless"])
    return rc, capsys.readouterr().err


def test_replay_of_a_folder_is_refused_naming_it(tmp_path, capsys):
    rc, err = replay(capsys, str(tmp_path))
    assert rc == 2 and f"{tmp_path}: expected a recording" in err and "found a folder" in err
    assert "Traceback" not in err


def test_replay_with_a_folder_for_config_is_refused_naming_it(tmp_path, capsys):
    conf = tmp_path / "conf"
    conf.mkdir()
    rc, err = replay(capsys, str(take(tmp_path / "take.fps")), "--config", str(conf))
    assert rc == 2 and f"{conf}: expected a TOML config file, found a folder" in err


def test_replay_of_a_fifo_is_refused_without_opening_it(tmp_path):
    """A FIFO with no writer blocks whoever opens it: the command must refuse it unopened.

    Run in a child process so that a regression blocks the child, not the test run (the timeout
    is a bound on a hang, not a speed limit).
    """
    fifo = tmp_path / "pipe.fps"
    os.mkfifo(fifo)
    code = ("import sys; from facepuppet.runtime.cli import main; "
            f"sys.exit(main(['replay', {str(fifo)!r}, '-c', {str(CHARACTER)!r}, '--headless']))")
    try:
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        pytest.fail("replay of a FIFO blocked (opened it instead of refusing it)")
    assert done.returncode == 2 and f"{fifo}: expected a recording" in done.stderr and "FIFO" in done.stderr


HEADERS = [[1, 2], {"format": "facepuppet session", "info": "a string"},
           {"format": "facepuppet session", "info": {"fps": None, "input": "vmc"}},
           {"format": "facepuppet session", "info": {"fps": [60], "input": "vmc"}},
           {"format": "facepuppet session", "info": {"fps": "abc", "input": "vmc"}},
           {"format": "facepuppet session", "info": {"fps": 60, "input": 7}}]


@pytest.mark.parametrize("header", HEADERS, ids=[json.dumps(h)[:40] for h in HEADERS])
def test_replay_of_a_crc_valid_but_malformed_header_is_refused_naming_the_file(tmp_path, capsys, header):
    path = take(tmp_path / "take.fps")
    path.write_bytes(swap_session_header(path.read_bytes(), json.dumps(header).encode()))
    rc, err = replay(capsys, str(path))
    assert rc == 2 and f"{path}: session header" in err, err


@pytest.mark.gl
def test_replay_of_a_frame_at_1e300_ends_after_the_gap_limit_and_says_so(tmp_path, capsys):
    path = tmp_path / "far.fps"
    with SessionWriter(path, info={"fps": 60, "input": "vmc"}) as writer:
        for t in (0.0, 1 / 60, 1e300):
            writer.write_frame(Frame(t=t, source="vmc", channels=("jawOpen",), weights=np.array([0.5], np.float32)))
    rc = main(["replay", str(path), "-c", str(CHARACTER), "--headless", "--fps", "5", "--size", "64x64",
               "--max-gap", "2"])
    out = capsys.readouterr()
    text = out.out + out.err
    assert rc == 0, text
    assert "replay: cut 1 pauses longer than the gap limit (first at frame 2, longest 1e+300 s" in text
    assert "--max-gap SECONDS changes the limit (2 s)" in text
    assert "replay: 12 ticks at 5 fps" in text  # ticks at 0, 0.2, ..., 2.2 s: the first past 2.017 s ends it
