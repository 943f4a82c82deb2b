"""VMC output as independent receivers see it on 127.0.0.1: liblo's oscdump (a subprocess) and a UDP socket
read with python-osc. The expected values are worked out here from the documented rules (perfect-sync
PascalCase, split sides folded by their max, the VRM 0.x preset table), never read back from the sender."""

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

from facepuppet.runtime.commands.options import parse_host_port
from facepuppet.runtime.live.vmc_out import MAX_BUNDLE, VmcSender
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.mapping.vrm_names import VRM0_PRESETS

from helpers.udp_helpers import free_udp_port

LINE = re.compile(r'^\S+ (?P<address>/\S+)(?: (?P<types>\S+))?(?: (?P<args>.*))?$')  # time tag, address, ...


def oscdump_capture(make_sender, send, tmp_path, min_applies=2, timeout_s=10.0) -> list[tuple[str, list]]:
    """Run oscdump on a free port, ``sender = make_sender(port)``, call ``send(sender)`` until oscdump has
    printed ``min_applies`` Apply lines; the messages oscdump printed, as (address, args).

    Two by default: oscdump binds its port some time after it starts, and on a loaded machine the first
    tick's first datagrams can go out before that, leaving that tick incomplete; the second is whole."""
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
    """Messages of the last complete tick: from the OK before the last Apply to that Apply."""
    end = max(i for i, (a, _) in enumerate(messages) if a == "/VMC/Ext/Blend/Apply")
    start = max(i for i, (a, _) in enumerate(messages[:end]) if a == "/VMC/Ext/OK")
    return messages[start:end + 1]


# ICT-FaceKit's 57 shape names (the data kit's ict-facekit/*.obj): ARKit with _L/_R, browInnerUp and
# cheekPuff split, no tongueOut, four shapes outside ARKit
ICT_NAMES = (
    "PupilDilate_L", "PupilDilate_R", "browDown_L", "browDown_R", "browInnerUp_L", "browInnerUp_R",
    "browOuterUp_L", "browOuterUp_R", "cheekPuff_L", "cheekPuff_R", "cheekRaiser_L", "cheekRaiser_R",
    "cheekSquint_L", "cheekSquint_R", "eyeBlink_L", "eyeBlink_R", "eyeLookDown_L", "eyeLookDown_R",
    "eyeLookIn_L", "eyeLookIn_R", "eyeLookOut_L", "eyeLookOut_R", "eyeLookUp_L", "eyeLookUp_R",
    "eyeSquint_L", "eyeSquint_R", "eyeWide_L", "eyeWide_R", "jawForward", "jawLeft", "jawOpen", "jawRight",
    "mouthClose", "mouthDimple_L", "mouthDimple_R", "mouthFrown_L", "mouthFrown_R", "mouthFunnel", "mouthLeft",
    "mouthLowerDown_L", "mouthLowerDown_R", "mouthPress_L", "mouthPress_R", "mouthPucker", "mouthRight",
    "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper", "mouthSmile_L", "mouthSmile_R",
    "mouthStretch_L", "mouthStretch_R", "mouthUpperUp_L", "mouthUpperUp_R", "noseSneer_L", "noseSneer_R",
)
PRESETS = ("Blink", "Blink_L", "Blink_R", "A", "I", "U", "E", "O", "Joy", "Angry", "Sorrow", "Fun",
           "LookUp", "LookDown", "LookLeft", "LookRight", "Neutral")


def ict_weights(seed=3):
    """Distinct weights in [0.05, 0.95] for the ICT names, the two sides of the split shapes unequal."""
    w = np.random.default_rng(seed).uniform(0.05, 0.95, len(ICT_NAMES))
    return dict(zip(ICT_NAMES, w)), w


def expected_blend(by_name: dict) -> dict:
    """What a perfect-sync + VRM 0.x receiver should get for ICT weights, from the documented rules."""
    def sided(base):
        return by_name[base + "_L"], by_name[base + "_R"]

    want = {}
    for key in ARKIT_NAMES:
        name = key[0].upper() + key[1:]
        if key in ("browInnerUp", "cheekPuff"):
            want[name] = max(sided(key))  # split sides folded by their max
        elif key == "tongueOut":
            want[name] = 0.0  # ICT has none
        elif key.endswith(("Left", "Right")) and key not in ("jawLeft", "jawRight", "mouthLeft", "mouthRight"):
            base = key[:-4] if key.endswith("Left") else key[:-5]
            want[name] = by_name[base + ("_L" if key.endswith("Left") else "_R")]
        else:
            want[name] = by_name[key]

    def mean(base):
        return (want[base + "Left"] + want[base + "Right"]) / 2

    def clip(v):
        return min(max(v, 0.0), 1.0)

    left, right = want["EyeBlinkLeft"], want["EyeBlinkRight"]
    want.update({
        "Blink": min(left, right), "Blink_L": left - min(left, right), "Blink_R": right - min(left, right),
        "A": clip(want["JawOpen"] - 0.5 * want["MouthFunnel"] - 0.5 * want["MouthPucker"]),
        "I": clip(mean("MouthStretch") - 0.5 * want["MouthPucker"]),
        "U": clip(want["MouthPucker"] - 0.5 * want["JawOpen"]),
        "E": clip(0.5 * mean("MouthLowerDown") + 0.5 * mean("MouthStretch") - 0.5 * want["MouthFunnel"]),
        "O": want["MouthFunnel"], "Joy": mean("MouthSmile"), "Angry": mean("BrowDown"),
        "Sorrow": 0.5 * want["BrowInnerUp"] + 0.5 * mean("MouthFrown"), "Fun": mean("CheekSquint"),
        "LookUp": mean("EyeLookUp"), "LookDown": mean("EyeLookDown"),
        "LookLeft": (want["EyeLookOutLeft"] + want["EyeLookInRight"]) / 2,
        "LookRight": (want["EyeLookInLeft"] + want["EyeLookOutRight"]) / 2, "Neutral": 0.0,
    })
    return want


def test_oscdump_gets_the_52_perfect_sync_names_once_the_presets_and_the_status(tmp_path):
    """Issue 12 §2: ICT's split and extra shapes went out as BrowInnerUpLeft, CheekRaiserLeft ...; BrowInnerUp,
    CheekPuff and TongueOut never did."""
    by_name, weights = ict_weights()
    rotation = np.array([0.0, math.sin(0.2), 0.0, math.cos(0.2)])
    tick = last_tick(oscdump_capture(lambda port: VmcSender("127.0.0.1", port, ICT_NAMES),
                                     lambda sender: sender.send(weights, rotation, [1.0, 2.0, 3.0], t=12.5),
                                     tmp_path))
    ok, t, root, head, *vals, apply = tick
    assert ok == ("/VMC/Ext/OK", [1, 3, 0, 1])  # loaded, calibrated, normal mode, tracking
    assert t == ("/VMC/Ext/T", [12.5])
    assert root == ("/VMC/Ext/Root/Pos", ["root", 0, 0, 0, 0, 0, 0, 1])
    assert head[0] == "/VMC/Ext/Bone/Pos" and head[1][0] == "Head"
    np.testing.assert_allclose(head[1][1:], [-1.0, 2.0, 3.0, 0.0, -math.sin(0.2), 0.0, math.cos(0.2)], atol=1e-6)
    assert apply == ("/VMC/Ext/Blend/Apply", [])
    assert all(v[0] == "/VMC/Ext/Blend/Val" for v in vals)
    names = [v[1][0] for v in vals]
    pascal_arkit = [n[0].upper() + n[1:] for n in ARKIT_NAMES]
    assert sorted(names) == sorted(pascal_arkit + list(PRESETS))  # each exactly once, nothing else
    assert not {"BrowInnerUpLeft", "CheekPuffRight", "CheekRaiserLeft", "PupilDilateRight"} & set(names)
    got = {v[1][0]: v[1][1] for v in vals}
    want = expected_blend(by_name)
    for name in want:
        assert got[name] == pytest.approx(want[name], abs=1e-6), name


def test_python_osc_receiver_gets_complete_bundles_within_1200_bytes_apply_at_the_end():
    by_name, weights = ict_weights(seed=11)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(5.0)
        sender = VmcSender("127.0.0.1", receiver.getsockname()[1], ICT_NAMES, extra=True)
        try:
            sender.send(weights)
            n = len(sender.datagrams)
            datagrams = [receiver.recv(65536) for _ in range(n)]
        finally:
            sender.close()
    assert n >= 3 and all(len(d) <= 1200 for d in datagrams)
    bundles = [OscBundle(d) for d in datagrams]  # python-osc refuses anything but a complete bundle
    messages = [[(m.address, m.params) for m in b] for b in bundles]
    applies = [(i, j) for i, ms in enumerate(messages) for j, (a, _) in enumerate(ms) if a == "/VMC/Ext/Blend/Apply"]
    assert applies == [(n - 1, len(messages[-1]) - 1)]  # one Apply, last in the last bundle
    assert [a for a, _ in messages[0]] == ["/VMC/Ext/OK", "/VMC/Ext/T", "/VMC/Ext/Root/Pos", "/VMC/Ext/Bone/Pos"]
    vals = [p for ms in messages[1:] for a, p in ms if a == "/VMC/Ext/Blend/Val"]
    got = dict(vals)
    assert len(got) == len(vals) == 52 + 17 + 4  # names unique; --vmc-extra adds ICT's four non-ARKit shapes
    want = expected_blend(by_name)
    want.update({"CheekRaiserLeft": by_name["cheekRaiser_L"], "CheekRaiserRight": by_name["cheekRaiser_R"],
                 "PupilDilateLeft": by_name["PupilDilate_L"], "PupilDilateRight": by_name["PupilDilate_R"]})
    assert set(got) == set(want)
    for name in want:
        assert got[name] == pytest.approx(want[name], abs=1e-6), name


def test_extras_only_with_vmc_extra_and_said_at_start():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        port = receiver.getsockname()[1]
        plain = VmcSender("127.0.0.1", port, ICT_NAMES)
        extra = VmcSender("127.0.0.1", port, ICT_NAMES + ("Blink", "myShape"), extra=True)
        plain.close()
        extra.close()
    assert len(plain.sent_names) == 69 and "CheekRaiserLeft" not in plain.sent_names
    assert plain.held_back == ("PupilDilate_L", "PupilDilate_R", "cheekRaiser_L", "cheekRaiser_R")
    assert "not sent (not ARKit; --vmc-extra sends them): PupilDilate_L" in plain.describe()
    assert extra.sent_names[69:] == ("PupilDilateLeft", "PupilDilateRight", "CheekRaiserLeft", "CheekRaiserRight",
                                     "MyShape")
    assert extra.held_back == ("Blink",)  # would clash with the preset
    assert extra.sent_names.count("Blink") == 1


def test_presets_can_be_left_out_for_a_perfect_sync_avatar(tmp_path):
    names = tuple(ARKIT_NAMES)
    weights = np.linspace(0.0, 1.0, len(names))
    sender_args = {}

    def make_sender(port):
        sender = VmcSender("127.0.0.1", port, names, presets=False)
        sender_args["line"] = sender.describe()
        return sender

    tick = last_tick(oscdump_capture(make_sender, lambda sender: sender.send(weights), tmp_path))
    vals = {args[0]: args[1] for address, args in tick if address == "/VMC/Ext/Blend/Val"}
    assert len(vals) == 52 and not {"Blink", "Blink_L", "A", "Neutral"} & set(vals)
    assert vals["EyeBlinkLeft"] == pytest.approx(weights[ARKIT_NAMES.index("eyeBlinkLeft")], abs=1e-6)
    assert ("/VMC/Ext/Blend/Apply", []) in [(a, list(p)) for a, p in tick]
    assert "no VRM presets (--no-vmc-presets)" in sender_args["line"]


def test_many_long_channels_split_into_bundles_within_1200_bytes_all_arriving(tmp_path):
    names = tuple(ARKIT_NAMES) + tuple(f"customExpressionWithALongName{i:03d}" for i in range(60))
    weights = np.linspace(0.0, 1.0, len(names))

    def make_sender(port):
        sender = VmcSender("127.0.0.1", port, names, extra=True)
        assert len(sender.datagrams) >= 5 and all(len(d) <= MAX_BUNDLE == 1200 for d in sender.datagrams)
        return sender

    tick = last_tick(oscdump_capture(make_sender, lambda sender: sender.send(weights), tmp_path))
    vals = {args[0]: args[1] for address, args in tick if address == "/VMC/Ext/Blend/Val"}
    assert len(vals) == len(names) + 17
    assert vals["TongueOut"] == pytest.approx(weights[51], abs=1e-6)
    assert vals["CustomExpressionWithALongName059"] == pytest.approx(1.0, abs=1e-6)


def test_nan_weights_are_sent_as_zero_and_send_errors_are_counted():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))  # someone listens: no ICMP "port unreachable" to count
        sender = VmcSender("127.0.0.1", receiver.getsockname()[1], ("jawOpen",))
        sender.send(np.array([np.nan]))
        params = [m.params for m in OscBundle(bytes(sender.datagrams[1])) if m.address == "/VMC/Ext/Blend/Val"]
        assert ["JawOpen", 0.0] in params
        n = len(sender.datagrams)
        assert sender.counters == {"bundles_sent": n, "send_errors": 0}
        sender.close()
        sender.send(np.array([0.5]))  # closed socket: counted, not raised
        assert sender.counters == {"bundles_sent": n, "send_errors": n}


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


def one_tick(sender_args: dict, weights, expressions) -> dict[str, float]:
    """Blend/Val name -> value of one tick as a python-osc receiver on 127.0.0.1 reads it."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(5.0)
        sender = VmcSender("127.0.0.1", receiver.getsockname()[1], **sender_args)
        try:
            sender.send(np.asarray(weights, np.float32), expressions=expressions)
            datagrams = [receiver.recv(65536) for _ in range(len(sender.datagrams))]
        finally:
            sender.close()
    vals = [m.params for d in datagrams for m in OscBundle(d) if m.address == "/VMC/Ext/Blend/Val"]
    got = dict(vals)
    assert len(got) == len(vals), "a name sent twice"
    return got, sender


AVATAR = ("blink_left", "blink_right", "ah", "smile")  # a VRM 0.x avatar's morphs (no ARKit names)
OWN = ("Blink", "Blink_L", "Blink_R", "A", "Joy", "HideBlush")  # its expressions, as the sender names them


@pytest.mark.parametrize("mode", ["both", "vrm", "arkit"])
def test_vmc_names_send_the_avatars_own_expressions_with_the_values_drawn(mode):
    weights = [0.9, 0.4, 0.55, 0.0]
    expressions = np.array([0.4, 0.5, 0.0, 0.35, 0.0, 1.0], np.float32)
    got, sender = one_tick(dict(names=AVATAR, expressions=OWN, names_mode=mode), weights, expressions)
    if mode == "arkit":  # what an OBJ rig sends: the 52 (none of this avatar's morphs is ARKit) + the derived 17
        assert len(got) == 69 and got["Blink"] == 0.0 and got["A"] == 0.0 and "HideBlush" not in got
        assert "17 VRM presets" in sender.describe()
        return
    for name, value in zip(OWN, expressions.tolist()):
        assert got[name] == pytest.approx(value), name
    assert ("EyeBlinkLeft" in got) == (mode == "both") and len(got) == (52 if mode == "both" else 0) + len(OWN)
    assert "I" not in got and "Sorrow" not in got  # presets the avatar has not are not derived and sent
    assert f"--vmc-names {mode}" in sender.describe() and "the avatar's 6 VRM expressions" in sender.describe()


def test_vmc_names_without_expressions_sends_what_it_always_did_and_vrm_sends_the_derived_presets():
    weights = [0.3, 0.3, 0.6]
    plain, _ = one_tick(dict(names=("eyeBlink_L", "eyeBlink_R", "jawOpen")), weights, None)
    assert len(plain) == 69 and plain["Blink"] == pytest.approx(0.3) and plain["A"] == pytest.approx(0.6)
    vrm, _ = one_tick(dict(names=("eyeBlink_L", "eyeBlink_R", "jawOpen"), names_mode="vrm"), weights, None)
    assert set(vrm) == set(VRM0_PRESETS) and vrm["A"] == pytest.approx(0.6)


def test_vmc_names_is_checked():
    with pytest.raises(ValueError, match="--vmc-names: expected one of both, arkit, vrm"):
        VmcSender("127.0.0.1", free_udp_port(), AVATAR, names_mode="VRM")
    with pytest.raises(ValueError, match="--no-vmc-presets"):
        VmcSender("127.0.0.1", free_udp_port(), AVATAR, names_mode="vrm", presets=False)
