"""``--virtual-camera``: the drawn frames reach the camera through pyvirtualcam's own backend seam (a backend
registered with ``pyvirtualcam.register_backend`` that keeps what it is sent), over the green key colour, at
the run's frame rate; a missing device or module is said with the command that makes it and the run goes on;
on a machine with v4l2loopback, the frames are read back from the device."""

from __future__ import annotations

import argparse
import dataclasses
import glob
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime.cli import main
from facepuppet.runtime.commands import replay as replay_command
from facepuppet.runtime.live.virtual_camera import (
    LOOPBACK_SYSFS,
    MODPROBE,
    VirtualCameraSink,
    plan_virtual_camera,
    setup_command,
)

from helpers.live_pictures import RecordingBackend, register_recording_backend, write_take
from helpers.small_characters import sphere_character

pyvirtualcam = pytest.importorskip("pyvirtualcam", reason="pyvirtualcam is not installed: pip install -e '.[vcam]' "
                                                         "(make setup installs it)")

JAWS = [0.1, 0.3, 0.5, 0.7, 0.9, 0.6]


def _replay_plan(tmp_path, *extra: str):
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    take = tmp_path / "take.csv"
    write_take(take, JAWS)
    parser = argparse.ArgumentParser(prog="facepuppet")
    replay_command.register(parser.add_subparsers())
    ns = parser.parse_args(["replay", str(take), "-c", str(character), "--headless", "--size", "48x40", "--fps",
                            "10", "--out", str(tmp_path / "frames"), *extra])
    return replay_command.ReplayPlan.from_args(ns)


def _with_backend(plan):
    camera = dataclasses.replace(plan.outputs.virtual_camera, backend=register_recording_backend())
    return dataclasses.replace(plan, outputs=dataclasses.replace(plan.outputs, virtual_camera=camera))


def _pngs(folder: Path) -> list[np.ndarray]:
    return [np.asarray(Image.open(p)) for p in sorted(folder.glob("frame_*.png"))]


def _in_order(sent: list[np.ndarray], drawn: list[np.ndarray]) -> bool:
    """Every sent frame is one of the drawn ones, exactly, in drawing order (a dropped one is skipped)."""
    i = 0
    for frame in sent:
        while i < len(drawn) and not np.array_equal(frame, drawn[i]):
            i += 1
        if i == len(drawn):
            return False
        i += 1
    return True


@pytest.mark.gl
def test_the_drawn_frames_reach_the_camera_over_green_at_the_run_rate(tmp_path):
    plan = _with_backend(_replay_plan(tmp_path, "--virtual-camera"))
    assert plan.picture.render.background == (0.0, 1.0, 0.0)   # no --background: the key colour
    RecordingBackend.opened.clear()
    result, _ = replay_command.replay(plan)
    (camera,) = RecordingBackend.opened
    assert camera.closed and (camera.width, camera.height, camera.fps) == (48, 40, 10.0)
    assert camera.fourcc == pyvirtualcam.util.encode_fourcc("ABGR")       # RGBA frames, as the loop read them
    drawn = _pngs(tmp_path / "frames")
    counters = result.outputs.virtual_camera.counters
    assert len(drawn) == len(JAWS) == counters["offered"] == counters["sent"] + counters["dropped"]
    assert counters["sent"] == len(camera.frames) >= 1
    assert _in_order([f[:, :, :3] for f in camera.frames], drawn)
    for frame in camera.frames:
        assert tuple(frame[0, 0]) == (0, 255, 0, 255)                        # the key colour in the corner


@pytest.mark.gl
def test_a_transparent_picture_goes_to_the_camera_over_green_and_keeps_its_alpha_in_the_pngs(tmp_path):
    plan = _with_backend(_replay_plan(tmp_path, "--virtual-camera", "/dev/video42", "--background",
                                      "transparent"))
    RecordingBackend.opened.clear()
    replay_command.replay(plan)
    (camera,) = RecordingBackend.opened
    assert camera.device() == "/dev/video42" and camera.fourcc == pyvirtualcam.util.encode_fourcc("raw ")
    drawn = _pngs(tmp_path / "frames")
    assert drawn[0].shape[2] == 4 and drawn[0][0, 0, 3] == 0
    over = [np.where(d[:, :, 3:4] == 255, d[:, :, :3], 0) for d in drawn]
    for frame in camera.frames:
        assert tuple(frame[0, 0]) == (0, 255, 0)
        opaque = [d[:, :, 3] == 255 for d in drawn]
        assert any(np.array_equal(np.where(m[:, :, None], frame, 0), o) for m, o in zip(opaque, over))


@pytest.mark.gl
def test_a_background_colour_is_the_key(tmp_path):
    plan = _with_backend(_replay_plan(tmp_path, "--virtual-camera", "--background", "0,0,255"))
    RecordingBackend.opened.clear()
    replay_command.replay(plan)
    assert tuple(RecordingBackend.opened[-1].frames[0][0, 0, :3]) == (0, 0, 255)
    assert plan.outputs.virtual_camera.key == (0, 0, 255)


@pytest.mark.gl
def test_a_missing_device_is_said_with_the_command_that_makes_it_and_the_run_goes_on(tmp_path):
    """The real command on this machine: no v4l2loopback (the module's command), or a module without
    /dev/video99 (the same command with video_nr=99); either way the replay ends well with its frames."""
    if os.path.exists("/dev/video99"):
        pytest.skip("/dev/video99 exists on this machine: the missing-device case cannot be made here")
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    take = tmp_path / "take.csv"
    write_take(take, JAWS)
    done = subprocess.run([sys.executable, "-m", "facepuppet", "replay", str(take), "-c", str(character),
                           "--headless", "--size", "48x40", "--fps", "10", "--virtual-camera", "/dev/video99",
                           "--out", str(tmp_path / "frames")], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert "virtual camera: not available" in done.stderr and "the run goes on without it" in done.stderr
    assert MODPROBE in done.stderr
    if not LOOPBACK_SYSFS.exists():
        assert "v4l2loopback kernel module is not loaded" in done.stderr
    assert "replay: no virtual camera (not available; said at the start)" in done.stdout
    assert len(list((tmp_path / "frames").glob("frame_*.png"))) == len(JAWS)


def test_the_setup_command_names_the_device_number():
    assert setup_command(None) == "sudo modprobe v4l2loopback devices=1 exclusive_caps=1 card_label=facepuppet"
    assert setup_command("/dev/video7").endswith(" video_nr=7")


@pytest.mark.parametrize("device, said", [("", "expected a device such as /dev/video7"), ("/", "is a folder")])
def test_a_device_that_cannot_be_one_is_refused_before_work(tmp_path, capsys, device, said):
    take = tmp_path / "take.csv"
    write_take(take, JAWS)
    code = main(["replay", str(take), "-c", str(tmp_path / "absent.npz"), "--headless", "--virtual-camera", device])
    err = capsys.readouterr().err
    assert code == 2 and "--virtual-camera" in err and said in err and "Traceback" not in err, err


def test_the_plan_keys_over_green_when_transparent():
    plan = plan_virtual_camera(None, 64, 48, None, (0.2, 0.3, 0.4), transparent=True)
    assert plan.key == (0, 255, 0) and plan.device is None


def _loopback_device() -> str | None:
    for path in sorted(glob.glob("/dev/video*")):
        try:
            name = Path(f"/sys/class/video4linux/{Path(path).name}/name").read_text().strip()
        except OSError:
            continue
        if os.access(path, os.R_OK | os.W_OK) and ("loopback" in name.lower() or "facepuppet" in name.lower()):
            return path
    return None


@pytest.mark.skipif(not LOOPBACK_SYSFS.exists(), reason="no v4l2loopback kernel module here (/sys/module/"
                    "v4l2loopback absent): the frames cannot be read back from a device; " + MODPROBE + " makes one")
def test_frames_written_to_a_loopback_device_are_read_back():
    """pyvirtualcam's own v4l2loopback backend writes I420; a reader of the device gets the frame's luma back."""
    device = _loopback_device()
    if device is None:
        pytest.skip("v4l2loopback is loaded but no readable and writable loopback /dev/video* was found")

    width, height = 64, 48
    plan = plan_virtual_camera(device, width, height, 30.0, (0.0, 1.0, 0.0), False)
    camera = pyvirtualcam.Camera(width, height, 30.0, fmt=pyvirtualcam.PixelFormat.RGBA, device=device,
                                 backend="v4l2loopback")
    sink = VirtualCameraSink(camera, plan)
    grey = np.full((height, width, 3), 200, np.uint8)
    reader = os.open(device, os.O_RDONLY)
    try:
        for k in range(10):
            sink.handoff.offer(k, k / 30, 0.0, grey)
            sink.handoff.drain()
        data = os.read(reader, width * height * 3 // 2)
    finally:
        os.close(reader)
        sink.close()
    luma = np.frombuffer(data[:width * height], np.uint8)
    assert len(data) == width * height * 3 // 2
    assert abs(float(luma.mean()) - 200) < 12   # BT.601 luma of grey 200, limited or full range
