"""``run --record`` when the file cannot grow: the file-size limit (RLIMIT_FSIZE; Python ignores SIGXFSZ, so the
write fails with EFBIG, as it fails with ENOSPC on a full disk: one code path). The run stops, exits 1 with one
line saying what the file keeps, claims no recording, and the file reads whole and replays. A run under the same
limit without ``--record`` writes nothing and is not affected (the receiver's shared-memory ring that failed
there is gone)."""

from __future__ import annotations

import re
import resource
import socket
import subprocess
import sys
import threading
import warnings

import pytest

from facepuppet.runtime.recording.replay_source import open_recording
from facepuppet.runtime.recording.session import read_session

from helpers.osc_helpers import vmc_frame
from helpers.small_characters import sphere_character
from helpers.udp_helpers import free_udp_port

pytestmark = pytest.mark.gl  # the run draws headless (EGL)

LIMIT = 40_000  # bytes a process may write to one file: the header and a second or so of VMC packets
RUN_TIMEOUT_S = 180  # a fresh interpreter importing NumPy and making an EGL context on a loaded machine


@pytest.fixture(scope="module")
def character(tmp_path_factory):
    path = tmp_path_factory.mktemp("limits") / "sphere.npz"
    sphere_character().save(path)
    return path


def _file_size_limit() -> None:
    resource.setrlimit(resource.RLIMIT_FSIZE, (LIMIT, LIMIT))


def _run_limited(character, *extra: str) -> subprocess.CompletedProcess:
    """``facepuppet run`` under the file-size limit, VMC frames sent to it until it exits."""
    port = free_udp_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "facepuppet", "run", "-c", str(character), "--input", "vmc",
         "--listen", f"127.0.0.1:{port}", "--headless", "--size", "32x24", *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_file_size_limit)
    done = threading.Event()

    def send() -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            while not done.wait(0.002):
                s.sendto(vmc_frame(0.5), ("127.0.0.1", port))

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    try:
        out, err = proc.communicate(timeout=RUN_TIMEOUT_S)
    finally:
        done.set()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        sender.join(timeout=10)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def test_a_recording_over_the_file_size_limit_stops_the_run_with_exit_1_and_says_what_it_keeps(character, tmp_path):
    record = tmp_path / "take.fps"
    done = _run_limited(character, "--record", str(record), "--duration", "60", "--stats")
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr and "recorded to" not in done.stdout
    last = done.stderr.splitlines()[-1]
    found = re.fullmatch(rf"facepuppet run: error: {re.escape(str(record))}: the recording stopped: a write failed "
                         r"\(File too large\); the file keeps its first (\d+) records \((\d+) bytes: (\d+) ticks "
                         r"\([\d.]+ s of the run\), (\d+) packets\) and reads and replays up to there", last)
    assert found, last
    n_records, size, ticks, packets = map(int, found.groups())
    assert 0 < size <= LIMIT and record.stat().st_size == size  # cut back to its last whole record
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a torn tail would warn
        session = read_session(record)
    assert session.complete and session.n_records == n_records
    assert (len(session.ticks), len(session.packets)) == (ticks, packets) and packets > 0
    assert len(open_recording(record)) > 0  # and it replays
    stats = next(line for line in done.stdout.splitlines() if line.startswith("stats json: "))
    assert '"record_failed": 1' in stats


@pytest.mark.parametrize("receiver", ["process", "thread"])
def test_a_run_without_record_under_the_file_size_limit_is_not_affected(character, receiver):
    done = _run_limited(character, "--receiver", receiver, "--duration", "1.5", "--stats")
    assert done.returncode == 0, done.stderr
    for sign in ("Traceback", "KeyError", "resource_tracker", "File too large"):
        assert sign not in done.stderr
    assert re.search(r"frames received [1-9]", done.stdout), done.stdout
