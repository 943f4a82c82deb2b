"""``facepuppet run`` as a real process under a flooding tracker: killed, its port is free again at once;
asked to stop (SIGTERM, SIGINT), it ends cleanly with its final stats and a complete recording.

The tracker is a thread here sending VMC frames to 127.0.0.1 about every 0.5 ms (the issue: the
receiving child only looked for its parent when a receive timed out, which a tracker at >= 20 Hz never
lets happen, so the port stayed bound after ``kill -9`` until the tracker stopped).
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import warnings

import pytest

from facepuppet.runtime.recording.session import read_session

from helpers.osc_helpers import vmc_frame
from helpers.small_characters import sphere_character
from helpers.udp_helpers import free_udp_port

pytestmark = pytest.mark.gl  # the run draws headless (EGL)

START_DEADLINE_S = 60.0  # a fresh interpreter importing NumPy and making an EGL context on a loaded machine
FREE_DEADLINE_S = 10.0   # the bound on the wait for the port; the time it took is printed


@pytest.fixture(scope="module")
def character(tmp_path_factory):
    path = tmp_path_factory.mktemp("signals") / "sphere.npz"
    sphere_character().save(path)
    return path


class Flood:
    """A thread sending VMC frames to 127.0.0.1:port in bursts, until :meth:`stop`."""

    def __init__(self, port: int) -> None:
        self.port, self.sent = port, 0
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._send, daemon=True)

    def __enter__(self) -> Flood:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._done.set()
        self._thread.join(timeout=10)

    def _send(self) -> None:
        data = vmc_frame(0.5)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            while not self._done.is_set():
                for _ in range(10):
                    s.sendto(data, ("127.0.0.1", self.port))
                    self.sent += 1
                time.sleep(0.005)


def start_run(character, port: int, *extra: str) -> subprocess.Popen:
    """A ``facepuppet run`` process, returned once it says it listens."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "facepuppet", "run", "-c", str(character), "--input", "vmc",
         "--listen", f"127.0.0.1:{port}", "--headless", "--size", "64x48", "--duration", "120", *extra],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1)
    end = time.monotonic() + START_DEADLINE_S
    lines = []
    while time.monotonic() < end:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if line.startswith("run: listening"):
            return proc
    proc.kill()
    proc.wait()
    pytest.fail("the run did not start listening:\n" + "".join(lines))


def receiver_children(pid: int) -> list[int]:
    """Pids of the receiving processes whose parent is ``pid`` (Linux /proc; not the resource tracker)."""
    with open(f"/proc/{pid}/task/{pid}/children") as f:
        children = [int(p) for p in f.read().split()]
    out = []
    for child in children:
        with open(f"/proc/{child}/cmdline", "rb") as f:
            if b"udp_child" in f.read():
                out.append(child)
    return out


def gone(pid: int) -> bool:
    """True when ``pid`` has exited (no such process, or a zombie awaiting its reaper)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        return True


def seconds_until_bindable(port: int) -> float | None:
    """Seconds until 127.0.0.1:port can be bound (None after FREE_DEADLINE_S)."""
    start = time.monotonic()
    while time.monotonic() - start < FREE_DEADLINE_S:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("127.0.0.1", port))
                return time.monotonic() - start
            except OSError:
                pass
        time.sleep(0.005)
    return None


@pytest.mark.slow
def test_the_port_is_free_soon_after_kill_9_while_the_tracker_floods(character):
    if not sys.platform.startswith("linux"):
        pytest.skip("reads /proc to find the receiving process")
    port = free_udp_port()
    proc = start_run(character, port)
    try:
        with Flood(port) as flood:
            children = receiver_children(proc.pid)
            assert len(children) == 1, children
            while flood.sent < 2000:  # the child is busy reading (it never times out)
                time.sleep(0.01)
            proc.kill()
            proc.wait(timeout=10)
            t_free = seconds_until_bindable(port)
            sent_then = flood.sent
            time.sleep(0.05)
            assert flood.sent > sent_then, "the tracker must still be sending"
            assert t_free is not None, f"port {port} still bound {FREE_DEADLINE_S} s after kill -9 of the run"
            print(f"port free {t_free * 1e3:.1f} ms after kill -9")
            assert gone(children[0])
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_sigterm_and_sigint_end_the_run_with_its_stats_and_a_complete_recording(character, tmp_path, signum):
    port = free_udp_port()
    record = tmp_path / "take.fps"
    proc = start_run(character, port, "--stats", "--record", str(record))
    try:
        with Flood(port) as flood:
            while flood.sent < 500:
                time.sleep(0.01)
            time.sleep(0.5)  # drawing by now (the GL context came after the listening line)
            os.kill(proc.pid, signum)
            out, _ = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, out
    assert "Traceback" not in out
    stats = json.loads(next(line for line in out.splitlines() if line.startswith("stats json: "))[12:])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a torn tail would warn
        session = read_session(record)
    assert session.complete
    assert len(session.packets) == stats["counters"]["record"]["packets_recorded"] > 0
    assert stats["counters"]["record"]["record_dropped"] == 0
