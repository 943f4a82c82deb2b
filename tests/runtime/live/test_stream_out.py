"""``--stream``: MPEG-TS sent over UDP on 127.0.0.1 to a socket bound before the run, decoded back by PyAV:
as many frames as were sent, each the drawn one within the codec's tolerance, at its tick's time; bad URLs
refused before any work (exit 2, naming --stream); ``srt://`` refused where this FFmpeg has no libsrt."""

from __future__ import annotations

import argparse
import dataclasses
import subprocess
import sys
import time

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime.cli import main
from facepuppet.runtime.commands import replay as replay_command
from facepuppet.runtime.live.stream_out import StreamSink, output_protocols, plan_stream

from helpers.live_pictures import Receiver, decode_ts, register_recording_backend, write_take
from helpers.small_characters import sphere_character

av = pytest.importorskip("av", reason="PyAV is not installed: pip install -e '.[video]' (make setup installs it)")

JAWS = [0.1, 0.3, 0.5, 0.7, 0.9, 0.6, 0.4, 0.2]


@pytest.fixture
def receiver():
    r = Receiver()
    yield r
    if not r._stop.is_set():
        r.stop()


def marker(k: int, h: int = 48, w: int = 64) -> np.ndarray:
    """A grey picture with a white bar 8 pixels wide at column 4k, and a colour that changes with k."""
    img = np.full((h, w, 3), (60, 90 + 10 * k, 120), np.uint8)
    img[:, 4 * k: 4 * k + 8] = 255
    return img


def test_the_pictures_offered_are_decoded_back_with_their_marker_and_time(receiver):
    plan = plan_stream(f"udp://127.0.0.1:{receiver.port}", 64, 48, 25.0, (0.0, 0.0, 0.0), False)
    assert plan.url.endswith("?pkt_size=1316")
    sink = StreamSink(plan, 25.0)
    n = 12
    for k in range(n):
        sink.handoff.offer(k, 3.0 + k / 25, time.perf_counter(), marker(k))
        sink.handoff.drain()   # a test's pace: each one sent (a run never waits)
    sink.close()
    frames, times = decode_ts(receiver.stop())
    assert sink.counters["sent"] == n == len(frames) and sink.counters["dropped"] == 0
    np.testing.assert_allclose(times, np.arange(n) / 25, atol=1e-4)
    for k, frame in enumerate(frames):
        columns = frame[:, :, 0].mean(axis=0)
        assert int(np.argmax(columns > 200)) == 4 * k, k        # the bar where it was drawn
        expected = marker(k).astype(float)
        assert np.abs(frame.astype(float) - expected).mean() < 6, k


def test_a_picture_with_alpha_is_streamed_over_the_key_colour(receiver):
    plan = plan_stream(f"udp://127.0.0.1:{receiver.port}", 64, 48, 25.0, (0.0, 0.0, 0.0), True)
    sink = StreamSink(plan, 25.0)
    rgba = np.zeros((48, 64, 4), np.uint8)
    rgba[16:32, 16:48] = (255, 0, 0, 255)
    for k in range(3):
        sink.handoff.offer(k, k / 25, time.perf_counter(), rgba)
        sink.handoff.drain()
    sink.close()
    frames, _ = decode_ts(receiver.stop())
    assert len(frames) == 3
    corner, middle = frames[0][2:10, 2:10].mean(axis=(0, 1)), frames[0][20:28, 24:40].mean(axis=(0, 1))
    np.testing.assert_allclose(corner, (0, 255, 0), atol=12)
    np.testing.assert_allclose(middle, (255, 0, 0), atol=12)


@pytest.mark.gl
def test_a_replay_streams_the_drawn_frames(tmp_path, receiver, capsys):
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    take = tmp_path / "take.csv"
    write_take(take, JAWS)
    code = main(["replay", str(take), "-c", str(character), "--headless", "--size", "64x48", "--fps", "10",
                 "--background", "40,60,200", "--out", str(tmp_path / "frames"),
                 "--stream", f"udp://127.0.0.1:{receiver.port}"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert f"stream: udp://127.0.0.1:{receiver.port}, MPEG-TS H.264" in captured.err
    frames, times = decode_ts(receiver.stop())
    drawn = [np.asarray(Image.open(p)).astype(float) for p in sorted((tmp_path / "frames").glob("frame_*.png"))]
    line = next(x for x in captured.out.splitlines() if x.startswith("replay: streamed"))
    sent, dropped = int(line.split()[2]), int(line.rsplit(" ", 1)[1])
    assert len(drawn) == len(JAWS) == sent + dropped and len(frames) == sent >= 1
    ticks = [float(r.split(",")[2]) for r in (tmp_path / "frames" / "frames.csv").read_text().splitlines()[1:]]
    for frame, t in zip(frames, times):
        i = int(np.argmin([abs(t - (tick - ticks[0])) for tick in ticks]))   # the drawn frame of that time
        assert abs(t - (ticks[i] - ticks[0])) < 1e-3
        assert np.abs(frame.astype(float) - drawn[i]).mean() < 6, i
        np.testing.assert_allclose(frame[1, 1], (40, 60, 200), atol=10)   # the background as drawn


@pytest.mark.parametrize("url, said", [
    ("http://127.0.0.1:8000", "expected udp://HOST:PORT or srt://HOST:PORT, not http://"),
    ("127.0.0.1:5000", "expected udp://HOST:PORT"),
    ("udp://127.0.0.1", "needs a host and a port"),
    ("udp://:5000", "needs a host and a port"),
    ("udp://127.0.0.1:70000", "expected udp://HOST:PORT"),
    ("udp://127.0.0.1:5000/path", "at most a ?key=value query"),
    ("udp://127.0.0.1:5000?listen=1", "it does not listen"),
    ("srt://127.0.0.1:9000?mode=listener", "it does not listen"),
    ("udp://127.0.0.1:5000?a=b;rm", "not a plain key=value"),
])
def test_a_bad_url_is_refused_before_any_work(tmp_path, capsys, url, said):
    take = tmp_path / "take.csv"
    write_take(take, JAWS)
    code = main(["replay", str(take), "-c", str(tmp_path / "absent.npz"), "--headless", "--stream", url])
    err = capsys.readouterr().err
    assert code == 2 and f"--stream {url}" in err and said in err and "Traceback" not in err, err


def test_an_odd_size_is_refused_naming_the_option(tmp_path, capsys):
    take = tmp_path / "take.csv"
    write_take(take, JAWS)
    code = main(["replay", str(take), "-c", str(tmp_path / "absent.npz"), "--headless", "--size", "65x48",
                 "--stream", "udp://127.0.0.1:5000"])
    err = capsys.readouterr().err
    assert code == 2 and "--stream" in err and "even width and height" in err and "--size 66x48" in err, err


def test_srt_is_refused_naming_the_missing_support_where_ffmpeg_has_no_libsrt(tmp_path, capsys):
    protocols = output_protocols()
    assert protocols is not None and "udp" in protocols   # read from the libavformat PyAV loaded
    if "srt" in protocols:
        pytest.skip("this PyAV's FFmpeg has libsrt: srt:// is accepted here")
    take = tmp_path / "take.csv"
    write_take(take, JAWS)
    code = main(["replay", str(take), "-c", str(tmp_path / "absent.npz"), "--headless",
                 "--stream", "srt://127.0.0.1:9000"])
    err = capsys.readouterr().err
    assert code == 2 and "--stream srt://127.0.0.1:9000" in err and "without SRT (libsrt)" in err, err
    assert "udp://HOST:PORT" in err


@pytest.mark.gl
def test_the_camera_and_the_stream_read_each_tick_back_once_between_them(tmp_path, receiver):
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    take = tmp_path / "take.csv"
    write_take(take, JAWS)
    plan = replay_command.ReplayPlan.from_args(_replay_ns([
        str(take), "-c", str(character), "--headless", "--size", "64x48", "--fps", "10",
        "--virtual-camera", "--stream", f"udp://127.0.0.1:{receiver.port}"]))
    plan = dataclasses.replace(plan, outputs=dataclasses.replace(plan.outputs, virtual_camera=dataclasses.replace(
        plan.outputs.virtual_camera, backend=register_recording_backend())))
    result, _ = replay_command.replay(plan)
    frames, _ = decode_ts(receiver.stop())
    camera, stream = result.outputs.virtual_camera, result.outputs.stream
    assert camera.readback is stream.readback and stream.readback.reads == result.loop.n_ticks == len(JAWS)
    assert len(frames) == stream.counters["sent"] >= 1 and camera.counters["sent"] >= 1


def _replay_ns(argv):
    parser = argparse.ArgumentParser(prog="facepuppet")
    replay_command.register(parser.add_subparsers())
    return parser.parse_args(["replay", *argv])


def test_the_command_refuses_a_bad_stream_url_with_exit_2(tmp_path):
    """The real ``facepuppet run``: exit 2, one line naming --stream, nothing opened."""
    done = subprocess.run([sys.executable, "-m", "facepuppet", "run", "-c", str(tmp_path / "absent.npz"),
                           "--input", "vmc", "--headless", "--stream", "rtmp://127.0.0.1/live"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr
    assert "--stream rtmp://127.0.0.1/live: expected udp://HOST:PORT or srt://HOST:PORT, not rtmp://" in done.stderr
    assert "Traceback" not in done.stderr
