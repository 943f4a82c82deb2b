"""Live Link Face CSV: columns by header name, timecodes, onto a `_L/_R` rig, errors."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from facepuppet.runtime.mapping.channels import ChannelMap
from facepuppet.runtime.recording.livelinkface_csv import parse_timecode, read_llf_csv
from facepuppet.runtime.recording.replay_source import open_recording

from conftest import need_shared

MYSLATE = ("tracker", "livelinkface_myslate_3.csv")
ALEX = ("tracker", "livelinkface_alex_rom_3.csv")


def _columns(path):
    """Cells of the CSV parsed independently, by header name: {name: list of float}."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return {name: [r[name] for r in rows] for name in rows[0]}


def _weight(frame, name):
    return frame.weights[frame.channels.index(name)]


@pytest.mark.data
def test_myslate_columns_are_taken_by_name_not_position():
    path = need_shared(*MYSLATE)
    frames = read_llf_csv(path)
    cols = _columns(path)
    assert len(frames) == 328
    for name in ("JawOpen", "JawLeft", "JawRight", "MouthLeft", "MouthRight", "EyeBlinkLeft", "TongueOut"):
        expected = np.array(cols[name], dtype=np.float32)
        got = np.array([_weight(f, name) for f in frames])
        np.testing.assert_array_equal(got, expected, err_msg=name)
    # The file's JawRight column is constant 0 and JawLeft is not: a position swap would show.
    jaw_left = np.array([_weight(f, "JawLeft") for f in frames])
    jaw_right = np.array([_weight(f, "JawRight") for f in frames])
    assert np.all(jaw_right == 0) and jaw_left.max() > 0.01
    assert len(frames[0].channels) == 52 and "HeadYaw" not in frames[0].channels
    assert not any("Eye" in c and c.endswith(("Yaw", "Pitch", "Roll")) for c in frames[0].channels)


@pytest.mark.data
def test_myslate_timecodes_become_seconds():
    path = need_shared(*MYSLATE)
    frames = read_llf_csv(path)
    # 00:32:09:07.867 -> 00:32:14:35.066
    first = 32 * 60 + 9 + 7.867 / 60
    last = 32 * 60 + 14 + 35.066 / 60
    assert frames[0].t == 0.0 and frames[0].t_sender == pytest.approx(first, abs=1e-9)
    assert frames[-1].t_sender == pytest.approx(last, abs=1e-9)
    assert frames[-1].t == pytest.approx(last - first, abs=1e-9)
    assert frames[-1].t == pytest.approx(5.45, abs=0.01)
    assert frames[0].number == (32 * 60 + 9) * 60 + 7
    assert all(b.t >= a.t for a, b in zip(frames, frames[1:]))
    # head angles are all 0 in this recording: identity rotation, present
    np.testing.assert_array_equal(frames[0].head_rotation, [0, 0, 0, 1])
    assert frames[0].source == "livelinkface_csv"


@pytest.mark.data
def test_alex_rom_all_rows():
    path = need_shared(*ALEX)
    frames = open_recording(path)  # chosen by its header
    assert len(frames) == 4030
    assert frames[-1].t == pytest.approx(134.38, abs=0.01)
    assert max(float(f.weights.max()) for f in frames) == pytest.approx(1.0033, abs=1e-4)


@pytest.mark.data
def test_onto_an_ict_style_rig_jaw_and_blink_get_the_right_columns():
    path = need_shared(*MYSLATE)
    ict_names = sorted(p.stem for p in need_shared("ict-facekit").glob("*.obj") if p.stem != "generic_neutral_mesh")
    assert "eyeBlink_L" in ict_names and "jawOpen" in ict_names
    frames = read_llf_csv(path)
    cols = _columns(path)
    cmap = ChannelMap.build(frames[0].channels, ict_names)
    rig = np.stack([cmap.apply(f.weights) for f in frames])
    for rig_name, column in (("jawOpen", "JawOpen"), ("eyeBlink_L", "EyeBlinkLeft"), ("eyeBlink_R", "EyeBlinkRight"),
                             ("jawLeft", "JawLeft"), ("mouthRight", "MouthRight"),
                             ("browInnerUp_L", "BrowInnerUp"), ("browInnerUp_R", "BrowInnerUp")):
        np.testing.assert_array_equal(rig[:, ict_names.index(rig_name)],
                                      np.array(cols[column], dtype=np.float32), err_msg=rig_name)
    # reported, not silently dropped: ICT has no tongueOut; no ARKit shape drives cheekRaiser/PupilDilate
    assert cmap.unmatched_source == ("TongueOut",)
    assert set(cmap.undriven_target) == {"cheekRaiser_L", "cheekRaiser_R", "PupilDilate_L", "PupilDilate_R"}


HEADER = "Timecode,BlendShapeCount,JawOpen,EyeBlinkLeft,HeadYaw,HeadPitch,HeadRoll,LeftEyeYaw\n"


def _csv(tmp_path, text, name="take.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_small_file_with_head_pose_and_ignored_eye_columns(tmp_path):
    p = _csv(tmp_path, HEADER + "01:00:00:00.000,61,0.5,0.25,0.3,0,0,0.4\n01:00:00:01.500,61,0.6,0.2,0,0,0,0\n")
    frames = read_llf_csv(p)
    assert frames[0].channels == ("JawOpen", "EyeBlinkLeft")
    assert frames[1].t == pytest.approx(1.5 / 60)
    # yaw 0.3 rad about +y
    np.testing.assert_allclose(frames[0].head_rotation, [0, np.sin(0.15), 0, np.cos(0.15)], atol=1e-7)


@pytest.mark.parametrize(
    "text, match",
    [
        ("Time,BlendShapeCount,JawOpen\n1,61,0\n", r"take.csv, line 1: no 'Timecode' column"),
        (HEADER + "01:00:00:00.000,61,0.5,0.2,0,0,0,0\n01:00:00:01,61,abc,0.2,0,0,0,0\n",
         r"take.csv, line 3, column 'JawOpen': expected a number, found 'abc'"),
        (HEADER + "01:00:00:00.000,61,0.5,0.2,0,0,0,0\n01:00:00,61,0.5,0.2,0,0,0,0\n",
         r"take.csv, line 3, column 'Timecode': expected a timecode"),
        (HEADER + "01:00:00:70.000,61,0.5,0.2,0,0,0,0\n", r"line 2, column 'Timecode': timecode .* out of range"),
        (HEADER + "01:00:00:00.000,61,0.5,0.2,0,0,0\n", r"take.csv, line 2: 7 cells, the header has 8 columns"),
        (HEADER + "01:00:00:05.000,61,0.5,0.2,0,0,0,0\n01:00:00:04.000,61,0.5,0.2,0,0,0,0\n",
         r"take.csv, line 3, column 'Timecode': 01:00:00:04.000 goes back in time"),
        (HEADER, r"take.csv: no data rows"),
    ],
)
def test_malformed_csv_errors_name_file_line_and_column(tmp_path, text, match):
    with pytest.raises(ValueError, match=match):
        read_llf_csv(_csv(tmp_path, text))


def test_timecode_parsing():
    assert parse_timecode("00:00:01:30.000") == (1.5, 90)
    assert parse_timecode("13:13:04:31.652")[0] == pytest.approx(13 * 3600 + 13 * 60 + 4 + 31.652 / 60)
    with pytest.raises(ValueError, match="expected a timecode"):
        parse_timecode("1.5")


def _llf_text(rows: list[str]) -> str:
    return "Timecode,BlendShapeCount,JawOpen,EyeBlinkLeft,HeadYaw,HeadPitch,HeadRoll\n" + "\n".join(rows) + "\n"


def test_a_csv_that_is_not_utf8_is_refused_naming_file_and_line(tmp_path):
    from facepuppet.runtime.errors import InputFileError

    path = tmp_path / "latin.csv"
    path.write_bytes(_llf_text(["10:00:00:00.000,61,0.1,0.2,0,0,0", "10:00:00:01.000,61,0.\xe9,0.2,0,0,0"])
                     .encode("latin-1"))
    with pytest.raises(InputFileError, match=r"latin\.csv, line 3: not UTF-8 text"):
        read_llf_csv(path)


def test_a_1e300_cell_is_counted_once_not_warned_about_by_numpy(tmp_path):
    import warnings

    path = tmp_path / "huge.csv"
    path.write_text(_llf_text([f"10:00:00:{i:02d}.000,61,{'1e300' if i in (2, 4) else '0.5'},0.2,0,0,0"
                               for i in range(6)]), encoding="utf-8")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        frames = read_llf_csv(path)
    said = [str(w.message) for w in caught]
    assert len(said) == 1 and "huge.csv: 2 rows hold NaN, infinite or out-of-range numbers (first at line 4)" in said[0]
    assert not any(issubclass(w.category, RuntimeWarning) for w in caught)
    assert [f.is_finite() for f in frames] == [True, True, False, True, False, True]
