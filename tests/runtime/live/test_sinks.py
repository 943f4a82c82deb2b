"""PNG frames: numbered in drawing order (an image-sequence reader stops at a gap), ticks kept in frames.csv."""

from __future__ import annotations

import csv

import numpy as np
import pytest
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


def test_encoding_threads_write_the_same_files_in_the_same_order(tmp_path):
    infos = []
    for workers in (0, 3):
        sink, info = PngSink(tmp_path / str(workers), workers=workers), TickInfo(Pixels())
        for k in range(40):
            info.k, info.t = 2 * k, k / 30
            sink(info)
            assert sink.written <= k + 1 and len(sink._pending) <= workers + 1  # bounded, however slow the disk
        sink.close()
        sink.close()  # once
        infos.append(sink)
    assert [s.written for s in infos] == [40, 40]
    for name in [f"frame_{i:05d}.png" for i in range(40)] + ["frames.csv"]:
        assert (tmp_path / "0" / name).read_bytes() == (tmp_path / "3" / name).read_bytes()
    assert not [p for p in (tmp_path / "3").iterdir() if p.name.startswith(".")]  # no temporary file left


def test_an_image_that_cannot_be_written_raises_at_a_later_tick_or_at_close(tmp_path):
    sink, info = PngSink(tmp_path, workers=2), TickInfo(Pixels())
    info.renderer.read_pixels = lambda: np.zeros((4, 4, 7), np.uint8)  # no PNG mode has 7 channels
    with pytest.raises(TypeError, match="Cannot handle this data type"):
        sink(info)
        sink.close()
    sink.close()
    assert sink.written == 0 and not list(tmp_path.glob("*.png"))
