"""Shared fixtures: paths to ../shared/data, a real EGL context, the ICT character; the test markers."""

from __future__ import annotations

import functools
import os
import select
import shutil
import socket
import subprocess
import time
from pathlib import Path

import pytest

from helpers import running_test

# One BLAS thread per test process, set before NumPy loads OpenBLAS (none of the imports above load it): the
# suite runs in two worker processes (make test: pytest -n 2) on two cores, and OpenBLAS's own threads, which
# spin while they wait, made a 20 s kernel-PLS fit take 250 s once the cores were busy (measured: 27 s with one
# thread under the same load).
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

# the module-scoped fixture ``db`` (a small synthetic gesture database) for the gesture tests; ``udp_receiver``
# (a loopback socket for what a run or a replay sends)
pytest_plugins = ["helpers.gesture_dbs", "helpers.udp_helpers", "helpers.virtual_sound_card"]

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"
ICT_DIR = SHARED_DATA / "ict-facekit"
TRACKER_DIR = SHARED_DATA / "tracker"


def need_shared(*parts: str) -> Path:
    """Path under ../shared/data, or skip (with the reason) when the data kit is absent."""
    if running_test.marks is not None and "data" not in running_test.marks:
        pytest.fail("this test reads ../shared/data but is not marked data: add @pytest.mark.data "
                    "(or pytestmark = pytest.mark.data) so that -m 'not data' leaves it out", pytrace=False)
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"../shared/data is absent here ({path} not found); this test needs the real asset")
    return path


@pytest.fixture(scope="session")
def _egl_session_ctx():
    moderngl = pytest.importorskip("moderngl")
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=330)
    except Exception as exc:  # no libEGL / no driver: the one honest reason to skip
        pytest.skip(f"no EGL OpenGL context on this machine: {exc}")
    yield ctx
    ctx.release()


@pytest.fixture
def egl_ctx(_egl_session_ctx):
    """A real headless OpenGL context (EGL, Mesa llvmpipe here), one per test process; skips only if EGL is
    truly missing. Each test starts with no GL error pending, and one that leaves an error behind fails,
    naming it (the error is sticky: whichever test read ``ctx.error`` next would fail instead, and which one
    that is depends on the order the workers ran the tests in)."""
    ctx = _egl_session_ctx
    before = ctx.error
    assert before == "GL_NO_ERROR", f"a GL error was pending before this test: {before}"
    yield ctx
    left = ctx.error
    assert left == "GL_NO_ERROR", f"this test left a GL error on the shared context: {left}"


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
    from facepuppet.runtime.model.character import Character

    return Character.load(ict_character_path)


@pytest.fixture
def x_display():
    """A virtual X display (Xvfb), stopped after the test. Xvfb picks a free display number itself and writes
    it to a pipe (``-displayfd``), so tests running in parallel never race for one."""
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.skip("Xvfb is not installed (make test installs it through .ci/system-deps); "
                    "the window path needs an X display")
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen([xvfb, "-displayfd", str(write_fd), "-screen", "0", "1024x768x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, pass_fds=(write_fd,))
    os.close(write_fd)
    try:
        number = _read_display(read_fd, proc)
        yield f":{number}"
    finally:
        os.close(read_fd)
        proc.terminate()
        proc.wait(timeout=10)


def _read_display(fd: int, proc: subprocess.Popen, timeout_s: float = 20.0) -> str:
    """The display number Xvfb writes to ``fd`` once it listens (a line of digits)."""
    text = b""
    deadline = time.monotonic() + timeout_s
    while not text.endswith(b"\n"):
        ready, _, _ = select.select([fd], [], [], max(0.0, deadline - time.monotonic()))
        chunk = os.read(fd, 64) if ready else b""
        if not chunk:
            raise RuntimeError(f"Xvfb did not start (exit code {proc.poll()}) within {timeout_s:g} s")
        text += chunk
    return text.decode().strip()


@pytest.fixture
def udp_sender():
    """A UDP socket for sending datagrams to a receiver on 127.0.0.1."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    yield s
    s.close()


# Markers (registered in pyproject.toml): gl, data and slow. A test that uses one of these fixtures gets
# the marker here; any other test says so itself (@pytest.mark.gl, or pytestmark = ... in its module).
GL_FIXTURES = {
    "egl_ctx",    # a headless OpenGL context in this process
    "x_display",  # its tests open a glfw window with an OpenGL context on Xvfb
}
DATA_FIXTURES = {"ict_character_path"}  # ict_character depends on it
# Importing the ICT head takes about 4 s once per session (measured with --durations), whichever test
# asks first, so the tests that need it are slow as a group even where their own call is short.
SLOW_FIXTURES = {"ict_character_path"}

@pytest.hookimpl(tryfirst=True)  # before -m deselects by marker
def pytest_collection_modifyitems(config, items):
    for item in items:
        names = set(item.fixturenames)  # the closure: fixtures of fixtures too
        marks = set()
        if names & GL_FIXTURES:
            marks.add("gl")
        if names & DATA_FIXTURES:
            marks.add("data")
        if names & SLOW_FIXTURES:
            marks.add("slow")
        for name in sorted(marks - {m.name for m in item.iter_markers()}):
            item.add_marker(name)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Run the test with its marker names in helpers.running_test (need_shared checks for data), and with
    moderngl's context constructors refusing when it is not marked gl. This catches a context opened in
    this process only: a test whose subprocess opens one is marked by hand."""
    running_test.marks = frozenset(m.name for m in item.iter_markers())
    restore = [] if "gl" in running_test.marks else _refuse_gl_contexts()
    try:
        return (yield)
    finally:
        for undo in restore:
            undo()
        running_test.marks = None


def _refuse_gl_contexts():
    try:
        import moderngl
    except ImportError:  # no moderngl: nothing can open a context
        return []
    restore = []
    for name in ("create_standalone_context", "create_context"):
        def refuse(*args, _name=name, **kwargs):
            # pytest.fail raises a BaseException: the `except Exception` around context creation in the
            # runtime (which turns failures into GLUnavailable) cannot swallow it.
            pytest.fail(f"this test opens an OpenGL context (moderngl.{_name}) but is not marked gl: add "
                        "@pytest.mark.gl (or use the egl_ctx fixture)", pytrace=False)

        restore.append(functools.partial(setattr, moderngl, name, getattr(moderngl, name)))
        setattr(moderngl, name, refuse)
    return restore
