"""Capture readers and writers: round trips, gaps, units, malformed files."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import need_shared
from facepuppet.offline.io.capture import (
    Capture,
    CaptureError,
    fill_gaps,
    read_capture,
    write_c3d,
    write_csv,
    write_trc,
)


def _capture(units="mm") -> Capture:
    rng = np.random.default_rng(3)
    m = rng.normal(size=(30, 5, 3)).astype(np.float32) * 10
    m[4:7, 1] = np.nan          # short gap: filled on read
    m[10:25, 2] = np.nan        # long gap: reported
    return Capture(m, ("a", "b", "c_long", "d", "e"), 120.0, units)


@pytest.mark.parametrize("writer", [write_trc, write_c3d, write_csv])
def test_round_trip_keeps_markers_names_rate_units_and_gaps(tmp_path, writer):
    cap = _capture("mm")
    path = writer(tmp_path / f"take.{writer.__name__[6:]}", cap)
    back = read_capture(path, max_gap=5)
    assert back.names == cap.names and back.rate == pytest.approx(120.0) and back.units == "mm"
    present = ~np.isnan(cap.markers)
    np.testing.assert_allclose(back.markers[present], cap.markers[present], atol=1e-5)
    assert back.gaps == (("c_long", 10, 15),) and back.filled == 3
    # the short gap is a straight line between its neighbours
    np.testing.assert_allclose(back.markers[5, 1], (cap.markers[3, 1] + cap.markers[7, 1]) / 2, atol=1e-4)


def test_fill_gaps_leaves_edges_and_long_gaps():
    m = np.zeros((10, 1, 3), np.float32)
    m[:, 0, 0] = np.arange(10)
    m[0, 0] = np.nan
    m[4:6, 0] = np.nan
    filled, gaps, n = fill_gaps(m, ["x"], max_gap=2)
    assert n == 2 and gaps == [("x", 0, 1)]
    np.testing.assert_allclose(filled[4:6, 0, 0], [4, 5])


def test_malformed_trc_line_is_named(tmp_path):
    path = write_trc(tmp_path / "bad.trc", _capture())
    lines = path.read_text().splitlines()
    cells = lines[8].split("\t")
    cells[4] = "1.2.3"
    lines[8] = "\t".join(cells)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(CaptureError, match=r"bad\.trc: line 9, field 5: expected a number, found '1\.2\.3'"):
        read_capture(path)


def test_trc_units_and_marker_count_checked(tmp_path):
    path = write_trc(tmp_path / "u.trc", _capture())
    text = path.read_text().splitlines()
    text[2] = text[2].replace("\tmm\t", "\tinches\t")
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(CaptureError, match="units must be one of"):
        read_capture(path)


def test_nan_only_marker_is_refused(tmp_path):
    cap = _capture()
    m = np.array(cap.markers)
    m[:, 3] = np.nan
    path = write_csv(tmp_path / "empty.csv", Capture(m, cap.names, 120.0, "mm"))
    with pytest.raises(CaptureError, match=r"marker 'd': has no sample in any frame"):
        read_capture(path)


def test_csv_without_units_and_damaged_c3d(tmp_path):
    path = tmp_path / "nounits.csv"
    path.write_text("frame,time,a_x,a_y,a_z\n1,0.0,1,2,3\n")
    with pytest.raises(CaptureError, match="no '# units: cm' line"):
        read_capture(path)
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(b"\x02P" + b"\x00" * 100)
    with pytest.raises(CaptureError, match=r"bad\.c3d: file: not a readable C3D file"):
        read_capture(bad)


@pytest.mark.data
def test_real_takes_trc_and_c3d_agree():
    trc = read_capture(need_shared("markers", "animface_jaw.trc"))
    c3d = read_capture(need_shared("markers", "animface_jaw.c3d"))
    assert trc.markers.shape == (1590, 41, 3) and trc.units == c3d.units == "cm" and trc.rate == 60.0
    assert trc.names == c3d.names and trc.names[0] == "ForeHead_M"
    np.testing.assert_allclose(trc.markers, c3d.markers, atol=1e-5)


def test_csv_with_a_constant_time_column_is_refused_naming_it(tmp_path):
    path = tmp_path / "still.csv"
    path.write_text("# units: mm\ntime,a_x,a_y,a_z\n0.5,1,2,3\n0.5,1,2,3\n0.5,1,2,4\n", encoding="utf-8")
    with pytest.raises(CaptureError, match=r"still\.csv: time column: cannot give the frame rate"):
        read_capture(path)


def test_csv_that_is_not_utf8_is_refused_naming_file_and_line(tmp_path):
    path = tmp_path / "latin.csv"
    path.write_bytes(b"# units: mm\n# rate: 60\na_x,a_y,a_z\n1,2,3\n1,2,\xe93\n")
    with pytest.raises(CaptureError, match=r"latin\.csv: line 5: not UTF-8 text"):
        read_capture(path)


def test_trc_with_a_repeated_marker_name_says_which(tmp_path):
    cap = _capture("mm")
    path = write_trc(tmp_path / "dup.trc", cap)
    lines = path.read_text(encoding="utf-8").split("\n")
    lines[3] = lines[3].replace("\td\t", "\tb\t")
    path.write_text("\n".join(lines), encoding="utf-8")
    with pytest.raises(CaptureError, match=r"dup\.trc: line 4: marker names must be distinct; repeated: \['b'\]"):
        read_capture(path)


@pytest.mark.parametrize("writer", [write_trc, write_csv])
def test_a_value_beyond_float32_is_refused_by_name_without_a_runtime_warning(tmp_path, writer):
    import warnings

    path = writer(tmp_path / f"huge.{writer.__name__[6:]}", _capture("mm"))
    text = path.read_text(encoding="utf-8")
    lines = text.split("\n")
    row = 8 if writer is write_trc else 4
    cells = lines[row].split("\t" if writer is write_trc else ",")
    cells[-1] = "1e300"
    lines[row] = ("\t" if writer is write_trc else ",").join(cells)
    path.write_text("\n".join(lines), encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(CaptureError, match=r"huge\.\w+: markers: infinite or beyond float32 range \(frame \d+, "
                                               r"marker 'e'\)"):
            read_capture(path)


def test_a_truncated_c3d_is_refused_saying_how_many_frames_it_lost(tmp_path):
    pytest.importorskip("c3d")
    cap = _capture("mm")
    whole = write_c3d(tmp_path / "whole.c3d", cap)
    data = whole.read_bytes()
    frame_bytes = cap.n_markers * 4 * 4  # float C3D: x, y, z, residual per marker
    cut = tmp_path / "cut.c3d"
    cut.write_bytes(data[:len(data) - 10 * frame_bytes])  # about ten frames (the file ends in block padding)
    with pytest.raises(CaptureError, match=r"cut\.c3d: data: the header declares 30 frames but the file holds "
                                           r"(\d+); truncated\?") as caught:
        read_capture(cut)
    assert 15 < int(caught.value.problem.split("holds ")[1].split(";")[0]) < 30
