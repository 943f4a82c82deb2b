"""VMC output as an independent receiver sees it: liblo's oscdump on 127.0.0.1."""

from __future__ import annotations

import math
import re
import shutil
import socket
import subprocess
import time

import numpy as np
import pytest
from pythonosc.osc_bundle import OscBundle

from facepuppet.runtime.channels import ARKIT_NAMES
from facepuppet.runtime.commands.options import parse_host_port
from facepuppet.runtime.live.vmc_out import MAX_BUNDLE, VmcSender

LINE = re.compile(r'^\S+ (?P<address>/\S+)(?: (?P<types>\S+))?(?: (?P<args>.*))?$')  # time tag, address, ...


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def oscdump_capture(make_sender, send, tmp_path, min_applies=1, timeout_s=10.0) -> list[tuple[str, list]]:
    """Run oscdump on a free port, ``sender = make_sender(port)``, call ``send(sender)`` until oscdump has
    printed ``min_applies`` Apply lines; the messages oscdump printed, as (address, args)."""
    exe = shutil.which("oscdump")
    if exe is None:
        pytest.skip("liblo's oscdump is not installed (Debian package liblo-tools; `make setup` installs it)")
    port = free_udp_port()
    out_path = tmp_path / "oscdump.txt"
    with open(out_path, "w") as out:
        # oscdump has no interface option (a host in its URL means multicast): it binds the port on all
        # interfaces; we only ever send to 127.0.0.1
        proc = subprocess.Popen([exe, "-L", str(port)], stdout=out, stderr=subprocess.STDOUT)
        sender = make_sender(port)
        try:
            deadline = time.monotonic() + timeout_s
            while time.monotonic() < deadline:
                send(sender)
                time.sleep(0.1)
                if out_path.read_text().count("/VMC/Ext/Blend/Apply") >= min_applies:
                    break
        finally:
            sender.close()
            proc.terminate()
            proc.wait(timeout=5)
    messages = []
    for line in out_path.read_text().splitlines():
        m = LINE.match(line.strip())
        if m:
            args = re.findall(r'"[^"]*"|\S+', m.group("args") or "")
            messages.append((m.group("address"), [a.strip('"') if a.startswith('"') else float(a) for a in args]))
    return messages


def last_tick(messages):
    """Messages of the last complete tick: from the Head bone before the last Apply to that Apply."""
    end = max(i for i, (a, _) in enumerate(messages) if a == "/VMC/Ext/Blend/Apply")
    start = max(i for i, (a, _) in enumerate(messages[:end]) if a == "/VMC/Ext/Bone/Pos")
    return messages[start:end + 1]


def test_oscdump_sees_pascal_case_names_values_apply_last_and_the_head(tmp_path):
    names = ("jawOpen", "eyeBlink_L", "mouthSmile_R", "browInnerUp")
    weights = np.array([0.5, 0.25, 0.875, 0.125])
    rotation = np.array([0.0, math.sin(0.2), 0.0, math.cos(0.2)])
    tick = last_tick(oscdump_capture(lambda port: VmcSender("127.0.0.1", port, names),
                                     lambda sender: sender.send(weights, rotation, [1.0, 2.0, 3.0]), tmp_path))
    head, *vals, apply = tick
    assert head[0] == "/VMC/Ext/Bone/Pos" and head[1][0] == "Head"
    np.testing.assert_allclose(head[1][1:], [-1.0, 2.0, 3.0, 0.0, -math.sin(0.2), 0.0, math.cos(0.2)], atol=1e-6)
    assert apply == ("/VMC/Ext/Blend/Apply", [])
    assert [v[1][0] for v in vals] == ["JawOpen", "EyeBlinkLeft", "MouthSmileRight", "BrowInnerUp"]
    assert all(v[0] == "/VMC/Ext/Blend/Val" for v in vals)
    np.testing.assert_allclose([v[1][1] for v in vals], weights, atol=1e-6)


def test_many_channels_split_into_bundles_under_1500_bytes_all_arriving(tmp_path):
    names = tuple(ARKIT_NAMES) + tuple(f"customExpressionWithALongName{i:03d}" for i in range(60))
    weights = np.linspace(0.0, 1.0, len(names))

    def make_sender(port):
        sender = VmcSender("127.0.0.1", port, names)
        assert len(sender.datagrams) >= 4 and all(len(d) < MAX_BUNDLE for d in sender.datagrams)
        sender.send(weights)
        parsed = [OscBundle(bytes(d)) for d in sender.datagrams]
        applies = [i for i, b in enumerate(parsed) for m in b if m.address == "/VMC/Ext/Blend/Apply"]
        assert applies == [len(parsed) - 1]  # one Apply, in the last bundle
        return sender

    tick = last_tick(oscdump_capture(make_sender, lambda sender: sender.send(weights), tmp_path))
    vals = {args[0]: args[1] for address, args in tick if address == "/VMC/Ext/Blend/Val"}
    assert len(vals) == len(names)
    assert vals["TongueOut"] == pytest.approx(weights[51], abs=1e-6)
    assert vals["CustomExpressionWithALongName059"] == pytest.approx(1.0, abs=1e-6)


def test_nan_weights_are_sent_as_zero_and_send_errors_are_counted():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))  # someone listens: no ICMP "port unreachable" to count
        sender = VmcSender("127.0.0.1", receiver.getsockname()[1], ("jawOpen",))
        sender.send(np.array([np.nan]))
        assert OscBundle(bytes(sender.datagrams[1])).content(0).params == ["JawOpen", 0.0]
        assert sender.counters == {"bundles_sent": 2, "send_errors": 0}
        sender.close()
        sender.send(np.array([0.5]))  # closed socket: counted, not raised
        assert sender.counters["send_errors"] == 2


def test_host_port_parsing():
    assert parse_host_port("127.0.0.1:39539") == ("127.0.0.1", 39539)
    assert parse_host_port("[::1]:9000") == ("::1", 9000)
    with pytest.raises(ValueError, match="--vmc-out: expected HOST:PORT"):
        parse_host_port("localhost")
    with pytest.raises(ValueError, match="--listen: expected HOST:PORT"):
        parse_host_port("1.2.3.4:70000", "--listen")


def test_the_sending_socket_is_bound_to_loopback_and_hears_only_its_destination():
    """Issue 17 §6: the socket was never bound, so the kernel gave it a port on 0.0.0.0 that anyone could reach."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as stranger:
        receiver.bind(("127.0.0.1", 0))
        stranger.bind(("127.0.0.1", 0))
        receiver.settimeout(5.0)
        sender = VmcSender("127.0.0.1", receiver.getsockname()[1], ("jawOpen",))
        try:
            local = sender._sock.getsockname()
            assert local[0] == "127.0.0.1" and local[1] != 0  # bound before the first send
            sender.send(np.array([0.5]))
            receiver.recvfrom(2048)
            # a datagram from another port first, then one from the destination: only the second gets in
            stranger.sendto(b"not for you", local)
            receiver.sendto(b"from the destination", local)
            sender._sock.settimeout(5.0)
            data, peer = sender._sock.recvfrom(2048)
            assert (data, peer) == (b"from the destination", receiver.getsockname())
            sender._sock.setblocking(False)
            with pytest.raises(BlockingIOError):
                sender._sock.recvfrom(2048)
        finally:
            sender.close()
