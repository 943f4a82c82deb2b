"""``facepuppet replay`` as a real process: stopped by SIGINT or SIGTERM part way through a long take, it
prints its summary, says what stopped it, exits 128 + the signal, and leaves only whole files: every PNG
reads, ``frames.csv`` names each one, the video holds as many frames as the summary's ticks."""

from __future__ import annotations

import csv
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.recording.session import SessionWriter

from helpers.small_characters import sphere_character

pytestmark = [pytest.mark.gl, pytest.mark.slow]  # the subprocess draws headless (EGL)

START_DEADLINE_S = 120.0  # a fresh interpreter making an EGL context and decoding the take on a loaded machine
RATE, SECONDS = 30.0, 600  # far longer than the test waits: the signal always comes part way through


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    folder = tmp_path_factory.mktemp("replay_signals")
    character = sphere_character()
    char_path = character.save(folder / "sphere.npz")
    name = character.shape_names[0]
    session = folder / "long.fps"
    with SessionWriter(session) as w:
        for i in range(int(RATE * SECONDS)):
            w.write_frame(Frame(t=i / RATE, source="test", channels=(name,),
                                weights=np.array([0.5 + 0.5 * np.sin(i / 9)], np.float32)))
    return session, char_path


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_stops_the_replay_with_its_summary_and_whole_files(take, tmp_path, signum):
    session, char_path = take
    out_dir, video = tmp_path / "png", tmp_path / "take.mp4"
    proc = subprocess.Popen(
        [sys.executable, "-m", "facepuppet", "replay", str(session), "-c", str(char_path), "--headless",
         "--size", "64x48", "--out", str(out_dir), "--video", str(video)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        end = time.monotonic() + START_DEADLINE_S
        while time.monotonic() < end and proc.poll() is None and len(list(out_dir.glob("frame_*.png"))) < 20:
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()
        os.kill(proc.pid, signum)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 128 + signum, (out, err)
    assert "Traceback" not in err
    name = signal.Signals(signum).name
    m = re.search(rf"replay: stopped by {name} after (\d+) of (\d+) ticks", out)
    assert m, out
    ticks, total = int(m.group(1)), int(m.group(2))
    assert 20 <= ticks < total == RATE * SECONDS
    assert re.search(rf"^replay: {ticks} ticks at 30 fps", out, re.M), out
    assert f"wrote {ticks} PNGs" in out
    pngs = sorted(out_dir.glob("frame_*.png"))
    assert [p.name for p in pngs] == [f"frame_{i:05d}.png" for i in range(ticks)]
    assert sorted(p.name for p in out_dir.iterdir()) == sorted([*(p.name for p in pngs), "frames.csv"])
    for p in pngs:
        with Image.open(p) as image:
            image.load()  # a truncated PNG raises here
    with open(out_dir / "frames.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["frame"]) for r in rows] == list(range(ticks))
    assert [int(r["tick"]) for r in rows] == list(range(ticks))
    av = pytest.importorskip("av", reason="the video extra (PyAV) is not installed")
    with av.open(str(video)) as container:
        assert sum(1 for _ in container.decode(video=0)) == ticks
