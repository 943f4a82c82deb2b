"""``--video``: frames and sound encoded through PyAV, read back by decoding with PyAV; refusals before work."""

from __future__ import annotations

import io
import sys
import wave

import numpy as np
import pytest

from facepuppet.runtime.cli import main
from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.live.video_out import AUDIO_RATE, VideoError, VideoSink, plan_video

from helpers.logs import said
from helpers.small_characters import sphere_character

av = pytest.importorskip("av", reason="PyAV is not installed: pip install -e '.[video]' (make setup installs it)")


def write_wav(path, seconds: float, rate: int = 44100, freq: float = 440.0, channels: int = 1) -> np.ndarray:
    n = int(round(seconds * rate))
    tone = 0.4 * np.sin(2 * np.pi * freq * np.arange(n) / rate)
    with wave.open(str(path), "wb") as f:
        f.setnchannels(channels)
        f.setsampwidth(2)
        f.setframerate(rate)
        f.writeframes(np.repeat((tone * 32767).astype("<i2"), channels).tobytes())
    return tone


def pattern(k: int, h: int, w: int, channels: int = 3) -> np.ndarray:
    """A frame that differs from tick to tick: a gradient and a bar at column 2k."""
    img = np.zeros((h, w, channels), np.uint8)
    img[..., 0] = np.linspace(0, 255, w, dtype=np.uint8)[None, :]
    img[..., 1] = (40 + 3 * k) % 256
    img[:, 2 * k % w: 2 * k % w + 6, 2] = 255
    if channels == 4:
        img[..., 3] = np.linspace(0, 255, h, dtype=np.uint8)[:, None]
    return img


def decode(path, alpha: bool = False):
    """(frames as arrays, their times in s, {stream type: duration s}) of a file, decoded by PyAV."""
    with av.open(str(path)) as container:
        durations = {}
        for s in container.streams:
            if s.duration is not None:
                durations[s.type] = float(s.duration * s.time_base)
        stream = container.streams.video[0]
        if alpha and stream.codec_context.name == "vp9":  # FFmpeg's own VP9 decoder drops the alpha plane
            decoder = av.CodecContext.create("libvpx-vp9", "r")
            frames = [f for p in container.demux(stream) for f in decoder.decode(p)]  # the last packet flushes
        else:
            frames = list(container.decode(video=0))
        images = [f.to_ndarray(format="rgba" if alpha else "rgb24") for f in frames]
        times = [float(f.pts * f.time_base) for f in frames] if not (alpha and stream.codec_context.name == "vp9") \
            else [float(f.pts * stream.time_base) for f in frames]
        if not durations or "audio" not in durations:
            durations.update(_packet_durations(path))
    return images, times, durations


def _packet_durations(path) -> dict:
    """Each stream's end time from its packets (Matroska/WebM keep no per-stream duration)."""
    out = {}
    with av.open(str(path)) as container:
        for packet in container.demux():
            if packet.pts is None or packet.duration is None:
                continue
            end = float((packet.pts + packet.duration) * packet.time_base)
            out[packet.stream.type] = max(out.get(packet.stream.type, 0.0), end)
    return out


def audio_samples(path) -> np.ndarray:
    with av.open(str(path)) as container:
        return np.concatenate([f.to_ndarray().reshape(-1) for f in container.decode(audio=0)])


# -- the sink on synthetic frames ------------------------------------------------------------------------------


def test_h264_mp4_one_frame_per_tick_at_the_tick_times_with_sound(tmp_path):
    wav = tmp_path / "tone.wav"
    write_wav(wav, 3.0)  # longer than the video: cut to it
    plan = plan_video(tmp_path / "out.mp4", 64, 48, audio_file=wav)
    assert (plan.codec, plan.pix_fmt, plan.audio_codec) == ("libx264", "yuv420p", "aac")
    sink = VideoSink(plan, 30.0)
    sent = [pattern(k, 48, 64) for k in range(40)]
    for k, img in enumerate(sent):
        sink.write(k, img)
    sink.close()
    images, times, durations = decode(tmp_path / "out.mp4")
    assert len(images) == 40 == sink.frames
    np.testing.assert_allclose(times, np.arange(40) / 30, atol=1e-9)
    # lossy, but the picture is the one given (mean error a few levels of 255)
    assert max(float(np.abs(a.astype(int) - b.astype(int)).mean()) for a, b in zip(images, sent)) < 4
    assert durations["video"] == pytest.approx(40 / 30)
    assert abs(durations["audio"] - durations["video"]) <= 1 / 30
    sound = audio_samples(tmp_path / "out.mp4")
    rms = float(np.sqrt(np.mean(sound[AUDIO_RATE // 10: AUDIO_RATE] ** 2)))
    assert rms == pytest.approx(0.4 / np.sqrt(2), rel=0.05)  # the tone is in it


def test_a_short_wav_is_padded_with_silence_to_the_video(tmp_path):
    wav = tmp_path / "short.wav"
    write_wav(wav, 0.5, rate=48000)
    sink = VideoSink(plan_video(tmp_path / "out.mkv", 32, 32, audio_file=wav), 25.0)
    for k in range(50):  # 2 s
        sink.write(k, pattern(k, 32, 32))
    sink.close()
    images, _, durations = decode(tmp_path / "out.mkv")
    assert len(images) == 50
    assert abs(durations["audio"] - 2.0) <= 1 / 25 and abs(durations["video"] - 2.0) <= 1 / 25
    sound = audio_samples(tmp_path / "out.mkv")
    assert np.abs(sound[int(0.7 * AUDIO_RATE):]).max() < 1e-3  # silence after the WAV's end
    assert np.abs(sound[: int(0.4 * AUDIO_RATE)]).max() > 0.3


def test_ticks_with_gaps_keep_their_times(tmp_path):
    """A run drawing on arrival labels its ticks on a 1 kHz grid: each frame at its own tick's time."""
    ticks = [7, 23, 40, 41, 90, 150]
    sink = VideoSink(plan_video(tmp_path / "vfr.mp4", 32, 32), 1000.0)
    for k in ticks:
        sink.write(k, pattern(k, 32, 32))
    sink.close()
    images, times, _ = decode(tmp_path / "vfr.mp4")
    assert len(images) == len(ticks)
    np.testing.assert_allclose(times, (np.array(ticks) - ticks[0]) / 1000, atol=1e-9)
    assert sink.duration == pytest.approx((150 - 7 + 1) / 1000)


@pytest.mark.parametrize("suffix, codec, exact", [(".mov", "prores_ks", 2), (".webm", "libvpx-vp9", 12)])
def test_frames_with_alpha_get_an_alpha_codec(tmp_path, suffix, codec, exact):
    """(h, w, 4) frames: ProRes 4444 in .mov, VP9 yuva420p in .webm; the alpha plane comes back."""
    plan = plan_video(tmp_path / f"alpha{suffix}", 64, 48, alpha=True)
    assert plan.alpha_codec == codec
    sink = VideoSink(plan, 30.0)
    sent = [pattern(k, 48, 64, channels=4) for k in range(12)]
    for k, img in enumerate(sent):
        sink.write(k, img)
    sink.close()
    images, _, _ = decode(tmp_path / f"alpha{suffix}", alpha=True)
    assert len(images) == 12
    for got, want in zip(images, sent):
        assert got.shape == (48, 64, 4)
        assert float(np.abs(got[..., 3].astype(int) - want[..., 3].astype(int)).mean()) <= exact


def test_alpha_frames_into_mp4_are_refused(tmp_path):
    with pytest.raises(VideoError, match=r"the frames carry alpha and libx264 in \.mp4 carries no alpha; name a "
                                         r"\.webm \(VP9\) or \.mov"):
        plan_video(tmp_path / "a.mp4", 64, 48, alpha=True)
    sink = VideoSink(plan_video(tmp_path / "b.mp4", 64, 48), 30.0)  # alpha not announced: refused at the frame
    with pytest.raises(VideoError, match="the frames carry alpha"):
        sink.write(0, pattern(0, 48, 64, channels=4))
    sink.abort()
    assert not any(tmp_path.iterdir())


def test_bad_frames_and_order_are_refused(tmp_path):
    sink = VideoSink(plan_video(tmp_path / "o.mp4", 32, 32), 30.0)
    with pytest.raises(VideoError, match=r"expected frames of \(32, 32, 3\) or \(32, 32, 4\) uint8, got \(32, 30, 3\)"):
        sink.write(0, np.zeros((32, 30, 3), np.uint8))
    sink.write(0, pattern(0, 32, 32))
    with pytest.raises(VideoError, match="tick 0 comes after tick 0"):
        sink.write(0, pattern(0, 32, 32))
    with pytest.raises(VideoError, match="changed from 3 to 4 channels"):
        sink.write(1, pattern(1, 32, 32, channels=4))
    sink.close()
    assert len(decode(tmp_path / "o.mp4")[0]) == 1


def test_abort_and_an_empty_run_leave_no_file(tmp_path):
    sink = VideoSink(plan_video(tmp_path / "a.mp4", 32, 32), 30.0)
    sink.write(0, pattern(0, 32, 32))
    sink.abort()
    empty = VideoSink(plan_video(tmp_path / "b.mp4", 32, 32), 30.0)
    empty.close()
    assert not any(tmp_path.iterdir())  # nor a temporary file


def test_progress_counts_the_frames():
    stream = io.StringIO()
    clock = iter(np.arange(0, 100, 1.0))
    progress = Progress("demo --video x.mp4", total=5, unit="frames", stream=stream, enabled=True, interval_s=0,
                        clock=lambda: float(next(clock)))
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        sink = VideoSink(plan_video(Path(d) / "p.mp4", 32, 32), 30.0, progress=progress)
        for k in range(5):
            sink.write(k, pattern(k, 32, 32))
        sink.close()
    assert "demo --video x.mp4: 5/5 frames (100%)" in stream.getvalue()


# -- refused before any work -------------------------------------------------------------------------------------


@pytest.mark.parametrize("name, size, codec, match", [
    ("out.avi", (64, 48), None, r"--video .*out\.avi: unknown container '\.avi'; name a \.mp4, \.mkv, \.mov, \.webm"),
    ("out", (64, 48), None, r"unknown container '\(no suffix\)'"),
    ("out.mp4", (64, 48), "nosuchcodec", r"--video-codec nosuchcodec: FFmpeg .* has no encoder of that name"),
    ("out.mp4", (64, 48), "aac", r"--video-codec aac: is a audio encoder, not a video one"),
    ("out.mp4", (65, 48), None, r"libx264 yuv420p needs an even width and height, got --size 65x48; try --size 66x48"),
    ("out.webm", (64, 48), "libx264", r"FFmpeg cannot write libx264 yuv420p 64x48 into webm"),
])
def test_plan_refuses_what_cannot_be_written(tmp_path, name, size, codec, match):
    with pytest.raises(VideoError, match=match):
        plan_video(tmp_path / name, *size, codec=codec)
    assert not any(tmp_path.iterdir())


def test_without_pyav_the_message_says_how_to_install_it(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "av", None)  # import av now raises ImportError
    with pytest.raises(VideoError, match=r"--video: needs PyAV, which is not installed: "
                                         r"pip install 'facepuppet\[video\]'"):
        plan_video(tmp_path / "x.mp4", 64, 48)


def test_a_bad_wav_is_refused_naming_it(tmp_path):
    bad = tmp_path / "not.wav"
    bad.write_bytes(b"RIFF0000WAVEjunk")
    with pytest.raises(ValueError, match="not.wav"):
        plan_video(tmp_path / "x.mp4", 64, 48, audio_file=bad)


@pytest.fixture(scope="module")
def character(tmp_path_factory):
    path = tmp_path_factory.mktemp("video") / "sphere.npz"
    sphere_character().save(path)
    return path


@pytest.mark.parametrize("extra, match", [
    (["--video-codec", "nosuchcodec"], "--video-codec nosuchcodec: FFmpeg"),
    (["--size", "63x48"], "needs an even width and height, got --size 63x48"),
    (["--audio-file", "/nonexistent/a.wav"], "/nonexistent/a.wav"),
])
@pytest.mark.parametrize("command", ["run", "replay", "demo"])
def test_commands_refuse_before_any_work(character, tmp_path, capsys, command, extra, match):
    argv = {"run": ["run", "-c", str(character), "--input", "vmc", "--headless", "--duration", "0.1"],
            "replay": ["replay", str(tmp_path / "missing.csv"), "-c", str(character), "--headless"],
            "demo": ["demo", "--headless", "--out", str(tmp_path / "demo")]}[command]
    if command == "demo" and extra[0] == "--size":
        extra = ["--size", "63x48"]
    code = main([*argv, "--video", str(tmp_path / "v.mp4"), *extra])
    assert code == 2
    assert match in capsys.readouterr().err
    assert not (tmp_path / "v.mp4").exists() and not (tmp_path / "demo").exists()


@pytest.mark.parametrize("command", ["run", "replay", "demo"])
def test_an_existing_video_is_refused_without_force_and_a_stray_codec_too(character, tmp_path, capsys, command):
    existing = tmp_path / "v.mp4"
    existing.write_bytes(b"keep me")
    argv = {"run": ["run", "-c", str(character), "--input", "vmc", "--headless", "--duration", "0.1"],
            "replay": ["replay", str(tmp_path / "missing.csv"), "-c", str(character), "--headless"],
            "demo": ["demo", "--headless", "--out", str(tmp_path / "demo")]}[command]
    assert main([*argv, "--video", str(existing)]) == 2
    assert "--video" in (err := capsys.readouterr().err) and "exists; pass --force" in err
    assert existing.read_bytes() == b"keep me"
    assert main([*argv, "--video", str(tmp_path / "nodir" / "v.mp4")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main([*argv, "--video-codec", "libx264"]) == 2
    assert "--video-codec: needs --video FILE" in capsys.readouterr().err


def test_audio_file_without_video_is_refused_in_replay_and_demo(character, tmp_path, capsys):
    wav = tmp_path / "a.wav"
    write_wav(wav, 0.2)
    assert main(["replay", str(tmp_path / "x.csv"), "-c", str(character), "--headless", "--audio-file",
                 str(wav)]) == 2
    assert "--audio-file: in a replay it is the sound track of --video FILE" in capsys.readouterr().err
    assert main(["demo", "--headless", "--out", str(tmp_path / "d"), "--audio-file", str(wav)]) == 2
    assert "--audio-file: in the demo it is the sound track of --video FILE" in capsys.readouterr().err



# -- the commands, end to end (EGL) ------------------------------------------------------------------------------


def llf_take(path, seconds: float = 1.0) -> None:
    """A Live Link Face CSV take: the jaw opens and closes over ``seconds`` (60 rows a second)."""
    from facepuppet.runtime.mapping.channels import ARKIT_NAMES, pascal

    rows = ["Timecode,BlendShapeCount," + ",".join(pascal(n) for n in ARKIT_NAMES)]
    for i in range(int(seconds * 60)):
        values = ["0"] * 52
        values[17] = f"{0.5 - 0.5 * np.cos(2 * np.pi * i / 60):.4f}"
        rows.append(f"00:00:{i // 60:02d}:{i % 60:02d}.000,52," + ",".join(values))
    path.write_text("\n".join(rows) + "\n")


@pytest.mark.gl
def test_replay_to_video_is_deterministic_one_frame_per_tick_with_sound(character, tmp_path, capsys):
    take = tmp_path / "take.csv"
    llf_take(take)
    wav = tmp_path / "voice.wav"
    write_wav(wav, 2.0)
    decoded = []
    for run in ("a", "b"):
        video, weights = tmp_path / f"{run}.mp4", tmp_path / f"{run}.npy"
        code = main(["replay", str(take), "-c", str(character), "--headless", "--size", "96x64", "--fps", "30",
                     "--video", str(video), "--audio-file", str(wav), "--dump-weights", str(weights)])
        out = said(capsys)
        assert code == 0, out
        assert "video: " in out and "libx264 yuv420p" in out and f"wrote {len(np.load(weights))} video frames" in out
        decoded.append((decode(video), len(np.load(weights))))
    (images_a, times_a, durations_a), ticks = decoded[0]
    (images_b, _, _), _ = decoded[1]
    assert len(images_a) == ticks == 31  # 1 s at 30 fps: ticks 0..30
    np.testing.assert_allclose(times_a, np.arange(ticks) / 30, atol=1e-9)
    assert all(np.array_equal(a, b) for a, b in zip(images_a, images_b, strict=True))  # frame for frame
    assert not np.array_equal(images_a[0], images_a[15])  # the jaw moved
    assert abs(durations_a["audio"] - durations_a["video"]) <= 1 / 30


@pytest.mark.gl
def test_demo_video_has_every_tick(tmp_path, capsys):
    wav = tmp_path / "voice.wav"
    write_wav(wav, 0.5, rate=22050)
    video = tmp_path / "demo.webm"
    code = main(["demo", "--headless", "--no-frames", "--out", str(tmp_path / "d"), "--size", "64x48",
                 "--duration", "1", "--fps", "20", "--video", str(video), "--audio-file", str(wav)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "demo: 21 video frames (1.05 s)" in out
    images, times, durations = decode(video)
    assert len(images) == 21
    assert abs(durations["audio"] - durations["video"]) <= 1 / 20


@pytest.mark.gl
@pytest.mark.parametrize("draw", ["tick", "arrival"])
def test_run_video_frames_are_the_ticks_and_the_audio_file_is_the_sound(character, tmp_path, capsys, draw):
    """``--draw tick`` gives a constant 20 fps; on arrival (idle redraws at 20 fps, labels on a 1 kHz grid)
    each frame sits at its own tick's millisecond."""
    import re

    from helpers.udp_helpers import free_udp_port

    wav = tmp_path / "voice.wav"
    write_wav(wav, 1.0, rate=48000)
    video = tmp_path / "live.mov"
    code = main(["run", "-c", str(character), "--input", "vmc", "--listen", f"127.0.0.1:{free_udp_port()}",
                 "--headless", "--duration", "0.5", "--size", "64x48", "--draw", draw, "--fps", "20",
                 "--video", str(video), "--audio-file", str(wav)])
    out = capsys.readouterr().out
    assert code == 0, out
    n_ticks = int(re.search(r"run: (\d+) ticks", out).group(1))
    assert f"run: wrote {n_ticks} video frames to {video}" in out
    images, times, durations = decode(video)
    assert len(images) == n_ticks >= 2
    grid = 20 if draw == "tick" else 1000
    np.testing.assert_allclose(np.array(times) * grid, np.round(np.array(times) * grid), atol=1e-6)
    if draw == "tick":
        # each frame at its own tick's time, in order; a live run late for a tick skips it rather than fall
        # behind (a loaded machine), so every tick up to the last is either drawn or counted as skipped
        k = np.round(np.array(times) * 20).astype(int)
        np.testing.assert_allclose(times, k / 20, atol=1e-9)
        skipped = int(re.search(r"late ticks \d+ \(skipped (\d+)\)", out).group(1))
        assert k[0] == 0 and list(k) == sorted(set(k)) and k[-1] + 1 == n_ticks + skipped
    assert abs(durations["audio"] - durations["video"]) <= 1 / 20


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.gl
def test_replay_of_a_live_run_drawn_on_arrival_keeps_its_tick_times_and_counts_ticks(character, tmp_path,
                                                                                      capsys, monkeypatch):
    """A live recording drawn on arrival has tick labels on a 1 kHz grid: the replay's video puts each frame at
    its label, and the progress line counts ticks drawn (it used to show the label: '501/11 ticks')."""
    import re

    from helpers.udp_helpers import free_udp_port

    record = tmp_path / "live.fps"
    assert main(["run", "-c", str(character), "--input", "vmc", "--listen", f"127.0.0.1:{free_udp_port()}",
                 "--headless", "--duration", "0.5", "--size", "32x32", "--fps", "20", "--record", str(record)]) == 0
    capsys.readouterr()
    err = _Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    video = tmp_path / "replay.mp4"
    assert main(["replay", str(record), "-c", str(character), "--headless", "--size", "32x32",
                 "--video", str(video)]) == 0
    out = capsys.readouterr().out
    n_ticks = int(re.search(r"replay: (\d+) ticks", out).group(1))
    assert n_ticks >= 2 and f"{n_ticks}/{n_ticks} ticks (100%)" in err.getvalue()
    done = [int(m) for m in re.findall(r"(\d+)/\d+ ticks", err.getvalue())]
    assert max(done) == n_ticks
    images, times, _ = decode(video)
    assert len(images) == n_ticks
    steps = np.diff(np.array(times) * 1000)
    assert np.all(steps >= 1 - 1e-6) and steps.max() > 1.5  # labels in ms, not one frame per millisecond


@pytest.mark.parametrize("suffix, channels", [(".mp4", 3), (".webm", 3), (".webm", 4), (".mov", 4)])
def test_the_same_frames_give_the_same_decoded_frames(tmp_path, suffix, channels):
    """Every codec's output depends on the frames only (encoder threads included), however often it runs in one
    process (x264's macroblock-tree rate control did not: it changed with what the process did before)."""
    decoded = []
    for run in "abcdef":
        sink = VideoSink(plan_video(tmp_path / f"{run}{suffix}", 96, 64), 30.0)
        for k in range(20):
            sink.write(k, pattern(k, 64, 96, channels))
        sink.close()
        decoded.append(decode(tmp_path / f"{run}{suffix}", alpha=channels == 4)[0])
        decode(tmp_path / f"a{suffix}", alpha=channels == 4)  # what a process does in between counts
    assert len(decoded[0]) == 20
    for other in decoded[1:]:
        assert all(np.array_equal(a, b) for a, b in zip(decoded[0], other, strict=True))
