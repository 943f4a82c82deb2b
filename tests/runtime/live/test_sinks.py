"""PNG frames: numbered in drawing order (an image-sequence reader stops at a gap), ticks kept in frames.csv."""

from __future__ import annotations

import csv

import numpy as np
from PIL import Image

from facepuppet.runtime.live.loop import TickInfo
from facepuppet.runtime.live.sinks import PngSink


class Pixels:
    def __init__(self) -> None:
        self.n = 0

    def read_pixels(self) -> np.ndarray:
        self.n += 1
        return np.full((6, 8, 3), self.n, np.uint8)


def test_frames_are_numbered_consecutively_and_the_index_says_each_ones_tick(tmp_path):
    sink, info = PngSink(tmp_path), TickInfo(Pixels())
    for k in (0, 9, 17, 1033):  # a run drawing on arrival labels its ticks on a 1 kHz grid
        info.k, info.t = k, k / 1000
        sink(info)
    sink.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "frame_00000.png", "frame_00001.png", "frame_00002.png", "frame_00003.png", "frames.csv"]
    assert [np.asarray(Image.open(tmp_path / f"frame_{i:05d}.png"))[0, 0, 0] for i in range(4)] == [1, 2, 3, 4]
    with open(tmp_path / "frames.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(int(r["frame"]), int(r["tick"]), float(r["t"])) for r in rows] == [
        (0, 0, 0.0), (1, 9, 0.009), (2, 17, 0.017), (3, 1033, 1.033)]
    assert sink.written == 4 and sink.last_path == tmp_path / "frame_00003.png"
