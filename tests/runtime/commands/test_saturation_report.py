"""The marker solve's saturation, as ``run --input markers`` and ``replay`` report it: real commands (subprocesses
of ``facepuppet``) fed over UDP on 127.0.0.1 and replaying what the run recorded.

The pair is fitted with a face-size ratio four times the measured one, so the take's widest jaw pose asks for
more than the character's jawOpen has: that pose is drawn at jawOpen 1.0, the rest pose at 0. The sender
alternates the two every 10 frames, so about half of the solved frames sit at 1.0 however late the run starts.
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading

import numpy as np
import pytest
from pythonosc.udp_client import SimpleUDPClient

from facepuppet.runtime.actuation.stage import ActorRetarget
from facepuppet.runtime.frames import Frame

from facepuppet.offline.actuation.synthetic_capture import synthetic_capture
from facepuppet.offline.actuation.train import train_actor
from facepuppet.offline.actuation.transfer import retarget_actor
from helpers.marker_senders import marker_sender
from helpers.small_characters import grid_face
from helpers.udp_helpers import free_udp_port

pytestmark = [pytest.mark.gl, pytest.mark.slow]
NO_SMOOTHING = "\n".join(f"[filter.{r}]\nmin_cutoff = 500.0\nbeta = 0.0" for r in ("eyes", "brows", "mouth", "other",
                                                                                  "head"))


@pytest.fixture(scope="module")
def saturating(tmp_path_factory):
    """Files of an actor and a pair that saturates jawOpen, the rest pose and the saturating pose."""
    tmp = tmp_path_factory.mktemp("saturating")
    cap, _ = synthetic_capture(n_frames=600, n_markers=20, k=3, seed=4)
    actor = train_actor(cap, k=3, head_markers=["M00", "M01", "M02", "M03"]).actor_
    character = grid_face()
    measured = retarget_actor(actor, character).metadata["metrics"]["face_scale"]["ratio"]
    pair = retarget_actor(actor, character, scale=4 * measured)
    stage = ActorRetarget(actor, pair)
    w = np.array([stage.apply(Frame(t=0.0, markers=m.astype(np.float32), marker_names=cap.names))
                  for m in cap.markers])
    rest, wide = cap.markers[int(np.argmin(w.sum(axis=1)))], cap.markers[int(np.argmax(w[:, 0]))]
    for pose, expected in ((rest, 0.0), (wide, 1.0)):   # what each pose draws once the solve has settled
        for _ in range(40):
            drawn = stage.apply(Frame(t=0.0, markers=pose.astype(np.float32), marker_names=cap.names))
        assert drawn[0] == expected and drawn[1] < 1.0
    config = tmp / "fast.toml"
    config.write_text(NO_SMOOTHING)
    files = {"actor": actor.save(tmp / "actor.npz"), "pair": pair.save(tmp / "pair.npz"),
             "character": character.save(tmp / "grid.npz"), "config": config}
    return files, cap.names, rest.astype(np.float32), wide.astype(np.float32)


def facepuppet(*args) -> subprocess.CompletedProcess:
    done = subprocess.run([sys.executable, "-m", "facepuppet", *map(str, args)], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return done


def run_fed(files, names, pose_at, *extra) -> subprocess.CompletedProcess:
    """``facepuppet run --input markers`` for 2 s, fed by a sender on a thread over 127.0.0.1 until it ends."""
    port = free_udp_port()
    stop = threading.Event()
    sender = threading.Thread(target=marker_sender(names, pose_at), args=(SimpleUDPClient("127.0.0.1", port), stop),
                              daemon=True)
    sender.start()
    try:
        return facepuppet("run", "-c", files["character"], "--input", "markers", "--actor", files["actor"], "--pair",
                          files["pair"], "--config", files["config"], "--listen", f"127.0.0.1:{port}", "--headless",
                          "--size", "48x40", "--duration", "2", *extra)
    finally:
        stop.set()
        sender.join(timeout=10)


def stats_json(out: str) -> dict:
    return json.loads(next(line for line in out.splitlines() if line.startswith("stats json: "))[len("stats json: "):])


def test_run_counts_saturation_in_stats_and_warns_without(saturating, tmp_path):
    files, names, rest, wide = saturating
    alternating = lambda age: wide if int(age * 100) // 10 % 2 else rest   # noqa: E731  10 frames each

    done = run_fed(files, names, alternating, "--stats")
    summary = stats_json(done.stdout)["saturation"]
    assert summary["frames"] > 20 and list(summary["channels_at_1"]) == ["jawOpen"]
    assert 0.2 < summary["channels_at_1"]["jawOpen"] < 0.8, summary
    line = next(x for x in done.stdout.splitlines() if "solve saturation over" in x)
    assert line.startswith("run: solve saturation over") and "jawOpen" in line and "puff" not in line

    recording = tmp_path / "take.fprec"
    done = run_fed(files, names, alternating, "--record", recording)      # no --stats: still warned
    assert "run: warning: solve saturation over" in done.stdout and "jawOpen" in done.stdout

    quiet = tmp_path / "rest.fprec"
    done = run_fed(files, names, lambda age: rest, "--record", quiet)      # nothing at 1.0: nothing said
    assert "solve saturation" not in done.stdout

    # replay, without --stats: the recording that saturated is warned about, the rest one is not
    replay = ["-c", files["character"], "--actor", files["actor"], "--pair", files["pair"], "--headless", "--size",
              "48x40"]
    done = facepuppet("replay", recording, *replay)
    assert "replay: warning: solve saturation over" in done.stdout and "jawOpen" in done.stdout
    done = facepuppet("replay", quiet, *replay)
    assert "solve saturation" not in done.stdout
