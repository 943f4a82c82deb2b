"""``run --web`` in this process on a synthetic VRM avatar, fed by a real VMC sender over UDP on 127.0.0.1.

The tests of the control API (tests/runtime/control) drive it with real WebSocket, OSC and Chromium clients.
"""

from __future__ import annotations

import argparse
import threading
import time
from contextlib import contextmanager

from pythonosc.udp_client import SimpleUDPClient

from facepuppet.runtime.bench.web import free_port as free_web_port
from facepuppet.runtime.commands import run

from helpers.udp_helpers import free_udp_port
from helpers.vmc_run import NO_SMOOTHING, send_vmc
from helpers.vrm_characters import preset_character


class WebRun:
    """A running ``run --web`` (see :func:`web_run`): its address, its ticks' weights, its result once stopped."""

    def __init__(self) -> None:
        self.port = 0
        self.ready = threading.Event()
        self.stop = threading.Event()
        self.ticks: list[tuple[int, float]] = []  # (k, t) of every drawn tick
        self.weights: list = []  # the weights drawn at each tick (copies)
        self.result = None
        self.error: BaseException | None = None
        self.character = None

    def weight(self, name: str) -> float:
        return float(self.weights[-1][self.character.shape_names.index(name)])

    def wait_for(self, predicate, timeout_s: float = 20.0, what: str = "") -> None:
        """Wait (for the run, not a measure) until ``predicate()``; AssertionError naming ``what`` otherwise."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if self.error is not None:
                raise self.error
            if predicate():
                return
            time.sleep(0.02)
        raise AssertionError(f"the run never showed {what}")


@contextmanager
def web_run(tmp_path, values: dict | None = None, extra: tuple = (), size: str = "64x48"):
    """Start ``run --input vmc --headless --web 127.0.0.1:PORT`` on :func:`preset_character` in a thread, sending
    ``values`` over VMC every 10 ms; yields a :class:`WebRun` once the first received frame is drawn."""
    character = preset_character()
    path = tmp_path / "avatar.npz"
    character.save(path)
    config = tmp_path / "live.toml"
    if not config.exists():
        config.write_text(NO_SMOOTHING)
    udp, web = free_udp_port(), free_web_port()
    parser = argparse.ArgumentParser()
    run.register(parser.add_subparsers())
    ns = parser.parse_args(["run", "-c", str(path), "--input", "vmc", "--listen", f"127.0.0.1:{udp}", "--headless",
                            "--receiver", "thread", "--size", size, "--duration", "120", "--config", str(config),
                            "--background", "transparent", "--web", f"127.0.0.1:{web}", *extra])
    state = WebRun()
    state.port, state.character = web, character

    def on_ready(address):
        def send():
            client = SimpleUDPClient("127.0.0.1", udp)
            while not state.stop.is_set():
                send_vmc(client, values or {"aa": 0.2})
                time.sleep(0.01)
        threading.Thread(target=send, daemon=True).start()

    def hook(info):
        state.ticks.append((info.k, info.t))
        state.weights.append(info.weights.copy())
        if info.raw is not None:
            state.ready.set()

    def go():
        try:
            state.result = run.run_live(ns, stop_event=state.stop, on_ready=on_ready, hooks=[hook], keep_weights=True)
        except BaseException as exc:  # handed to the test
            state.error = exc
            state.ready.set()

    thread = threading.Thread(target=go, name="web-run")
    thread.start()
    try:
        state.ready.wait(60.0)
        if state.error is not None:
            raise state.error
        yield state
    finally:
        state.stop.set()
        thread.join(60.0)
