"""``--llf-out``: Live Link Face v6 packets out (PROTOCOLS.md §5), checked against the published layout
built here byte by byte, against our own decoder, over real UDP on 127.0.0.1 and into ``run --input
livelinkface``."""

from __future__ import annotations

import math
import re
import struct
import threading

import numpy as np
import pytest

from facepuppet.runtime.cli import main
from facepuppet.runtime.inputs.livelinkface import LiveLinkFaceAdapter
from facepuppet.runtime.live.llf_out import EYE_PITCH_MAX, EYE_YAW_MAX, LlfSender, device_id
from facepuppet.runtime.mapping.channels import ARKIT_NAMES, pascal
from facepuppet.runtime.model.geometry import euler_to_quat, quat_to_euler, quat_to_matrix

from helpers.logs import said
from helpers.small_characters import sphere_character
from helpers.udp_helpers import drain, free_udp_port, wait_for


def published_packet(values61, name: bytes, uuid: bytes, number: int, sub: float, fps: int, den: int) -> bytes:
    """§5's layout, field by field: version int32 LE = 6, 37-byte id, name length int32 BE, name, frame number
    int32, sub-frame float32, fps int32, denominator int32 (BE), count uint8 = 61, 61 float32 BE."""
    assert len(uuid) == 37 and uuid[:1] == b"$" and len(values61) == 61
    out = bytearray()
    out += (6).to_bytes(4, "little", signed=True)
    out += uuid
    out += len(name).to_bytes(4, "big", signed=True) + name
    out += number.to_bytes(4, "big", signed=True) + struct.pack(">f", sub)
    out += fps.to_bytes(4, "big", signed=True) + den.to_bytes(4, "big", signed=True)
    out += bytes([61])
    for v in values61:
        out += struct.pack(">f", v)
    return bytes(out)


def r_yxz(yaw, pitch, roll):
    """R = Ry(yaw) Rx(pitch) Rz(roll) from the three plain rotation matrices."""
    cy, sy, cp, sp, cr, sr = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch), math.cos(roll), \
        math.sin(roll)
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    rz = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
    return ry @ rx @ rz


def test_quat_to_euler_inverts_euler_to_quat_and_reads_the_matrix_order():
    rng = np.random.default_rng(3)
    for yaw, pitch, roll in rng.uniform([-3.1, -1.5, -3.1], [3.1, 1.5, 3.1], size=(200, 3)):
        q = euler_to_quat(yaw, pitch, roll)
        np.testing.assert_allclose(quat_to_matrix(q), r_yxz(yaw, pitch, roll), atol=1e-12)
        np.testing.assert_allclose(quat_to_euler(q), (yaw, pitch, roll), atol=1e-9)
        np.testing.assert_allclose(quat_to_euler(-3.0 * q), (yaw, pitch, roll), atol=1e-9)  # sign, scale
    assert quat_to_euler((0.0, 0.0, 0.0, 1.0)) == (0.0, 0.0, 0.0)


def test_packet_is_the_published_layout_byte_for_byte(udp_receiver):
    """Rig channels named as ARKit (any spelling) go out unchanged: the packet equals one built from §5."""
    rng = np.random.default_rng(0)
    names = [pascal(n) for n in ARKIT_NAMES]  # the PascalCase of Live Link Face itself
    weights = rng.uniform(0, 1, 52).astype(np.float32)
    yaw, pitch, roll = 0.3, -0.2, 0.1
    sender = LlfSender("127.0.0.1", udp_receiver.getsockname()[1], names, subject="Stage Left")
    try:
        t = 12.3456
        sent = bytes(sender.encode(weights, euler_to_quat(yaw, pitch, roll), t))
    finally:
        sender.close()
    w = weights.astype(np.float64)
    eyes = (EYE_YAW_MAX * (w[3] - w[2]), EYE_PITCH_MAX * (w[1] - w[4]), 0.0,
            EYE_YAW_MAX * (w[9] - w[10]), EYE_PITCH_MAX * (w[8] - w[11]), 0.0)
    number = int(t * 60)
    sub = t * 60 - number
    expected = published_packet(list(w) + [yaw, pitch, roll, *eyes], b"Stage Left", device_id("Stage Left").encode(),
                                number, sub, 60, 1)
    assert len(sent) == 306 + len(b"Stage Left")
    # float32 of the same doubles: the head angles pass through a quaternion, so allow their last bit
    assert sent[:45 + 10 + 17] == expected[:45 + 10 + 17]
    got = np.array(struct.unpack_from(">61f", sent, 45 + 10 + 17))
    want = np.array(struct.unpack_from(">61f", expected, 45 + 10 + 17))
    np.testing.assert_array_equal(got[:52], want[:52])
    np.testing.assert_allclose(got[52:], want[52:], atol=1e-6)


def test_our_decoder_reads_what_we_send_and_the_fold():
    """Encode -> decode: the rig's channels folded into ARKit's 52 (split browInnerUp by the max, unsided
    eyeBlink on both sides, a shape the rig lacks 0, an extra left out), clipped, NaN as 0; head; time."""
    names = ("jawOpen", "browInnerUp_L", "browInnerUp_R", "eyeBlink", "mouthSmile_L", "cheekRaiser_L", "tongueOut")
    weights = np.array([0.6, 0.2, 0.7, 0.4, 1.5, 0.9, np.nan], dtype=np.float32)
    q = euler_to_quat(-0.4, 0.25, 0.05)
    sender = LlfSender("127.0.0.1", free_udp_port(), names)
    try:
        packet = bytes(sender.encode(weights, q, t=2.5))
    finally:
        sender.close()
    adapter = LiveLinkFaceAdapter()
    frame = adapter.handle(packet, 7.0)
    assert adapter.counters["frames"] == 1 and adapter.device_name == "facepuppet"
    got = dict(zip(frame.channels, frame.weights.tolist()))
    assert got["jawOpen"] == pytest.approx(0.6) and got["browInnerUp"] == pytest.approx(0.7)
    assert got["eyeBlinkLeft"] == got["eyeBlinkRight"] == pytest.approx(0.4)
    assert got["mouthSmileLeft"] == 1.0 and got["mouthSmileRight"] == 0.0  # clipped; the rig has one side
    assert got["tongueOut"] == 0.0  # NaN (not sent) goes out as 0
    assert sum(1 for v in got.values() if v != 0) == 5  # cheekRaiser_L is no ARKit shape: not in the packet
    np.testing.assert_allclose(np.abs(frame.head_rotation @ q), 1.0, atol=1e-6)  # the same rotation
    assert frame.number == 150 and frame.t_sender == pytest.approx(2.5)
    assert "tongueOut" not in sender.missing and "jawLeft" in sender.missing


def test_eye_angles_follow_the_gaze_weights():
    names = ("eyeLookOutLeft", "eyeLookInRight", "eyeLookDownLeft", "eyeLookUpRight")
    sender = LlfSender("127.0.0.1", free_udp_port(), names)
    try:
        packet = bytes(sender.encode(np.array([1.0, 0.5, 0.2, 1.0], np.float32)))
    finally:
        sender.close()
    eyes = struct.unpack_from(">6f", packet, len(packet) - 24)
    # both eyes look to the character's own left (positive yaw); left eye a little down, right eye up
    np.testing.assert_allclose(eyes, (EYE_YAW_MAX, 0.2 * EYE_PITCH_MAX, 0, 0.5 * EYE_YAW_MAX, -EYE_PITCH_MAX, 0),
                               rtol=1e-6)


def test_sends_over_udp_on_loopback_and_counts(udp_receiver):
    port = udp_receiver.getsockname()[1]
    sender = LlfSender("127.0.0.1", port, ("jawOpen",))
    try:
        for i in range(5):
            sender.send(np.array([i / 10], np.float32), None, t=i / 60)
        got = [udp_receiver.recv(65536) for _ in range(5)]
    finally:
        sender.close()
    assert sender.counters == {"packets_sent": 5, "send_errors": 0}
    adapter = LiveLinkFaceAdapter()
    frames = [adapter.handle(d, 0.0) for d in got]
    assert [round(float(f.weights[17]), 6) for f in frames] == [0.0, 0.1, 0.2, 0.3, 0.4]
    assert [f.number for f in frames] == [0, 1, 2, 3, 4]
    assert adapter.counters["malformed"] == 0


def test_a_send_error_is_counted_not_raised():
    """Nothing listens there: the kernel's port-unreachable answer makes a later send fail; the run goes on."""
    sender = LlfSender("127.0.0.1", free_udp_port(), ("jawOpen",))
    try:
        wait_for(lambda: sender.send(np.zeros(1, np.float32)) or sender.counters["send_errors"] > 0,
                 "a refused send")
    finally:
        sender.close()
    assert sender.counters["packets_sent"] >= 1


@pytest.mark.parametrize("value", ["127.0.0.1", "127.0.0.1:0", "127.0.0.1:70000", ":11111", "127.0.0.1:port"])
@pytest.mark.parametrize("command", ["run", "replay"])
def test_a_bad_host_port_is_refused_before_anything_opens(tmp_path, capsys, command, value):
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    argv = (["run", "-c", str(character), "--input", "livelinkface", "--headless", "--duration", "0.1"]
            if command == "run" else ["replay", str(tmp_path / "none.csv"), "-c", str(character), "--headless"])
    assert main([*argv, "--llf-out", value]) == 2
    assert f"--llf-out: expected HOST:PORT such as 127.0.0.1:39539, got {value!r}" in capsys.readouterr().err


NO_SMOOTHING = "\n".join(f"[filter.{r}]\nmin_cutoff = 500.0\nbeta = 0.0" for r in
                         ("eyes", "brows", "mouth", "other", "head")) + "\n[tracking_loss]\ntimeout_s = 30.0\n"


@pytest.mark.gl
def test_round_trip_into_run_input_livelinkface(tmp_path):
    """Our sender, over real UDP on 127.0.0.1, into ``run --input livelinkface``: the run draws what was sent."""
    from types import SimpleNamespace

    from facepuppet.runtime.commands.run import run_live

    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    config = tmp_path / "live.toml"
    config.write_text(NO_SMOOTHING)
    stop = threading.Event()
    sent: list[float] = []
    rotation = euler_to_quat(0.2, -0.1, 0.0)

    rotations: list[np.ndarray] = []
    taken: list[float] = []  # jawOpen of each new frame the run's ticks took, as decoded (before the filter)

    def watch(info):
        if info.raw is not None:
            taken.append(float(info.raw.weights[info.raw.channels.index("jawOpen")]))
            rotations.append(np.asarray(info.raw.head_rotation, dtype=np.float64))

    def on_ready(address):
        def send():
            sender = LlfSender(*address, ARKIT_NAMES)
            try:
                for i, jaw in enumerate(np.linspace(0.05, 0.8, 40)):
                    w = np.zeros(52, np.float32)
                    w[17] = jaw
                    sender.send(w, rotation, t=i / 60)
                    sent.append(float(np.float32(jaw)))
                    # explicit synchronisation: the next packet only once a tick has taken this one
                    n_sent = len(sent)
                    wait_for(lambda n=n_sent: len(taken) >= n, f"the run to take packet {i}")
            finally:
                sender.close()
                stop.set()
        threading.Thread(target=send, daemon=True).start()

    args = SimpleNamespace(
        character=character, input="livelinkface", listen=f"127.0.0.1:{free_udp_port()}", allow=None,
        config=config, calibrate=False, audio=None, audio_file=None, record=None, vmc_out=None, stats=False,
        headless=True, out=None, dump_weights=None, size="48x40", fps=60.0, duration=30.0, path="auto",
        udp_receiver="thread")
    result = run_live(args, stop_event=stop, on_ready=on_ready, keep_weights=True,
                      hooks=[watch])
    assert stop.is_set() and len(sent) == 40
    udp = result.counters["udp"]
    assert udp["packets"] == udp["frames"] == 40 and udp["malformed"] == 0 and udp["nonfinite"] == 0
    assert taken == sent  # every packet decoded by the run to the value sent, in order
    np.testing.assert_allclose(np.abs(np.stack(rotations) @ rotation), 1.0, atol=1e-6)
    drawn = result.weights.array[:, 0]  # the sphere's jawOpen after the (near transparent) filter
    assert np.all(np.diff(drawn) >= -1e-6) and drawn[-1] == pytest.approx(sent[-1], abs=0.02)


@pytest.mark.gl
def test_run_llf_out_sends_one_packet_a_tick_and_says_so(tmp_path, udp_receiver, capsys):
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    code = main(["run", "-c", str(character), "--input", "vmc", "--listen", f"127.0.0.1:{free_udp_port()}",
                 "--headless", "--duration", "0.5", "--size", "48x40", "--draw", "tick", "--fps", "20", "--stats",
                 "--llf-out", f"127.0.0.1:{udp_receiver.getsockname()[1]}"])
    out = said(capsys)
    assert code == 0, out
    assert "llf-out: 127.0.0.1:" in out and "subject 'facepuppet'" in out
    assert "51 ARKit shapes the character lacks sent as the input gives them" in out  # the sphere: jawOpen, "puff"
    n_ticks = int(re.search(r"run: (\d+) ticks", out).group(1))
    datagrams = drain(udp_receiver)
    # one packet per drawn tick; a live run skips a tick it is late for (a loaded machine), so the count is
    # what the run reports, at most the 11 ticks of 0.5 s at 20 fps, and each packet's frame number is its
    # tick's time on the 60 fps timecode (3 per tick at 20 fps)
    assert len(datagrams) == n_ticks and 6 <= n_ticks <= 11
    adapter = LiveLinkFaceAdapter()
    frames = [adapter.handle(d, 0.0) for d in datagrams]
    numbers = [f.number for f in frames]
    assert adapter.counters["frames"] == n_ticks and numbers[0] == 0 and all(n % 3 == 0 for n in numbers)
    assert all(b > a for a, b in zip(numbers, numbers[1:])) and numbers[-1] <= 30
    assert f'"llf_out": {{"packets_sent": {n_ticks}, "send_errors": 0}}' in out


@pytest.mark.gl
def test_replay_llf_out_sends_the_takes_values(tmp_path, udp_receiver, capsys):
    """A Live Link Face CSV take replayed out as packets: the same values come back through our decoder."""
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    take = tmp_path / "take.csv"
    names = [pascal(n) for n in ARKIT_NAMES]
    rows = ["Timecode,BlendShapeCount," + ",".join(names)]
    jaws = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]
    for i, jaw in enumerate(jaws):
        values = ["0"] * 52
        values[17] = str(jaw)
        rows.append(f"00:00:01:{i * 6:02d}.000,52," + ",".join(values))
    take.write_text("\n".join(rows) + "\n")
    dumped = tmp_path / "w.npy"
    code = main(["replay", str(take), "-c", str(character), "--headless", "--size", "48x40", "--fps", "10",
                 "--llf-out", f"127.0.0.1:{udp_receiver.getsockname()[1]}", "--dump-weights", str(dumped)])
    out = said(capsys)
    assert code == 0, out
    assert "(paced to real time)" in out
    adapter = LiveLinkFaceAdapter()
    got = [float(adapter.handle(d, 0.0).weights[17]) for d in drain(udp_receiver)]
    drawn = np.load(dumped)[:, 0]
    assert len(got) == len(drawn) == 6  # one packet a tick, each with the tick's drawn jawOpen
    np.testing.assert_array_equal(np.float32(got), drawn)
    assert set(np.round(got, 5)) <= set(jaws) and len(set(np.round(got, 5))) >= 4


def _take_csv(path, n=6):
    """A Live Link Face CSV whose every channel moves (channel k at row i: (k + i) / 60)."""
    rows = ["Timecode,BlendShapeCount," + ",".join(pascal(n) for n in ARKIT_NAMES)]
    for i in range(n):
        rows.append(f"00:00:01:{i * 6:02d}.000,52," + ",".join(f"{(k + i) / 60:.6f}" for k in range(52)))
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.mark.gl
def test_replay_llf_out_sends_the_input_where_the_character_has_no_arkit_shape(tmp_path, udp_receiver, capsys):
    """A character without ARKit shapes (a plain VRM avatar) cannot answer for the face: what goes out is the
    input's face, not 52 zeros; where it has a shape (jawOpen here) it is what was drawn."""
    import dataclasses

    character = tmp_path / "blob.npz"
    dataclasses.replace(sphere_character(), shape_names=("jawOpen", "blobWiden")).save(character)
    take = _take_csv(tmp_path / "take.csv")
    code = main(["replay", str(take), "-c", str(character), "--headless", "--size", "48x40",
                 "--llf-out", f"127.0.0.1:{udp_receiver.getsockname()[1]}"])
    out = said(capsys)
    assert code == 0, out
    assert "51 ARKit shapes the character lacks sent as the input gives them (0 where it lacks them too): " \
           "eyeBlinkLeft" in out
    adapter = LiveLinkFaceAdapter()
    got = np.array([adapter.handle(d, 0.0).weights for d in drain(udp_receiver)])
    assert got.shape == (6, 52)
    expected = (np.arange(52)[None, :] + np.arange(6)[:, None]) / 60
    np.testing.assert_allclose(got, expected, atol=1e-6)


def test_the_input_fills_only_what_the_rig_lacks_and_nan_or_absent_input_is_0():
    from facepuppet.runtime.frames import Frame

    sender = LlfSender("127.0.0.1", free_udp_port(), ["jawOpen"])
    try:
        frame = Frame(t=0.0, source="t", channels=("JawOpen", "eyeBlink_L", "mouthSmile_R", "cheekPuff"),
                      weights=np.array([0.9, 0.25, 0.5, np.nan], np.float32))
        adapter = LiveLinkFaceAdapter()
        got = adapter.handle(bytes(sender.encode(np.array([0.3], np.float32), frame=frame)), 0.0).weights
        index = {name: i for i, name in enumerate(ARKIT_NAMES)}
        assert got[index["jawOpen"]] == np.float32(0.3)        # the rig's own: what was drawn
        assert got[index["eyeBlinkLeft"]] == 0.25 and got[index["mouthSmileRight"]] == 0.5
        assert got[index["cheekPuff"]] == 0.0 and got[index["browDownLeft"]] == 0.0
        plain = adapter.handle(bytes(sender.encode(np.array([0.3], np.float32))), 0.0).weights
        assert plain[index["eyeBlinkLeft"]] == 0.0
    finally:
        sender.close()
