"""bench latency --virtual-camera / --stream: the runs with each output report its cost in the loop and in its
thread, what it dropped, and (stream) the latency to a receiver process that decoded it; no speed is asserted."""

from __future__ import annotations

import argparse

import pytest

from facepuppet.runtime.bench.latency import _add_arguments, _phase
from facepuppet.runtime.bench.live_pictures import _viewer_latency, live_picture_phases

from helpers.small_characters import sphere_character

pytest.importorskip("pyvirtualcam", reason="pyvirtualcam is not installed: pip install -e '.[vcam]'")
pytest.importorskip("av", reason="PyAV is not installed: pip install -e '.[video]'")


def test_the_viewer_latency_matches_decoded_frames_to_the_sent_ones_by_pts():
    sent = [(k * 1500, 10.0 + k / 60) for k in range(180)]
    lines = ["garbage", *(f"{k * 1500} {10.0 + k / 60 + 0.040!r}" for k in range(30, 180)), "999 12.0"]
    v = _viewer_latency(lines, sent)
    assert v["decoded"] == 151 and v["matched"] == 150
    settled = v["gpu_to_decoded_ms"]
    # the frames drawn a second after the receiver decoded its first (k = 30, at 10.54 s): k >= 93
    assert settled["n"] == 180 - 93 and abs(settled["p50"] - 40.0) < 1e-6
    assert v["first_second_ms"]["n"] == 93 - 30


@pytest.mark.gl
@pytest.mark.slow
def test_the_picture_runs_report_each_output(tmp_path, capsys):
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    parser = argparse.ArgumentParser()
    _add_arguments(parser)
    args = parser.parse_args(["-c", str(character), "--seconds", "2.5", "--rate", "30", "--pictures-size", "64x48",
                              "--virtual-camera", "--stream", "--receiver", "thread"])
    results: dict = {}
    live_picture_phases(args, results, _phase)
    said = capsys.readouterr().out
    assert "latency bench [pictures --virtual-camera]" in said and "latency bench [pictures --stream]" in said
    camera, stream = results["virtual_camera"]["virtual_camera"], results["stream"]["stream"]
    for output, run in ((camera, results["virtual_camera"]), (stream, results["stream"])):
        assert output["offered"] + output["over_rate"] == run["ticks"] and output["sent"] >= 1
        assert output["offered"] == output["sent"] + output["dropped"]
        assert output["loop_ms"]["n"] == output["offered"] and output["worker_ms"]["n"] == output["sent"]
    assert camera["device"].startswith(("v4l2loopback", "none: pyvirtualcam backend seam"))
    viewer = stream["viewer"]
    assert viewer["matched"] == viewer["decoded"] >= 1   # every frame decoded was one sent, by its pts
    assert results["pictures_baseline"]["ticks"] >= 1
