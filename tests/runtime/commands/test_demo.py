"""The embedded demo runs headless end to end through the real frame loop and EGL."""

from __future__ import annotations

import numpy as np
from PIL import Image

from facepuppet.runtime.cli import main


def test_demo_headless_writes_frames_contact_sheet_and_timings(tmp_path, egl_ctx, capsys):
    out = tmp_path / "demo"
    code = main(["demo", "--headless", "--out", str(out), "--duration", "1.0", "--fps", "10",
                 "--size", "320x180", "--path", "cpu"])
    assert code == 0
    frames = sorted(out.glob("frame_*.png"))
    assert len(frames) == 11  # ticks at 0, 0.1, ..., 1.0 s
    first = np.asarray(Image.open(frames[0]).convert("RGB"))
    last = np.asarray(Image.open(frames[-1]).convert("RGB"))
    assert first.shape == (180, 320, 3)
    # the head is drawn (not just background) and the performance moves it
    assert (first.std(axis=(0, 1)) > 5).all()
    assert np.abs(first.astype(int) - last.astype(int)).mean() > 0.1
    sheet = Image.open(out / "contact_sheet.png")
    assert sheet.width == 4 * 320
    text = capsys.readouterr().out
    for stage in ("snapshot", "map", "draw_submit", "gpu_finish", "sink"):
        assert stage in text
    assert "deformation path: cpu" in text or "cpu deformation path" in text


def test_demo_contact_sheet_cells_are_filled_by_the_head(tmp_path, egl_ctx):
    # the frames are wide and the head tall: a whole frame per cell showed the head in a seventh of it
    out = tmp_path / "demo"
    assert main(["demo", "--headless", "--out", str(out), "--duration", "2.0", "--fps", "10", "--no-frames",
                 "--size", "640x360", "--path", "cpu"]) == 0
    sheet = np.asarray(Image.open(out / "contact_sheet.png").convert("RGB")).astype(int)
    cell_w = sheet.shape[1] // 4
    cell_h = sheet.shape[0] // 3 - 18                       # 12 cells in 3 rows, an 18-pixel label under each
    for row in range(3):
        for col in range(4):
            cell = sheet[row * (cell_h + 18):row * (cell_h + 18) + cell_h, col * cell_w:(col + 1) * cell_w]
            drawn = np.abs(cell - cell[0, 0]).sum(axis=2) > 30          # not the background
            assert drawn.mean() > 0.4, f"cell {row},{col}: the head covers {drawn.mean():.0%} of it"
