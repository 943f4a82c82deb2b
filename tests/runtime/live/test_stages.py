"""``run``/``replay`` parameter spaces end to end over real UDP on 127.0.0.1.

Markers -> actor solve -> pair table; kernel-PLS retarget; elastic characters driven by
muscle channels; and a live recording replayed tick for tick to the live run's weights.
"""

from __future__ import annotations

import argparse
import dataclasses
import threading
import time

import numpy as np
import pytest
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.udp_client import SimpleUDPClient

from facepuppet.runtime.actuation.stage import ActorRetarget
from facepuppet.runtime.commands import replay, run
from facepuppet.runtime.elastic.model import ElasticModel
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.kpls.stage import KplsRetarget
from facepuppet.runtime.recording.session import read_session

from helpers.elastic_models import random_model
from helpers.logs import logged
from helpers.marker_senders import marker_sender
from helpers.small_characters import sphere_character
from helpers.udp_helpers import free_udp_port

NO_SMOOTHING = "\n".join(f"[filter.{r}]\nmin_cutoff = 500.0\nbeta = 0.0" for r in ("eyes", "brows", "mouth", "other",
                                                                                  "head")) + \
    "\n[tracking_loss]\ntimeout_s = 30.0\n"


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser()
    sub = p.add_subparsers()
    run.register(sub)
    replay.register(sub)
    return p


def live(argv, send, tmp_path, hooks=()):
    """Run ``run`` with ``argv`` (plus --listen, --headless); ``send(client, stop)`` runs once the socket is bound."""
    port = free_udp_port()
    args = parser().parse_args(["run", *argv, "--listen", f"127.0.0.1:{port}", "--headless", "--size", "48x40"])
    stop = threading.Event()
    threads = []

    def on_ready(address):
        t = threading.Thread(target=send, args=(SimpleUDPClient("127.0.0.1", port), stop), daemon=True)
        t.start()
        threads.append(t)

    logs: list[str] = []
    try:
        with logged(logs):
            result = run.run_live(args, on_ready=on_ready, hooks=hooks, keep_weights=True)
    finally:
        stop.set()
        for t in threads:
            t.join(timeout=10)
    return result, logs


def vmc(client, values: dict) -> None:
    b = OscBundleBuilder(IMMEDIATELY)
    for name, value in values.items():
        m = OscMessageBuilder("/VMC/Ext/Blend/Val")
        m.add_arg(name, "s")
        m.add_arg(float(value), "f")
        b.add_content(m.build())
    b.add_content(OscMessageBuilder("/VMC/Ext/Blend/Apply").build())
    client.send(b.build())


# -- markers: actor solve and pair table ----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def actor_files(tmp_path_factory):
    from facepuppet.offline.actuation.synthetic_capture import synthetic_capture
    from facepuppet.offline.actuation.train import train_actor
    from facepuppet.offline.actuation.transfer import retarget_actor
    from helpers.small_characters import grid_face

    tmp = tmp_path_factory.mktemp("actor")
    cap, truth = synthetic_capture(n_frames=600, n_markers=20, k=3, seed=4)
    actor = train_actor(cap, k=3, head_markers=["M00", "M01", "M02", "M03"]).actor_
    character = grid_face()
    pair = retarget_actor(actor, character)
    paths = {"actor": actor.save(tmp / "actor.npz"), "pair": pair.save(tmp / "pair.npz"),
             "character": character.save(tmp / "grid.npz")}
    return paths, cap, truth, actor, pair


@pytest.mark.gl
@pytest.mark.slow
def test_markers_over_udp_are_solved_and_mapped_through_the_pair(actor_files, tmp_path):
    paths, cap, truth, actor, pair = actor_files
    probe = ActorRetarget(actor, pair)  # a near-neutral frame and the one opening the jaw most
    w_all = np.array([probe.apply(Frame(t=0.0, markers=m.astype(np.float32), marker_names=cap.names))
                      for m in cap.markers])
    poses = [cap.markers[i].astype(np.float32) for i in (np.argmin(w_all.sum(axis=1)), np.argmax(w_all[:, 0]))]
    expected = []
    for pose in poses:  # the same frame over and over: the warm-started solve settles where the live one does
        stage = ActorRetarget(actor, pair)
        frame = Frame(t=0.0, markers=pose, marker_names=cap.names)
        for _ in range(40):
            w = stage.apply(frame)
        expected.append(w)
    assert np.abs(expected[0] - expected[1]).max() > 0.05  # two distinguishable expressions

    send = marker_sender(cap.names, lambda age: poses[0] if age < 0.8 else poses[1])
    config = tmp_path / "fast.toml"
    config.write_text(NO_SMOOTHING)
    dump = tmp_path / "w.npy"
    result, logs = live(["-c", str(paths["character"]), "--input", "markers", "--actor", str(paths["actor"]),
                         "--pair", str(paths["pair"]), "--duration", "1.8", "--config", str(config),
                         "--dump-weights", str(dump)], send, tmp_path)
    w = result.weights.array
    assert any("actor:" in line and "K=3" in line for line in logs)
    assert result.counters["udp"]["malformed"] == 0 and result.loop.counters["frames_received"] > 20
    assert np.abs(w - expected[0]).max(axis=1).min() < 1e-3, "the first pose was never drawn"
    np.testing.assert_allclose(w[-1], expected[1], atol=1e-3)


@pytest.mark.gl
@pytest.mark.slow
def test_markers_in_mm_to_an_actor_in_cm_over_udp(actor_files, tmp_path):
    """Declared mm frames are converted to the actor's cm; undeclared ones are warned about, once."""
    paths, cap, truth, actor, pair = actor_files
    pose = cap.markers[int(np.argmax(np.ptp(cap.markers, axis=(1, 2))))].astype(np.float32)
    stage = ActorRetarget(actor, pair)
    for _ in range(40):
        expected = stage.apply(Frame(t=0.0, markers=pose, marker_names=cap.names))
    config = tmp_path / "fast.toml"
    config.write_text(NO_SMOOTHING)
    base = ["-c", str(paths["character"]), "--input", "markers", "--actor", str(paths["actor"]), "--pair",
            str(paths["pair"]), "--duration", "1.0", "--config", str(config)]
    result, logs = live(base, marker_sender(cap.names, lambda age: pose * 10, units="mm"), tmp_path)
    np.testing.assert_allclose(result.weights.array[-1], expected, atol=1e-3)
    assert not any("other units" in line for line in logs)
    result, logs = live(base, marker_sender(cap.names, lambda age: pose * 10), tmp_path)
    assert sum("are they in other units?" in line for line in logs) == 1
    result, logs = live(base + ["--marker-units", "mm"], marker_sender(cap.names, lambda age: pose * 10), tmp_path)
    np.testing.assert_allclose(result.weights.array[-1], expected, atol=1e-3)


def rotation_deg(q) -> float:
    return float(np.degrees(2 * np.arccos(min(1.0, abs(float(q[3]) / float(np.linalg.norm(q)))))))


@pytest.mark.gl
def test_markers_turn_the_head(actor_files, tmp_path):
    """The Kabsch head pose of the solve is the drawn head rotation (it used to be computed and dropped)."""
    paths, cap, truth, actor, pair = actor_files
    neutral = cap.markers[0].astype(np.float64)
    centre = neutral[actor.head_markers].mean(axis=0)
    a = np.radians(20.0)
    turn = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])  # 20 deg about y
    poses = [neutral.astype(np.float32), ((neutral - centre) @ turn.T + centre).astype(np.float32)]

    stage = ActorRetarget(actor, pair)  # the stage alone: a frame in, the weights and the head's turn out
    out = stage(Frame(t=0.0, markers=poses[1], marker_names=cap.names), 0.0)
    assert out.channels == tuple(pair.shape_names)
    assert rotation_deg(out.head_rotation) == pytest.approx(20.0, abs=0.5)
    assert rotation_deg(stage(Frame(t=0.1, markers=poses[0], marker_names=cap.names), 0.1).head_rotation) < 0.5

    send = marker_sender(cap.names, lambda age: poses[0] if age < 0.6 else poses[1])
    drawn = []
    config = tmp_path / "fast.toml"
    config.write_text(NO_SMOOTHING)
    result, logs = live(["-c", str(paths["character"]), "--input", "markers", "--actor", str(paths["actor"]),
                         "--pair", str(paths["pair"]), "--duration", "1.4", "--config", str(config)], send, tmp_path,
                        hooks=[lambda info: drawn.append(None if info.rotation is None else info.rotation.copy())])
    assert "stages: markers→solve→filter→map→draw" in logs
    angles = [rotation_deg(q) for q in drawn if q is not None]
    assert angles and min(angles) < 1.0, "the neutral pose was never drawn"
    assert angles[-1] == pytest.approx(20.0, abs=1.0), "the head did not turn with the markers"


@pytest.mark.gl
def test_replay_of_a_marker_take_plays_it_through_the_solve(actor_files, tmp_path):
    import dataclasses as dc

    from facepuppet.offline.io import capture_replay
    from facepuppet.offline.io.capture import write_c3d, write_csv, write_trc

    capture_replay.register()                       # as the facepuppet command does when it loads offline
    paths, cap, truth, actor, pair = actor_files     # the actor is in cm
    short = dc.replace(cap, markers=cap.markers[:300])
    in_mm = dc.replace(short, markers=short.markers * 10, units="mm")
    stage = ActorRetarget(actor, pair)              # the reference: the solve stage on every frame in order
    expected = np.array([stage.apply(Frame(t=i / 60, markers=m, marker_names=cap.names))
                         for i, m in enumerate(short.markers)])
    assert np.ptp(expected, axis=0).max() > 0.05    # the take moves the face
    takes = [write_trc(tmp_path / "take.trc", short), write_c3d(tmp_path / "take.c3d", in_mm),
             write_csv(tmp_path / "take.csv", in_mm)]
    for take in takes:
        out = tmp_path / f"{take.suffix[1:]}.npy"
        logs: list[str] = []
        args = parser().parse_args(["replay", str(take), "-c", str(paths["character"]), "--headless", "--size",
                                    "32x32", "--actor", str(paths["actor"]), "--pair", str(paths["pair"]),
                                    "--no-pipeline", "--dump-weights", str(out)])
        with logged(logs):
            assert replay.run_replay(args) == 0
        assert "stages: replay(markers)→solve→map→draw" in logs
        assert any("marker take, 300 frames x 20 markers" in line for line in logs)
        got = np.load(out)
        assert len(got) == 300, take
        np.testing.assert_allclose(got, expected, atol=2e-3, err_msg=str(take))   # mm takes converted to cm
    args = parser().parse_args(["replay", str(takes[0]), "-c", str(paths["character"]), "--headless", "--size",
                                "32x32", "--actor", str(paths["actor"]), "--pair", str(paths["pair"])])
    logs = []
    with logged(logs):
        assert replay.run_replay(args) == 0        # by default as the live markers input: filtered
    assert "stages: replay(markers)→solve→filter→map→draw" in logs
    args = parser().parse_args(["replay", str(takes[0]), "-c", str(paths["character"]), "--headless"])
    with pytest.raises(ValueError, match="--input markers: needs --actor ACTOR.npz and --pair PAIR.npz"):
        replay.run_replay(args)
    renamed = write_trc(tmp_path / "renamed.trc", dc.replace(short, names=tuple(f"Sub1:{n}" for n in short.names)))
    args = parser().parse_args(["replay", str(renamed), "-c", str(paths["character"]), "--headless", "--size",
                                "32x32", "--actor", str(paths["actor"]), "--pair", str(paths["pair"])])
    logs = []
    with pytest.raises(ValueError, match=r"renamed\.trc: the actor's markers are not in this take"):
        with logged(logs):
            replay.run_replay(args)             # refused before drawing a neutral face to its end
    assert any("layout of 20 markers refused" in line for line in logs)


def test_markers_need_an_actor_and_a_pair_that_fit(actor_files, tmp_path):
    paths, *_ = actor_files
    safe = ["--headless", "--duration", "0.2", "--listen", f"127.0.0.1:{free_udp_port()}"]  # should one not raise
    base = ["run", "-c", str(paths["character"]), "--input", "markers", *safe]
    with pytest.raises(ValueError, match="--input markers: needs --actor ACTOR.npz and --pair PAIR.npz"):
        run.run_live(parser().parse_args(base))
    with pytest.raises(ValueError, match="--actor and --pair go together"):
        run.run_live(parser().parse_args(base + ["--actor", str(paths["actor"])]))
    other = dataclasses.replace(sphere_character(), shape_names=("jawOpen", "smile"))
    sphere = other.save(tmp_path / "sphere.npz")
    args = parser().parse_args(["run", "-c", str(sphere), "--input", "markers", *safe,
                                "--actor", str(paths["actor"]), "--pair", str(paths["pair"])])
    with pytest.raises(ValueError, match="--pair .*pair.npz: its shapes \\(2\\) are not the shapes of the character"):
        run.run_live(args)


# -- kernel PLS ----------------------------------------------------------------------------------------------------

@pytest.mark.gl
def test_kpls_retarget_in_the_live_run(tmp_path):
    from helpers.kpls_stages import random_stage as _stage

    character = sphere_character()
    char_path = character.save(tmp_path / "sphere.npz")
    stage = _stage(target=character.shape_names, source=("jawOpen", "mouthSmileLeft"))
    stage.save(tmp_path / "r.npz")
    loaded = KplsRetarget.load(tmp_path / "r.npz")
    expected = loaded.predict_weights([0.6, 0.3])
    assert np.abs(expected - loaded.predict_weights([0.0, 0.0])).max() > 0.01

    def send(client, stop):
        while not stop.is_set():
            vmc(client, {"JawOpen": 0.6, "MouthSmileLeft": 0.3})
            time.sleep(0.01)

    config = tmp_path / "fast.toml"
    config.write_text(NO_SMOOTHING)
    result, logs = live(["-c", str(char_path), "--input", "vmc", "--retarget", str(tmp_path / "r.npz"),
                         "--duration", "1.0", "--config", str(config)], send, tmp_path)
    assert any(line.startswith("retarget:") and "rbf kernel" in line for line in logs)
    np.testing.assert_allclose(result.weights.array[-1], expected, atol=1e-4)


# -- elastic characters and muscles -------------------------------------------------------------------------------

def elastic_with_muscle(character, name="zygomaticMajorL") -> ElasticModel:
    model = random_model(character)
    arrays = dict(model.arrays)
    n_c = model.n_controls
    rng = np.random.default_rng(3)
    arrays.update(muscle_params=(0.3 * rng.standard_normal((1, n_c, 3))).astype(np.float32),
                  muscle_kinds=np.zeros(1, np.uint8), muscle_points=np.zeros((1, 2, 3), np.float32),
                  muscle_ranges=np.array([[0.5, 1.0, 0.5, 1.0]], np.float32))
    return ElasticModel(arrays, model.shape_names, model.control_names, (name,))


@pytest.mark.gl
def test_elastic_character_driven_by_a_muscle_channel_over_vmc(tmp_path):
    character = sphere_character(with_hidden=False)
    char_path = character.save(tmp_path / "sphere.npz")
    elastic_with_muscle(character).save(tmp_path / "e.npz")

    def send(client, stop):
        start = time.monotonic()
        while not stop.is_set():
            vmc(client, {"zygomaticMajorL": 0.0 if time.monotonic() - start < 0.6 else 0.8})
            time.sleep(0.01)

    config = tmp_path / "fast.toml"
    config.write_text(NO_SMOOTHING)
    pngs = tmp_path / "png"
    result, logs = live(["-c", str(char_path), "--input", "vmc", "--elastic", str(tmp_path / "e.npz"),
                         "--duration", "1.4", "--config", str(config), "--out", str(pngs)], send, tmp_path)
    assert result.path == "elastic" and any("1 muscles: zygomaticMajorL" in line for line in logs)
    w = result.weights.array
    assert w.shape[1] == 3  # jawOpen, puff, then the muscle
    assert w[-1, 2] == pytest.approx(0.8, abs=1e-4)
    np.testing.assert_array_equal(w[:, :2], 0.0)
    relaxed = int(np.flatnonzero(np.abs(w[:, 2]) < 1e-6)[-1])
    from PIL import Image

    drawn = sorted(pngs.glob("frame_*.png"))  # one per tick, named by tick label
    assert len(drawn) == len(w)
    still = np.asarray(Image.open(drawn[relaxed]))
    pulled = np.asarray(Image.open(drawn[-1]))
    assert (still != pulled).any(), "the contraction did not move the image"
    assert result.counters["udp"]["unmapped_name"] == 0


def test_elastic_table_must_fit_the_character(tmp_path):
    character = sphere_character(with_hidden=False)
    elastic_with_muscle(character).save(tmp_path / "e.npz")
    other = sphere_character(with_hidden=True).save(tmp_path / "other.npz")
    args = parser().parse_args(["run", "-c", str(other), "--input", "vmc", "--headless", "--duration", "0.2",
                                "--listen", f"127.0.0.1:{free_udp_port()}", "--elastic", str(tmp_path / "e.npz")])
    with pytest.raises(ValueError, match="--elastic .*e.npz: made for \\d+ vertices"):
        run.run_live(args)


# -- a live recording replayed tick for tick -----------------------------------------------------------------------

@pytest.mark.gl
@pytest.mark.slow
def test_replay_of_a_live_recording_draws_the_live_weights(tmp_path):
    character = sphere_character()
    char_path = character.save(tmp_path / "sphere.npz")
    config = tmp_path / "live.toml"  # real smoothing and a tracking-loss timeout that the gap below trips
    config.write_text("[filter.mouth]\nmin_cutoff = 2.0\nbeta = 0.5\n"
                      "[tracking_loss]\ntimeout_s = 0.15\nease_out_s = 0.1\nease_in_s = 0.1\n")

    def send(client, stop):
        start = time.monotonic()
        while not stop.is_set():
            age = time.monotonic() - start
            if not 0.7 < age < 1.0:  # a 0.3 s gap: tracking loss, then blend back
                vmc(client, {"JawOpen": 0.5 + 0.4 * np.sin(7 * age), "EyeBlinkLeft": 0.3})
            time.sleep(0.008)

    record, live_w, replay_w = tmp_path / "take.fps", tmp_path / "live.npy", tmp_path / "replay.npy"
    live_args = ["-c", str(char_path), "--input", "vmc", "--duration", "1.6", "--config", str(config),
                 "--calibrate", "--record", str(record), "--dump-weights", str(live_w)]
    result, _ = live(live_args, send, tmp_path)
    np.save(live_w, result.weights.array)
    session = read_session(record)
    assert len(session.ticks) == result.loop.n_ticks and result.counters["record"]["record_dropped"] == 0
    assert result.counters["pipeline"]["tracking_lost"] >= 1 and result.counters["pipeline"]["calibrations"] == 1

    logs: list[str] = []
    args = parser().parse_args(["replay", str(record), "-c", str(char_path), "--headless", "--size", "48x40",
                                "--config", str(config), "--calibrate", "--dump-weights", str(replay_w)])
    with logged(logs):
        assert replay.run_replay(args) == 0
    assert any("tick for tick" in line for line in logs)
    live_weights, replayed = np.load(live_w), np.load(replay_w)
    assert live_weights.shape == replayed.shape and np.abs(live_weights[:, 0]).max() > 0.1
    np.testing.assert_array_equal(replayed, live_weights)

    raw = parser().parse_args(["replay", str(record), "-c", str(char_path), "--headless", "--size", "48x40",
                               "--no-pipeline", "--dump-weights", str(replay_w)])
    with logged(logs):
        assert replay.run_replay(raw) == 0
    assert np.abs(np.load(replay_w) - live_weights).max() > 1e-3  # without the pipeline: the raw frames
    logs = []
    plain = parser().parse_args(["replay", str(record), "-c", str(char_path), "--headless", "--size", "48x40"])
    with logged(logs):
        assert replay.run_replay(plain) == 0         # the options the live run had are named
    note = next(line for line in logs if "the filter stage runs as in the live run" in line)
    # the recording keeps the config itself (replay uses it), so only --calibrate is left to name
    assert "--calibrate" in note and "--config" not in note
    assert any("the live run's config in force (recorded)" in line for line in logs)


@pytest.mark.gl
@pytest.mark.slow
def test_replay_of_a_live_recording_reproduces_it_by_default(tmp_path):
    char_path = sphere_character().save(tmp_path / "sphere.npz")

    def send(client, stop):
        start = time.monotonic()
        while not stop.is_set():
            age = time.monotonic() - start
            vmc(client, {"JawOpen": 0.5 + 0.4 * np.sin(9 * age), "EyeBlinkLeft": 0.5 + 0.5 * np.sin(23 * age)})
            time.sleep(0.008)

    record, replay_w = tmp_path / "take.fps", tmp_path / "replay.npy"
    result, _ = live(["-c", str(char_path), "--input", "vmc", "--duration", "1.0", "--record", str(record)],
                     send, tmp_path)
    live_weights = result.weights.array              # run always filters (default One Euro settings)
    args = parser().parse_args(["replay", str(record), "-c", str(char_path), "--headless", "--size", "48x40",
                                "--dump-weights", str(replay_w)])
    logs: list[str] = []
    with logged(logs):
        assert replay.run_replay(args) == 0
    assert any("stages: replay(vmc)→filter→map→draw" == line for line in logs)
    assert np.abs(live_weights).max() > 0.1
    np.testing.assert_array_equal(np.load(replay_w), live_weights)
    with pytest.raises(ValueError, match="--no-pipeline: --config and --calibrate configure the filter stage"):
        replay.run_replay(parser().parse_args(["replay", str(record), "-c", str(char_path), "--headless",
                                               "--no-pipeline", "--calibrate"]))


def voice_wav(path, seconds: float = 2.5, rate: int = 16000):
    """A 220 Hz tone switched on and off at 1.5 Hz: a voice level that comes and goes."""
    import wave

    t = np.arange(int(seconds * rate)) / rate
    voice = (0.5 * np.sin(2 * np.pi * 220 * t) * (np.sin(2 * np.pi * 1.5 * t) > 0)).astype(np.float32)
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1), w.setsampwidth(2), w.setframerate(rate)
        w.writeframes((voice * 32767).astype("<i2").tobytes())
    return path


@pytest.mark.gl
@pytest.mark.slow
def test_replay_of_a_live_gestures_run_draws_the_live_weights(tmp_path):
    """``run --gestures`` with a voice recorded, replayed with the same options: the same weights tick for tick."""
    from helpers.gesture_dbs import small_db

    small_db(tmp_path / "gestures.npz")
    character = dataclasses.replace(sphere_character(), shape_names=("jawOpen", "browInnerUp"))  # brows: gestures
    char_path = character.save(tmp_path / "sphere.npz")
    wav = voice_wav(tmp_path / "voice.wav")

    def send(client, stop):
        start = time.monotonic()
        while not stop.is_set():
            vmc(client, {"JawOpen": 0.3 + 0.2 * np.sin(5 * (time.monotonic() - start)), "BrowInnerUp": 0.1})
            time.sleep(0.01)

    record, live_w, replay_w = tmp_path / "take.fps", tmp_path / "live.npy", tmp_path / "replay.npy"
    options = ["--gestures", str(tmp_path / "gestures.npz"), "--gesture-seed", "3"]
    result, logs = live(["-c", str(char_path), "--input", "vmc", "--duration", "1.5", "--audio-file", str(wav),
                         "--record", str(record), *options], send, tmp_path)
    assert "stages: vmc→audio→filter→gestures→map→draw" in logs
    np.save(live_w, result.weights.array)
    session = read_session(record)
    assert len(session.ticks) == result.loop.n_ticks == len(session.audio_levels)
    assert session.header["info"]["options"]["gestures"] == str(tmp_path / "gestures.npz")

    logs = []
    args = parser().parse_args(["replay", str(record), "-c", str(char_path), "--headless", "--size", "48x40",
                                "--pipeline", *options, "--dump-weights", str(replay_w)])
    with logged(logs):
        assert replay.run_replay(args) == 0
    assert "stages: replay(vmc)→audio→filter→gestures→map→draw" in logs
    live_weights, replayed = np.load(live_w), np.load(replay_w)
    assert live_weights.shape == replayed.shape
    assert np.ptp(live_weights, axis=0).max() > 0.05  # the face moved
    np.testing.assert_array_equal(replayed, live_weights)

    other_seed = parser().parse_args(["replay", str(record), "-c", str(char_path), "--headless", "--size", "48x40",
                                      "--pipeline", "--gestures", str(tmp_path / "gestures.npz"), "--gesture-seed",
                                      "4", "--dump-weights", str(replay_w)])
    with logged(logs):
        assert replay.run_replay(other_seed) == 0
    assert np.abs(np.load(replay_w) - live_weights).max() > 1e-3  # the gestures are in what was compared


@pytest.mark.gl
def test_a_voice_only_run_says_it_plays_its_wav_and_listens_on_no_port(tmp_path):
    from helpers.gesture_dbs import small_db

    small_db(tmp_path / "gestures.npz")
    char_path = sphere_character().save(tmp_path / "sphere.npz")
    wav = voice_wav(tmp_path / "voice.wav", seconds=0.5)
    _, logs = live(["-c", str(char_path), "--input", "audio", "--gestures", str(tmp_path / "gestures.npz"),
                    "--audio-file", str(wav)], lambda client, stop: None, tmp_path)
    assert f"run: playing the voice from {wav} (0.50 s, 16000 Hz) on the run's clock" in logs
    assert not [line for line in logs if "listening" in line], logs


@pytest.mark.gl
def test_replay_of_a_voice_only_run_draws_the_live_weights(tmp_path):
    """``run --input audio --gestures`` records ticks and no packets; its replay is the live run, tick for tick."""
    from helpers.gesture_dbs import small_db

    small_db(tmp_path / "gestures.npz")
    char_path = sphere_character().save(tmp_path / "sphere.npz")
    record, replay_w = tmp_path / "voice.fps", tmp_path / "replay.npy"
    result, logs = live(["-c", str(char_path), "--input", "audio", "--gestures", str(tmp_path / "gestures.npz"),
                         "--audio-file", str(voice_wav(tmp_path / "voice.wav", seconds=1.0)), "--record", str(record)],
                        lambda client, stop: None, tmp_path)
    assert "stages: voice→audio→filter→gestures→map→draw" in logs
    live_weights = result.weights.array
    assert np.ptp(live_weights[:, 0]) > 0.05  # the jaw follows the voice
    logs = []
    args = parser().parse_args(["replay", str(record), "-c", str(char_path), "--headless", "--size", "48x40",
                                "--gestures", str(tmp_path / "gestures.npz"), "--dump-weights", str(replay_w)])
    with logged(logs):
        assert replay.run_replay(args) == 0
    assert "stages: replay(audio)→audio→filter→gestures→map→draw" in logs   # the live chain, by default
    np.testing.assert_array_equal(np.load(replay_w), live_weights)
