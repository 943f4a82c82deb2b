"""``facepuppet run`` end to end over real UDP on 127.0.0.1: python-osc and liblo's oscsend drive the face."""

from __future__ import annotations

import json
import math
import shutil
import socket
import subprocess
import sys
import threading
import time
import wave

import numpy as np
import pytest
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.udp_client import SimpleUDPClient

from facepuppet.runtime.cli import main
from facepuppet.runtime.inputs.osc import CALIBRATE_ADDRESS
from facepuppet.runtime.recording.replay_source import open_recording
from facepuppet.runtime.recording.session import read_session

from helpers.logs import said
from helpers.small_characters import sphere_character
from helpers.udp_helpers import free_udp_port, wait_for

FAST_CONFIG = """
[filter.mouth]
min_cutoff = 200.0   # next to no smoothing: the test reads the sent values back
[tracking_loss]
timeout_s = 30.0     # the senders' gaps must not count as tracking loss here
"""


@pytest.fixture(scope="module")
def character(tmp_path_factory):
    path = tmp_path_factory.mktemp("run") / "sphere.npz"
    sphere_character().save(path)
    return path


def python_osc_jaw(client: SimpleUDPClient, jaw: float) -> None:
    b = OscBundleBuilder(IMMEDIATELY)
    m = OscMessageBuilder("/VMC/Ext/Blend/Val")
    m.add_arg("JawOpen", "s")
    m.add_arg(jaw, "f")
    b.add_content(m.build())
    b.add_content(OscMessageBuilder("/VMC/Ext/Blend/Apply").build())
    client.send(b.build())


@pytest.mark.gl
@pytest.mark.slow
def test_run_end_to_end_python_osc_then_oscsend(character, tmp_path, capsys):
    oscsend = shutil.which("oscsend")
    if oscsend is None:
        pytest.skip("liblo's oscsend is not installed (Debian package liblo-tools; `make setup` installs it)")
    port = free_udp_port()
    config = tmp_path / "live.toml"
    config.write_text(FAST_CONFIG)
    done = threading.Event()
    counts = {"python_osc": 0, "oscsend": 0}

    def senders():
        client = SimpleUDPClient("127.0.0.1", port)
        end = time.monotonic() + 60  # phase 1: python-osc bundles, jaw 0.7, until the loop has drawn a while
        while time.monotonic() < end and not done.is_set():
            python_osc_jaw(client, 0.7)
            counts["python_osc"] += 1
            time.sleep(0.01)
            if pngs.is_dir() and len(list(pngs.glob("frame_*.png"))) >= 10:
                end = min(end, time.monotonic() + 0.3)
        while not done.is_set():  # phase 2: liblo, separate Val and Apply datagrams, jaw 0.25
            for args in (["/VMC/Ext/Blend/Val", "sf", "JawOpen", "0.25"], ["/VMC/Ext/Blend/Apply"]):
                subprocess.run([oscsend, "127.0.0.1", str(port), *args], check=True, timeout=10)
                counts["oscsend"] += 1
            if counts["oscsend"] >= 400:
                break

    thread = threading.Thread(target=senders, daemon=True)
    weights_path, record, pngs = tmp_path / "w.npy", tmp_path / "live.fps", tmp_path / "png"
    thread.start()
    try:
        code = main(["run", "-c", str(character), "--input", "vmc", "--listen", f"127.0.0.1:{port}", "--headless",
                     "--duration", "2.0", "--size", "160x120", "--config", str(config), "--stats",
                     "--dump-weights", str(weights_path), "--record", str(record), "--out", str(pngs),
                     "--audio", "no-such-microphone-4242"])
    finally:
        done.set()
        thread.join(timeout=30)
    out = said(capsys)
    assert code == 0, out
    assert "no audio" in out and "no-such-microphone-4242" in out  # and the run went on
    stats = json.loads(next(line for line in out.splitlines() if line.startswith("stats json: "))[12:])
    udp = stats["counters"]["udp"]
    assert udp["packets"] >= 10 and udp["malformed"] == 0 and udp["filtered_sender"] == 0
    assert stats["latency_ms"]["end_to_end"]["n"] > 0
    assert counts["python_osc"] > 0 and counts["oscsend"] >= 2
    w = np.load(weights_path)
    assert w.shape[1] == 2 and len(w) > 30 and len(list(pngs.glob("frame_*.png"))) == len(w)
    jaw = w[:, 0]
    assert np.any(np.abs(jaw - 0.7) < 1e-3), "python-osc's value was never drawn"
    assert jaw[-1] == pytest.approx(0.25, abs=1e-3), "oscsend's value is not the last drawn"
    np.testing.assert_array_equal(w[:, 1], 0.0)  # puff: no VMC channel drives it
    frames = open_recording(record)  # the recording replays to the values that were sent
    values = {round(float(f.weights[f.channels.index("jawOpen")]), 4) for f in frames}
    assert values == {0.7, 0.25}
    assert len(read_session(record).packets) == udp["packets"]


@pytest.mark.gl
def test_audio_file_levels_are_recorded_per_tick(character, tmp_path, capsys):
    rate = 48000
    samples = 0.5 * np.sin(2 * np.pi * 600 * np.arange(rate) / rate)
    wav = tmp_path / "tone.wav"
    with wave.open(str(wav), "wb") as f:
        f.setnchannels(1)
        f.setsampwidth(2)
        f.setframerate(rate)
        f.writeframes((samples * 32767).astype("<i2").tobytes())
    record = tmp_path / "audio.fps"
    code = main(["run", "-c", str(character), "--input", "vmc", "--listen", f"127.0.0.1:{free_udp_port()}",
                 "--headless", "--duration", "0.5", "--size", "64x48", "--audio-file", str(wav),
                 "--record", str(record)])
    assert code == 0, capsys.readouterr().out
    levels = read_session(record).audio_levels
    assert len(levels) >= 5
    assert levels[-1][1] == pytest.approx(20 * math.log10(0.5 / math.sqrt(2)), abs=0.1)
    assert all(t1 > t0 for (t0, _), (t1, _) in zip(levels, levels[1:]))


@pytest.mark.parametrize("receiver", ["process", "thread"])
def test_the_receivers_count_calibrate_messages_and_only_those(udp_sender, receiver):
    from facepuppet.runtime.inputs.udp import UdpSource
    from facepuppet.runtime.inputs.udp_process import UdpProcessSource
    from facepuppet.runtime.inputs.vmc import VmcAdapter

    kind = UdpProcessSource if receiver == "process" else UdpSource
    with kind(VmcAdapter(), port=0, watch=CALIBRATE_ADDRESS) as source:
        udp_sender.sendto(b"/VMC/Ext/Blend/Apply\x00\x00\x00\x00,\x00\x00\x00", source.address)
        m = OscMessageBuilder("/facepuppet/calibrate").build().dgram
        assert m.startswith(CALIBRATE_ADDRESS.encode())
        udp_sender.sendto(m, source.address)
        wait_for(lambda: source.counters["packets"] == 2, "both datagrams")
        assert source.watched == 1


@pytest.mark.parametrize("option, value, match", [
    ("--listen", "nowhere", "--listen: expected HOST:PORT"),
    ("--allow", "10.0.0.300", "--allow: expected comma-separated IP addresses, got '10.0.0.300'"),
    ("--vmc-out", "127.0.0.1", "--vmc-out: expected HOST:PORT"),
    ("--fps", "0", "--fps: expected a positive number"),
    ("--vmc-extra", "--draw=tick", "--vmc-extra: needs --vmc-out HOST:PORT"),
    ("--no-vmc-presets", "--draw=tick", "--no-vmc-presets: needs --vmc-out HOST:PORT"),
])
def test_bad_options_exit_2_with_a_message(character, capsys, option, value, match):
    code = main(["run", "-c", str(character), "--input", "vmc", "--headless", "--duration", "0.1", option, value])
    assert code == 2
    assert match in capsys.readouterr().err


@pytest.mark.gl
def test_run_vmc_out_sends_perfect_sync_and_presets_and_says_so(character, capsys):
    """Issue 12 §2 end to end: the sphere's jawOpen goes out as JawOpen with the 51 other ARKit names and the
    presets; its own shape "puff" is held back without --vmc-extra, and the start line says so."""
    from pythonosc.osc_bundle import OscBundle

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(0.0)
        code = main(["run", "-c", str(character), "--input", "vmc", "--listen", f"127.0.0.1:{free_udp_port()}",
                     "--headless", "--duration", "0.5", "--size", "64x48", "--draw", "tick", "--fps", "20",
                     "--vmc-out", f"127.0.0.1:{receiver.getsockname()[1]}"])
        datagrams = []
        while True:
            try:
                datagrams.append(receiver.recv(65536))
            except BlockingIOError:
                break
    out = said(capsys)
    assert code == 0, out
    assert "vmc-out: 127.0.0.1:" in out and "52 ARKit (perfect sync) + 17 VRM presets" in out
    assert "not sent (not ARKit; --vmc-extra sends them): puff" in out
    assert datagrams and all(len(d) <= 1200 for d in datagrams)
    messages = [(m.address, m.params) for d in datagrams for m in OscBundle(d)]
    end = max(i for i, (a, _) in enumerate(messages) if a == "/VMC/Ext/Blend/Apply")
    start = max(i for i, (a, _) in enumerate(messages[:end]) if a == "/VMC/Ext/OK")
    names = [p[0] for a, p in messages[start:end] if a == "/VMC/Ext/Blend/Val"]
    assert len(names) == len(set(names)) == 69 and {"JawOpen", "TongueOut", "A", "Blink_L"} <= set(names)
    assert "Puff" not in names


def test_busy_port_is_a_message_not_a_traceback(character, capsys):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("127.0.0.1", 0))
        port = busy.getsockname()[1]
        code = main(["run", "-c", str(character), "--input", "vmc", "--listen", f"127.0.0.1:{port}",
                     "--headless", "--duration", "0.1"])
    assert code == 2
    assert f"127.0.0.1:{port}" in capsys.readouterr().err


@pytest.mark.gl
@pytest.mark.parametrize("receiver", ["process", "thread"])
def test_both_receivers_record_every_packet_and_see_the_calibrate_message(character, tmp_path, receiver):
    from types import SimpleNamespace

    from facepuppet.runtime.commands.run import run_live

    record = tmp_path / f"{receiver}.fps"
    stop = threading.Event()
    sent = []

    def on_ready(address):
        def send():
            client = SimpleUDPClient(*address)
            client.send_message("/facepuppet/calibrate", [])
            for jaw in np.linspace(0.1, 0.6, 80):  # > capture_s (0.5 s) of frames after the first message
                python_osc_jaw(client, float(jaw))
                sent.append(float(jaw))
                time.sleep(0.01)
            time.sleep(0.3)
            stop.set()
        threading.Thread(target=send, daemon=True).start()

    config = tmp_path / "live.toml"
    config.write_text(FAST_CONFIG)
    args = SimpleNamespace(
        character=character, input="vmc", listen=f"127.0.0.1:{free_udp_port()}", allow=None, config=config,
        calibrate=False, audio=None, audio_file=None, record=record, vmc_out=None, stats=False, headless=True,
        out=None, dump_weights=None, size="64x48", fps=60.0, duration=30.0, path="auto", receiver=receiver)
    result = run_live(args, stop_event=stop, on_ready=on_ready)
    assert stop.is_set(), "the run ended before the sender"
    udp = result.counters["udp"]
    assert udp["packets"] == len(sent) + 1 == 81 and udp["internal_error"] == 0
    assert "waited_over_1ms" in udp
    assert result.counters["pipeline"]["calibrations"] >= 1  # the calibrate message reached the pipeline
    assert len(read_session(record).packets) == 81
    assert result.weights is None  # no --dump-weights: no per-tick weight log (a show runs for hours)


def test_unknown_receiver_is_refused(character):
    from types import SimpleNamespace

    from facepuppet.runtime.commands.run import run_live

    with pytest.raises(ValueError, match="--receiver: expected one of"):
        run_live(SimpleNamespace(receiver="fiber"))


def _strict_json(text: str):
    """JSON as strict parsers read it: NaN and Infinity are not JSON."""
    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")
    return json.loads(text, parse_constant=refuse)


@pytest.mark.gl
def test_stats_json_is_strict_and_counts_kernel_drops_per_source(character, capsys):
    """No sender: nothing was measured, written null (it was NaN, which strict parsers refuse); each input's
    receiver has its kernel drop count (0 here on Linux: the kernel reports it; null where it does not)."""
    ports = free_udp_port(), free_udp_port()
    code = main(["run", "-c", str(character), "--input", "vmc", "--input", "vmc", "--listen", f"127.0.0.1:{ports[0]}",
                 "--listen", f"127.0.0.1:{ports[1]}", "--headless", "--duration", "0.3", "--size", "32x24", "--stats"])
    out = said(capsys)
    assert code == 0, out
    stats = _strict_json(next(line for line in out.splitlines() if line.startswith("stats json: "))[12:])
    assert stats["latency_ms"]["end_to_end"] == {"n": 0, "p50_ms": None, "p99_ms": None, "max_ms": None}
    expected = 0 if sys.platform.startswith("linux") else None
    assert stats["counters"]["udp"]["kernel_dropped"] == stats["counters"]["udp:vmc#2"]["kernel_dropped"] == expected
