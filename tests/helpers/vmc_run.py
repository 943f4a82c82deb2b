"""Drive ``run --input vmc --headless`` over real UDP on 127.0.0.1 with fixed VMC values and read what it drew.

Used by the expression tests (synthetic VRM-like characters) and the Godette tests (the real avatar).
"""

from __future__ import annotations

import argparse
import threading
import time

from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.udp_client import SimpleUDPClient

from facepuppet.runtime.commands import run

from helpers.logs import logged
from helpers.udp_helpers import free_udp_port

NO_SMOOTHING = "\n".join(f"[filter.{r}]\nmin_cutoff = 500.0\nbeta = 0.0" for r in ("eyes", "brows", "mouth", "other",
                                                                                  "head")) + \
    "\n[tracking_loss]\ntimeout_s = 30.0\n"
TICKS_WITH_FRAMES = 8  # the run stops once this many ticks have drawn a received frame


def send_vmc(client: SimpleUDPClient, values: dict, bones: dict | None = None) -> None:
    """One VMC frame: ``values`` as /VMC/Ext/Blend/Val + Apply, and ``bones`` {name: (x, y, z, qx, qy, qz, qw)}
    as /VMC/Ext/Bone/Pos (Unity's frame, as VMC senders write it)."""
    b = OscBundleBuilder(IMMEDIATELY)
    for name, pose in (bones or {}).items():
        m = OscMessageBuilder("/VMC/Ext/Bone/Pos")
        m.add_arg(name, "s")
        for v in pose:
            m.add_arg(float(v), "f")
        b.add_content(m.build())
    for name, value in values.items():
        m = OscMessageBuilder("/VMC/Ext/Blend/Val")
        m.add_arg(name, "s")
        m.add_arg(float(value), "f")
        b.add_content(m.build())
    b.add_content(OscMessageBuilder("/VMC/Ext/Blend/Apply").build())
    client.send(b.build())


def drive(character, values: dict, tmp_path, extra: tuple = (), bones: dict | None = None,
          size: str = "48x40"):
    """Run ``run --input vmc -c character.npz --headless`` and send ``values`` (and ``bones``) until enough ticks
    have drawn them; the run's result (its weight log) and its log lines."""
    path = tmp_path / "avatar.npz"
    character.save(path)
    config = tmp_path / "live.toml"
    config.write_text(NO_SMOOTHING)
    port = free_udp_port()
    parser = argparse.ArgumentParser()
    run.register(parser.add_subparsers())
    ns = parser.parse_args(["run", "-c", str(path), "--input", "vmc", "--listen", f"127.0.0.1:{port}", "--headless",
                          "--receiver", "thread",  # the receiver itself is tested elsewhere (both kinds)
                          "--size", size, "--duration", "60", "--config", str(config), *extra])
    stop, drawn = threading.Event(), []

    def on_ready(address):
        def send():
            client = SimpleUDPClient("127.0.0.1", port)
            while not stop.is_set():
                send_vmc(client, values, bones)
                time.sleep(0.01)
        threading.Thread(target=send, daemon=True).start()

    def hook(info):
        if info.raw is not None:
            drawn.append(info.k)
            if len(drawn) >= TICKS_WITH_FRAMES:
                stop.set()

    logs: list[str] = []
    try:
        with logged(logs):
            result = run.run_live(ns, stop_event=stop, on_ready=on_ready, hooks=[hook],
                                  keep_weights=True)
    finally:
        stop.set()
    assert len(drawn) >= TICKS_WITH_FRAMES, "the run ended before drawing the sent frames"
    return result, "\n".join(logs)


def last_weights(character, result) -> dict[str, float]:
    return {n: float(w) for n, w in zip(character.shape_names, result.weights.array[-1])}
