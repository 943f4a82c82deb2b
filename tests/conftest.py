"""Shared fixtures: paths to ../shared/data, a real EGL context, the ICT character."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"
ICT_DIR = SHARED_DATA / "ict-facekit"
TRACKER_DIR = SHARED_DATA / "tracker"


def need_shared(*parts: str) -> Path:
    """Path under ../shared/data, or skip (with the reason) when the data kit is absent."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"../shared/data is absent here ({path} not found); this test needs the real asset")
    return path


@pytest.fixture(scope="session")
def egl_ctx():
    """A real headless OpenGL context (EGL, Mesa llvmpipe here); skips only if EGL is truly missing."""
    moderngl = pytest.importorskip("moderngl")
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=330)
    except Exception as exc:  # no libEGL / no driver: the one honest reason to skip
        pytest.skip(f"no EGL OpenGL context on this machine: {exc}")
    yield ctx
    ctx.release()


@pytest.fixture(scope="session")
def ict_character_path(tmp_path_factory) -> Path:
    """The ICT-FaceKit head imported once per test session with the real files."""
    ict = need_shared("ict-facekit")
    from facepuppet.offline.io.rig_import import import_rig

    out = tmp_path_factory.mktemp("ict") / "ict.npz"
    import_rig(ict / "generic_neutral_mesh.obj", ict).save(out)
    return out


@pytest.fixture(scope="session")
def ict_character(ict_character_path):
    from facepuppet.runtime.character import Character

    return Character.load(ict_character_path)


@pytest.fixture
def x_display():
    """A virtual X display (Xvfb) on a free number, stopped after the test."""
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.skip("Xvfb is not installed (make test installs it through .ci/system-deps); "
                    "the window path needs an X display")
    for number in range(91, 120):
        if not os.path.exists(f"/tmp/.X{number}-lock"):
            break
    proc = subprocess.Popen([xvfb, f":{number}", "-screen", "0", "1024x768x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 10
    while not os.path.exists(f"/tmp/.X11-unix/X{number}") and time.monotonic() < deadline:
        time.sleep(0.05)
    try:
        yield f":{number}"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


@pytest.fixture
def udp_sender():
    """A UDP socket for sending datagrams to a receiver on 127.0.0.1."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    yield s
    s.close()
