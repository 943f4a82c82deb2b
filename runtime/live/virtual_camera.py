"""``--virtual-camera [DEVICE]``: the drawn ticks as a webcam for Zoom, Meet, Discord and OBS's video capture.

pyvirtualcam (the optional extra ``vcam``) writes frames to a v4l2loopback device under Linux (and to OBS's
virtual camera on macOS and Windows). A camera has no alpha, so the picture goes out over a key colour a
viewer can remove: the background is green (0, 255, 0, what OBS's chroma key filter takes by default) unless
``--background R,G,B`` names another; with ``--background transparent`` the frames keep their alpha for
``--video`` and the camera gets them composited over green.

The camera is opened at the start, at the run's frame rate (``--fps``; a replay's take rate) and size, and
takes at most that many frames a second (a run drawing on arrival of a faster tracker leaves the ticks
between out, counted as ``over_rate``). A
camera that cannot be opened (pyvirtualcam missing, no v4l2loopback module loaded, the named device absent or
not a loopback one, no permission) does not stop the run: the reason is said once with the command that
makes the device, e.g. ``sudo modprobe v4l2loopback devices=1 exclusive_caps=1 card_label=facepuppet``
(``exclusive_caps=1``: Chrome and the browser-based call clients list only capture-only devices), and the
run goes on without it.

The frame loop reads the pixels back and hands them to a worker thread
(:mod:`~facepuppet.runtime.live.frame_handoff`); what the camera cannot take in time is dropped and counted
(``--stats``: ``virtual_camera: sent=... dropped=...``), never waited for.

Backends: pyvirtualcam picks one by name from its registry (``pyvirtualcam.register_backend``); the plan's
``backend`` names one (None: every backend of the platform in turn, as pyvirtualcam does), which is how the
tests drive a recording backend on a machine without the kernel module.
"""

from __future__ import annotations

import logging
import os
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.live.frame_handoff import FrameHandoff, TickReadback, live_picture, over_key

if TYPE_CHECKING:
    import pyvirtualcam

    from facepuppet.runtime.live.loop import TickInfo

logger = logging.getLogger(__name__)

#: the key colour behind the character when no --background is given: pure green, OBS chroma key's default
KEY_GREEN = (0.0, 1.0, 0.0)
LOOPBACK_SYSFS = Path("/sys/module/v4l2loopback")
MODPROBE = "sudo modprobe v4l2loopback devices=1 exclusive_caps=1 card_label=facepuppet"


@dataclass(frozen=True)
class VirtualCameraPlan:
    """What ``--virtual-camera`` asked for, checked before the run.

    Attributes
    ----------
    device : str or None, the device (``/dev/video7``); None: the first loopback device found
    width, height : int, pixels
    fps : float or None, the frame rate announced to the camera (None: the session's)
    key : tuple of 3 int, 0..255, the colour frames with alpha are composited over
    backend : str or None, pyvirtualcam's backend by name (None: each of the platform's in turn)
    transparent : bool, the picture has alpha (``--background transparent``): composited over ``key`` and sent
        as RGB; else sent as the framebuffer holds it, RGBA (the camera's conversion ignores the alpha)
    """

    device: str | None
    width: int
    height: int
    fps: float | None = None
    key: tuple[int, int, int] = (0, 255, 0)
    backend: str | None = None
    transparent: bool = False

    def describe(self, fps: float, device: str | None = None) -> str:
        """One line for the start of a run (``device``: the one opened)."""
        where = device or self.device or "the first v4l2loopback device"
        return (f"virtual camera: {where}, {self.width}x{self.height} at {fps:g} fps, key colour "
                f"{self.key[0]},{self.key[1]},{self.key[2]}")


def plan_virtual_camera(device: str | None, width: int, height: int, fps: float | None,
                        background: tuple[float, float, float], transparent: bool) -> VirtualCameraPlan:
    """The plan of ``--virtual-camera [DEVICE]`` (``device`` None or "auto": the first loopback device).

    The key colour is the picture's background (already green when no ``--background`` was given, see
    :data:`KEY_GREEN`); a transparent picture is composited over green. UsageError naming the option for a
    device that cannot be one (an empty name, a folder).
    """
    if device is not None:
        device = device.strip()
        if device == "auto":
            device = None
        elif device == "":
            raise UsageError("--virtual-camera: expected a device such as /dev/video7, or nothing for the first "
                             "v4l2loopback device")
    if device is not None and os.path.isdir(device):
        raise UsageError(f"--virtual-camera {device}: is a folder; name a device such as /dev/video7")
    key_rgb = KEY_GREEN if transparent else background
    key = tuple(int(round(min(max(c, 0.0), 1.0) * 255)) for c in key_rgb)
    return VirtualCameraPlan(device, int(width), int(height), fps, key,  # type: ignore[arg-type]
                             transparent=bool(transparent))


def setup_command(device: str | None) -> str:
    """The command that makes the loopback device (with its number when one was named)."""
    m = re.fullmatch(r"/dev/video(\d+)", device or "")
    return MODPROBE + (f" video_nr={m.group(1)}" if m else "")


def why_unavailable(plan: VirtualCameraPlan) -> str | None:
    """Why the camera cannot be opened, found before asking pyvirtualcam (None: nothing known against it)."""
    try:
        import pyvirtualcam  # noqa: F401  (the optional extra)
    except ImportError:
        return "needs pyvirtualcam, which is not installed: pip install 'facepuppet[vcam]'"
    if plan.backend not in (None, "v4l2loopback") or not sys.platform.startswith("linux"):
        return None
    if not LOOPBACK_SYSFS.exists():
        return (f"the v4l2loopback kernel module is not loaded; make a device with: {setup_command(plan.device)} "
                "(Debian/Ubuntu: apt install v4l2loopback-dkms first)")
    if plan.device is not None and not os.path.exists(plan.device):
        return f"{plan.device} does not exist; make it with: {setup_command(plan.device)}"
    return None


class VirtualCameraSink:
    """The frame loop's ``--virtual-camera`` output: a tick observer handing pictures to the camera's thread.

    Parameters
    ----------
    camera : a ``pyvirtualcam.Camera`` of the plan's size, RGB frames when the plan is transparent, else RGBA;
        closed with the sink
    plan : VirtualCameraPlan
    readback : TickReadback, shared with the session's other live outputs
    fps : float or None, at most this many frames a second of tick time (the rate the camera announces)

    Attributes
    ----------
    device : str, the device the camera opened
    counters : dict, the handoff's counts (``sent`` = frames the camera took)
    """

    name = "virtual_camera"

    def __init__(self, camera: pyvirtualcam.Camera, plan: VirtualCameraPlan,
                 readback: TickReadback | None = None, fps: float | None = None) -> None:
        self.camera = camera
        self.plan = plan
        self.readback = readback or TickReadback()
        self.device: str = camera.device
        self.handoff = FrameHandoff(self._send, "virtual camera", fps=fps)
        self.counters = self.handoff.counters

    def __call__(self, info: TickInfo) -> None:
        self.handoff.take(info, self.readback)

    def _send(self, k: int, t: float, stamp: float, pixels: np.ndarray) -> None:
        if self.plan.transparent:
            self.camera.send(over_key(pixels, self.plan.key))
        else:
            self.camera.send(pixels if pixels.shape[2] == 4 else live_picture(pixels))

    def costs(self) -> dict:
        return self.handoff.costs()

    def close(self) -> None:
        """Send what is waiting, stop the thread, release the device (once)."""
        ended = False
        try:
            ended = self.handoff.close()
        finally:
            if self.camera is not None and ended:  # a camera still writing is left to the process's end
                self.camera.close()
            self.camera = None


def open_virtual_camera(plan: VirtualCameraPlan, fps: float, readback: TickReadback | None = None,
                        log: Callable[[str], None] = logger.info) -> VirtualCameraSink | None:
    """The sink, or None when the camera cannot be opened (said once through ``log`` with how to fix it)."""
    reason = why_unavailable(plan)
    camera = None
    if reason is None:
        import pyvirtualcam

        try:
            fmt = pyvirtualcam.PixelFormat.RGB if plan.transparent else pyvirtualcam.PixelFormat.RGBA
            camera = pyvirtualcam.Camera(plan.width, plan.height, fps, fmt=fmt, device=plan.device,
                                         backend=plan.backend)
        except Exception as exc:  # pyvirtualcam says why in a RuntimeError per backend tried
            reason = f"{' '.join(str(exc).split())}; a loopback device is made with: {setup_command(plan.device)}"
    if camera is None:
        log(f"virtual camera: not available: {reason}; the run goes on without it")
        return None
    sink = VirtualCameraSink(camera, plan, readback, fps)
    log(plan.describe(fps, sink.device) + f" (pyvirtualcam {camera.backend} backend)")
    return sink
