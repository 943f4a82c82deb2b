"""A live ``run`` (VMC over UDP on 127.0.0.1) with both live picture outputs at once: the virtual camera through
pyvirtualcam's backend seam at the run's frame rate (``--fps``, not the arrival grid), the stream decoded back
by PyAV, and their counts in ``--stats``."""

from __future__ import annotations

import dataclasses
import threading
import time

import numpy as np
import pytest
from pythonosc.udp_client import SimpleUDPClient

from facepuppet.runtime.commands import run

from helpers.live_pictures import Receiver, RecordingBackend, decode_ts, register_recording_backend
from helpers.logs import logged
from helpers.small_characters import sphere_character
from helpers.udp_helpers import free_udp_port
from helpers.vmc_run import send_vmc

pytest.importorskip("pyvirtualcam", reason="pyvirtualcam is not installed: pip install -e '.[vcam]'")
pytest.importorskip("av", reason="PyAV is not installed: pip install -e '.[video]'")

TICKS = 10


@pytest.mark.gl
def test_a_live_run_feeds_the_camera_and_the_stream_and_counts_them(tmp_path):
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    port = free_udp_port()
    receiver = Receiver()
    plan = run.plan_from_argv(["-c", str(character), "--input", "vmc", "--listen", f"127.0.0.1:{port}",
                               "--headless", "--receiver", "thread", "--size", "64x48", "--fps", "30",
                               "--duration", "60", "--stats", "--virtual-camera",
                               "--stream", f"udp://127.0.0.1:{receiver.port}"])
    camera_plan = dataclasses.replace(plan.outputs.virtual_camera, backend=register_recording_backend())
    plan = dataclasses.replace(plan, outputs=dataclasses.replace(plan.outputs, virtual_camera=camera_plan))
    stop, drawn = threading.Event(), []

    def on_ready(address):
        def send():
            client = SimpleUDPClient("127.0.0.1", port)
            k = 0
            while not stop.is_set():
                send_vmc(client, {"JawOpen": (k % 10) / 10})
                k += 1
                time.sleep(0.02)
        threading.Thread(target=send, daemon=True).start()

    def hook(info):
        if info.raw is not None:
            drawn.append(info.k)
            if len(drawn) >= TICKS:
                stop.set()

    RecordingBackend.opened.clear()
    logs: list[str] = []
    try:
        with logged(logs):
            result = run.run_live(plan, stop_event=stop, on_ready=on_ready, hooks=[hook])
            run.report_live_pictures("run", plan.outputs, result)
    finally:
        stop.set()
    frames, _ = decode_ts(receiver.stop())
    (camera,) = RecordingBackend.opened
    assert camera.fps == 30.0 and camera.closed          # the run's --fps, not the 1 kHz arrival grid
    ticks = result.loop.n_ticks
    cam, stream = result.outputs.virtual_camera.counters, result.outputs.stream.counters
    for counters in (cam, stream):
        assert counters["offered"] + counters["over_rate"] == ticks
        assert counters["offered"] == counters["sent"] + counters["dropped"]
        assert counters["sent"] >= 1 and counters["failed"] == 0
    assert len(camera.frames) == cam["sent"] and len(frames) == stream["sent"]
    assert tuple(camera.frames[-1][0, 0, :3]) == (0, 255, 0)
    np.testing.assert_allclose(frames[-1][1, 1], (0, 255, 0), atol=12)   # the stream shows the same green
    final = "\n".join(result.stats.final())   # what --stats prints at exit
    assert "virtual_camera: offered=" in final and "stream: offered=" in final
    assert '"stream": {"dropped": ' in final
    text = "\n".join(logs)
    assert f"run: streamed {stream['sent']} frames to udp://127.0.0.1:{receiver.port}, dropped " in text
    assert f"run: sent {cam['sent']} frames to the virtual camera /dev/video-recording, dropped " in text
