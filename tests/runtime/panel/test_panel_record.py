"""Record and Stop in the panel of a real run (headless, VMC over real UDP on 127.0.0.1, clicks through ImGui's IO):
each recording is a complete file that ``replay`` plays back to the weights the run drew while it recorded."""

from __future__ import annotations

import argparse
import threading
import time

import numpy as np
import pytest
from pythonosc.udp_client import SimpleUDPClient

from facepuppet.runtime.cli import main
from facepuppet.runtime.commands import run
from facepuppet.runtime.recording.session import read_session
from facepuppet.runtime.session import recording_feed

from helpers.logs import logged
from helpers.small_characters import sphere_character
from helpers.udp_helpers import free_udp_port
from helpers.vmc_run import NO_SMOOTHING, send_vmc

pytest.importorskip("imgui_bundle", reason="the panel's extra (imgui-bundle) is not installed")

pytestmark = pytest.mark.gl

TICKS_RECORDED = 12  # ticks with a new frame in each recording before Stop is clicked


class _Operator:
    """The test's hand on the mouse: one step per tick, from the frame loop's tick hook (so it is in step with
    the panel's frames whatever the machine's speed)."""

    def __init__(self, stop: threading.Event):
        self.stop = stop
        self.panel = None
        self.plan: list = []  # (what, label) steps
        self.pressed = None
        self.live: dict[int, np.ndarray] = {}  # tick index -> rig weights drawn, while a recording was in force
        self.sizes: list[tuple[int, int]] = []  # (recording number, size shown) while recording
        self.files: list = []
        self.with_frames = 0
        self.quiet = threading.Event()  # set: the tracker sends nothing

    def click(self, label):
        x0, y0, x1, y1 = self.panel.rects[label]
        x, y = (x0 + x1) / 2, (y0 + y1) / 2
        self.panel.io.add_mouse_pos_event(float(x), float(y))
        self.panel.io.add_mouse_button_event(0, True)
        self.pressed = (x, y)

    def release(self):
        self.panel.io.add_mouse_button_event(0, False)
        self.pressed = None

    def _grew(self, n):
        """The size shown for recording ``n`` has changed since it was first shown (refreshed twice a second)."""
        sizes = [s for i, s in self.sizes if i == n]
        return len(sizes) >= 2 and sizes[-1] != sizes[0]

    def __call__(self, info):
        rec = self.panel.recorder
        if rec.recording:
            self.live[info.k] = info.weights.copy()
            shown = self.panel._status.get("record")
            if shown is not None and shown[1] is not None and shown[0] == str(rec.path):
                self.sizes.append((rec.recordings, shown[1]))
            if info.raw is not None:
                self.with_frames += 1
        if self.pressed is not None:
            self.release()
            return
        if not self.plan:
            self.stop.set()
            return
        what = self.plan[0]
        if what == "start" and "record.start" in self.panel.rects and not rec.recording:
            self.click("record.start")
            self.plan.pop(0)
            self.with_frames = 0
        elif what == "stop" and rec.recording and self.with_frames >= TICKS_RECORDED and self._grew(rec.recordings) \
                and "record.stop" in self.panel.rects:
            self.files.append(rec.path)
            self.click("record.stop")
            self.plan.pop(0)
        elif what == "wait":
            self.plan.pop(0)
        elif what == "halt" and rec.recording and "record.stop" in self.panel.rects:  # stop, frames or not
            self.files.append(rec.path)
            self.click("record.stop")
            self.plan.pop(0)
        elif what == "quiet":
            self.quiet.set()
            self.plan.pop(0)
        elif what == "loud":
            self.quiet.clear()
            self.plan.pop(0)
        elif what == "lost" and self.panel.pipeline.tracking_state == "lost":
            self.plan.pop(0)


def _run(tmp_path, extra=(), config_text=NO_SMOOTHING, plan=None):
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    config = tmp_path / "live.toml"
    config.write_text(config_text)
    port = free_udp_port()
    parser = argparse.ArgumentParser()
    run.register(parser.add_subparsers())
    ns = parser.parse_args(["run", "-c", str(character), "--input", "vmc", "--listen", f"127.0.0.1:{port}",
                            "--headless", "--panel", "--size", "640x1000", "--duration", "60", "--config",
                            str(config), "--draw", "tick", "--fps", "30", *extra])
    stop = threading.Event()
    op = _Operator(stop)
    op.plan = plan or ["wait"] * 5 + ["start", "stop"] + ["wait"] * 5 + ["start", "stop"] + ["wait"] * 3

    def on_ready(address):
        def send():
            client = SimpleUDPClient("127.0.0.1", port)
            i = 0
            while not stop.is_set():  # every frame its own jaw value: a replay taking another frame shows it
                if not op.quiet.is_set():
                    send_vmc(client, {"JawOpen": 0.05 + 0.9 * ((i * 7) % 97) / 97})
                    i += 1
                time.sleep(0.011)
        threading.Thread(target=send, daemon=True).start()

    try:
        result = run.run_live(ns, stop_event=stop, on_ready=on_ready, hooks=[op],
                              on_panel=lambda p: setattr(op, "panel", p))
    finally:
        stop.set()
    return result, op, character, config


@pytest.mark.slow
@pytest.mark.parametrize("receiver", ["process", "thread"])  # datagrams recorded from a ring, or as they arrive
def test_record_then_stop_in_the_panel_twice_makes_two_files_that_replay_the_run(tmp_path, monkeypatch, receiver):
    monkeypatch.chdir(tmp_path)  # recordings named by default go into the current folder
    result, op, character, config = _run(tmp_path, ("--receiver", receiver))
    assert not op.plan, f"the run ended before the clicks were done: {op.plan}"
    assert len(op.files) == 2 and op.files[0] != op.files[1]
    for path in op.files:
        assert path.parent == tmp_path and path.name.startswith("facepuppet-") and path.suffix == ".fps"
    assert result.counters["record"]["recordings"] == 2
    assert result.counters["record"]["record_dropped"] == 0
    # the size shown grew while each recording went on
    for n in (1, 2):
        sizes = [s for i, s in op.sizes if i == n]
        assert len(sizes) >= 2 and sizes[-1] > sizes[0], (n, sizes)

    for n, path in enumerate(op.files):
        session = read_session(path)
        assert session.complete, session.tail_error
        info = session.header["info"]
        assert info["input"] == "vmc" and info["started_at_t"] > 0
        assert "min_cutoff = 500.0" in info["config"]  # the config in force, in the header...
        assert session.configs and "min_cutoff = 500.0" in session.configs[0][1]  # ... and as the first CONFIG
        assert session.packets and session.ticks
        ticks = [t.k for t in session.ticks]
        assert set(ticks) <= set(op.live)
        # replay it (its own header: the config, the character's path, the fps) and compare with the run
        dump = tmp_path / f"replay{n}.npy"
        assert main(["replay", str(path), "-c", str(character), "--headless", "--size", "64x64",
                     "--dump-weights", str(dump)]) == 0
        replayed = np.load(dump)
        assert replayed.shape[0] == len(ticks)
        live = np.array([op.live[k] for k in ticks])
        drawn = np.flatnonzero(np.abs(replayed).sum(axis=1) > 0)
        assert drawn.size >= TICKS_RECORDED - 2  # the ticks before the first recorded frame draw the rest pose
        first = drawn[0]
        # from the first recorded frame on (the filter stage's state then is the recording's STATE) the replay
        # draws what the run drew, tick for tick
        assert len(session.states) == 1
        later = np.arange(first, len(ticks))
        assert later.size >= 5
        np.testing.assert_allclose(replayed[later], live[later], atol=1e-6)
    # the two recordings hold different stretches of the run: nothing of the first is in the second
    a, b = (read_session(p) for p in op.files)
    assert max(t.k for t in a.ticks) < min(t.k for t in b.ticks)


@pytest.mark.parametrize("receiver", ["process", "thread"])
def test_a_recording_started_mid_run_replays_the_smoothed_run_exactly_from_its_first_frame(tmp_path, monkeypatch,
                                                                                           receiver):
    """With the filters smoothing (the mouth at 1 Hz: each frame moves the jaw a few per cent of the way), a
    replay that started them afresh at the recording's first frame drew something else for a second or more.
    The recording keeps the filter stage's state before the tick of its first recorded frame (a STATE record)
    and the replay goes on from it: from that frame on it draws what the run drew."""
    monkeypatch.chdir(tmp_path)
    smooth = "[filter.mouth]\nmin_cutoff = 1.0\nbeta = 0.0\n"
    result, op, character, config = _run(tmp_path, ("--receiver", receiver), smooth,
                                         plan=["wait"] * 20 + ["start", "stop"] + ["wait"] * 3)
    assert not op.plan and len(op.files) == 1
    session = read_session(op.files[0])
    assert len(session.states) == 1
    ticks = [t.k for t in session.ticks]
    lines: list[str] = []
    dump = tmp_path / "replay.npy"
    from facepuppet.runtime.commands import replay
    ns = argparse.ArgumentParser()
    replay.register(ns.add_subparsers())
    args = ns.parse_args(["replay", str(op.files[0]), "-c", str(character), "--headless", "--size", "64x64",
                          "--dump-weights", str(dump)])
    with logged(lines):
        assert replay.run_replay(args) == 0
    assert any("goes on from its state at the recording's start" in line for line in lines), lines
    replayed = np.load(dump)
    live = np.array([op.live[k] for k in ticks])
    drawn = np.flatnonzero(np.abs(replayed).sum(axis=1) > 0)
    first = drawn[0]
    assert len(ticks) - first >= TICKS_RECORDED - 2
    np.testing.assert_allclose(replayed[first:], live[first:], atol=1e-6)
    # without it the replay starts the filters afresh: the first frame passes unsmoothed (the raw frame, as
    # --no-pipeline draws it), so the replay is off the run wherever the run's smoothed jaw was off the raw one
    raw = tmp_path / "raw.npy"
    args = ns.parse_args(["replay", str(op.files[0]), "-c", str(character), "--headless", "--size", "64x64",
                          "--no-pipeline", "--dump-weights", str(raw)])
    assert replay.run_replay(args) == 0
    raw = np.load(raw)
    monkeypatch.setattr(recording_feed, "restore_state", lambda *a, **k: None)
    fresh = tmp_path / "fresh.npy"
    args = ns.parse_args(["replay", str(op.files[0]), "-c", str(character), "--headless", "--size", "64x64",
                          "--dump-weights", str(fresh)])
    assert replay.run_replay(args) == 0
    fresh = np.load(fresh)
    np.testing.assert_allclose(fresh[first], raw[first], atol=1e-6)
    # (a load stall at the recording's start can leave the run's filter at the raw value: nothing to tell apart)
    if np.abs(raw[first] - live[first]).max() > 0.02:
        assert np.abs(fresh[first:] - live[first:]).max() > 0.02


@pytest.mark.parametrize("receiver", ["process", "thread"])
def test_recordings_started_while_tracking_is_lost_replay_the_voice_and_the_ease_in_exactly(tmp_path, monkeypatch,
                                                                                          receiver):
    """Record clicked while the tracker is silent and the mouth follows the voice (``[tracking_loss] mouth =
    "voice"``, ``--audio-file``), in the ease out: a first recording stopped before the tracker came back, a
    second one during which it came back. Each keeps the filter stage's state before its first tick, so its
    replay draws what the run drew from that tick on: the jaw on the voice, then the ease back in to the
    tracker. A stage started afresh drew the rest pose until a first frame came, and took it without the ease in;
    the first recording, which had no frame, kept no state at all before."""
    from helpers.swinging_voice import write_voice

    monkeypatch.chdir(tmp_path)
    wav = tmp_path / "voice.wav"
    write_voice(wav, seconds=80.0)
    loss = ("[tracking_loss]\ntimeout_s = 0.3\nease_out_s = 1.0\nease_in_s = 0.3\nmouth = \"voice\"\n"
            "voice_floor_db = -40.0\nvoice_ceiling_db = -5.0\n")
    result, op, character, config = _run(
        tmp_path, ("--receiver", receiver, "--audio-file", str(wav)), loss,
        plan=["wait"] * 15 + ["quiet", "lost"] + ["wait"] * 3 + ["start"] + ["wait"] * 8 + ["halt"]
        + ["wait"] * 2 + ["start"] + ["wait"] * 8 + ["loud", "stop"] + ["wait"] * 3)
    assert not op.plan and len(op.files) == 2
    from facepuppet.runtime.commands import replay
    ns = argparse.ArgumentParser()
    replay.register(ns.add_subparsers())
    jaw = list(sphere_character().shape_names).index("jawOpen")

    def replayed(path, name):
        dump = tmp_path / name
        args = ns.parse_args(["replay", str(path), "-c", str(character), "--headless", "--size", "64x64",
                              "--dump-weights", str(dump)])
        assert replay.run_replay(args) == 0
        return np.load(dump)

    for n, path in enumerate(op.files):
        session = read_session(path)
        assert len(session.states) == 1 and '"state": "lost"' in session.states[0][1]
        ticks = [t.k for t in session.ticks]
        live = np.array([op.live[k] for k in ticks])
        framed = [i for i, t in enumerate(session.ticks) if t.frames > 0]
        first_frame = framed[0] if framed else len(ticks)
        assert (not framed) == (n == 0)  # the tracker came back during the second recording only
        assert first_frame >= 8  # ticks on the voice alone
        assert np.ptp(live[:first_frame, jaw]) > 0.01  # the jaw moved with the voice then
        got = replayed(path, f"replay{n}.npy")
        assert got.shape == live.shape
        np.testing.assert_allclose(got, live, atol=1e-6)  # from the first tick: the voice, the ease out and in
    monkeypatch.setattr(recording_feed, "restore_state", lambda *a, **k: None)
    fresh = replayed(op.files[1], "fresh.npy")
    assert np.abs(fresh[:first_frame] - live[:first_frame]).max() > 0.01
