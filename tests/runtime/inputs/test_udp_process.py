"""UdpProcessSource over real UDP on 127.0.0.1: a child process decodes, the newest frame comes through
a socket pair (whole, never mixed with another), datagrams reach on_packet in the parent, counters are the
child's."""

from __future__ import annotations

import os
import random
import threading
import time

import numpy as np
import pytest

from facepuppet.runtime.inputs.kinds import make_adapter
from facepuppet.runtime.inputs.livelinkface import encode_llf_packet
from facepuppet.runtime.inputs.markers import FRAME, LAYOUT
from facepuppet.runtime.inputs.udp_process import UdpProcessSource
from facepuppet.runtime.inputs.vmc import VmcAdapter
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.model.geometry import euler_to_quat

from helpers.osc_helpers import bundle, msg, osc, vmc_frame
from helpers.udp_helpers import poll_frame, wait_for

JAW = ARKIT_NAMES.index("jawOpen")


def test_frame_crosses_the_process_with_its_kernel_arrival_time(udp_sender):
    with UdpProcessSource(VmcAdapter(), port=0) as source:
        host, port = source.address
        assert host == "127.0.0.1" and port > 0 and source.latest() == (None, 0)
        t_sent = time.monotonic()
        udp_sender.sendto(vmc_frame(0.6), source.address)
        frame = poll_frame(source)
        t_taken = time.monotonic()
        assert frame.weights[JAW] == pytest.approx(0.6) and frame.source == "vmc"
        assert frame.channels[JAW] == "jawOpen"
        assert t_sent - 0.002 <= frame.t <= t_taken  # arrival, on this process's monotonic clock
        assert source.latest() == (None, 0)
        counters = source.counters
        assert counters["frames"] == 1 and counters["packets"] == 1 and counters["internal_error"] == 0
        assert source.frames_taken == 1
    assert source.counters["datagrams"] == 1  # final counters survive stop()


def test_newest_frame_wins_and_overwritten_frames_are_counted_stale(udp_sender):
    with UdpProcessSource(VmcAdapter(), port=0) as source:
        for i in range(5):
            udp_sender.sendto(vmc_frame(i / 10), source.address)
        wait_for(lambda: source.counters["frames"] == 5, "5 frames handled")
        frame, stale = source.latest(123.0)
        assert frame.weights[JAW] == pytest.approx(0.4) and stale == 4
        udp_sender.sendto(vmc_frame(0.9), source.address)
        assert poll_frame(source).weights[JAW] == pytest.approx(0.9)
        assert source.counters["stale_dropped"] == 4 and source.frames_taken == 6


def test_senders_outside_allow_are_dropped_and_counted(udp_sender):
    seen = []
    with UdpProcessSource(VmcAdapter(), port=0, allow={"10.1.2.3"}, on_packet=lambda *a: seen.append(a)) as source:
        udp_sender.sendto(vmc_frame(0.5), source.address)
        wait_for(lambda: source.counters["filtered_sender"] == 1, "the filtered packet")
        assert source.latest() == (None, 0) and source.counters["datagrams"] == 0
    assert seen == []  # filtered datagrams are not recorded


def test_on_packet_runs_here_in_order_and_its_errors_are_counted(udp_sender):
    seen = []

    def record(data, t, who):
        seen.append((data, t, who))
        if len(seen) == 1:
            raise RuntimeError("recorder failed")

    with UdpProcessSource(VmcAdapter(), port=0, on_packet=record) as source:
        t_sent = time.monotonic()
        udp_sender.sendto(b"first", source.address)
        udp_sender.sendto(vmc_frame(0.3), source.address)
        assert poll_frame(source).weights[JAW] == pytest.approx(0.3)
        assert seen == []  # the snapshot has no side effects: datagrams wait in the ring
        source.deliver_packets()  # the recording hook's call, once a tick
        assert len(seen) == 2
        assert source.counters["internal_error"] == 1 and isinstance(source.last_error, RuntimeError)
        udp_sender.sendto(b"after the last tick", source.address)
        wait_for(lambda: source.counters["packets"] == 3, "the third datagram")
    # the rest of the ring is handed on by stop()
    assert [d for d, _, _ in seen] == [b"first", vmc_frame(0.3), b"after the last tick"]
    assert seen[0][2] == ("127.0.0.1", udp_sender.getsockname()[1]) and seen[0][1] >= t_sent - 0.002
    assert source.counters["malformed"] + source.counters["unknown_address"] >= 1  # b"first" is not OSC


def test_a_full_ring_drops_and_counts_instead_of_blocking(udp_sender):
    seen = []
    with UdpProcessSource(make_adapter("livelinkface"), port=0, on_packet=lambda *a: seen.append(a),
                          ring_bytes=1 << 17) as source:
        packet = encode_llf_packet([0.5] * 52, number=1)
        n = 2 * (1 << 17) // (len(packet) + 32) + 50  # about twice what the ring holds
        for _ in range(n):
            udp_sender.sendto(packet, source.address)
        wait_for(lambda: source.counters["packets"] == n, f"{n} datagrams read")
        dropped = source.counters["packets_ring_dropped"]
        assert dropped > 0
        assert poll_frame(source).weights[0] == pytest.approx(0.5)  # decoding went on
    assert len(seen) + dropped == n


def test_markers_and_livelinkface_frames_keep_every_field(udp_sender):
    points = np.array([[0.0, 10.0, 5.0], [1.5, -40.0, 2.0], [np.nan, np.nan, np.nan]], dtype="<f4")
    with UdpProcessSource(make_adapter("markers"), port=0) as source:
        udp_sender.sendto(osc(LAYOUT, 1, "nose", "chin", "mouthL"), source.address)
        udp_sender.sendto(osc(FRAME, 1, 7, (12.25, "d"), (points.tobytes(), "b")), source.address)
        frame = poll_frame(source)
        assert frame.marker_names == ("nose", "chin", "mouthL") and frame.number == 7 and frame.t_sender == 12.25
        np.testing.assert_array_equal(frame.markers, points)
        assert frame.weights is None and frame.channels is None and frame.head_rotation is None
    weights = np.linspace(0, 1, 52)
    with UdpProcessSource(make_adapter("livelinkface"), port=0) as source:
        udp_sender.sendto(encode_llf_packet(weights, head=(0.3, -0.2, 0.1), number=77), source.address)
        frame = poll_frame(source)
        np.testing.assert_allclose(frame.weights[:52], weights, atol=1e-6)
        assert frame.number == 77 and frame.head_rotation.shape == (4,)
        assert np.linalg.norm(frame.head_rotation) == pytest.approx(1.0, abs=1e-5)


def test_frames_read_while_the_child_writes_are_never_torn(udp_sender):
    # every frame has all 52 weights equal: a read that mixed two frames would show two values
    with UdpProcessSource(make_adapter("livelinkface"), port=0) as source:
        packets = [encode_llf_packet([v] * 52, number=i) for i, v in enumerate(np.linspace(0, 1, 4000))]
        taken = 0
        for _i, packet in enumerate(packets):
            udp_sender.sendto(packet, source.address)
            frame, _ = source.latest()
            if frame is not None:
                taken += 1
                w = frame.weights[:52]
                assert np.all(w == w[0]), f"torn frame {frame.number}: {np.unique(w)}"
                assert w[0] == pytest.approx(np.linspace(0, 1, 4000)[frame.number], abs=1e-6)
        assert taken > 0


def test_random_datagrams_do_not_stop_it(udp_sender):
    rng = random.Random(3)
    good = vmc_frame(0.25)
    with UdpProcessSource(VmcAdapter(), port=0) as source:
        for i in range(5000):
            kind = rng.random()
            if kind < 0.5:
                data = bytes(rng.getrandbits(8) for _ in range(rng.randrange(1, 200)))
            else:
                data = bytearray(good)
                for _ in range(rng.randrange(1, 6)):
                    data[rng.randrange(len(data))] = rng.getrandbits(8)
                data = bytes(data)
            udp_sender.sendto(data, source.address)
            if i % 200 == 0:
                time.sleep(0.002)
                source.latest()
        wait_for(lambda: source.counters["packets"] == 5000, "every datagram read")
        source.latest()  # what the mutated datagrams left in the slot
        udp_sender.sendto(vmc_frame(0.75), source.address)
        assert poll_frame(source).weights[JAW] == pytest.approx(0.75)
        assert source.counters["internal_error"] == 0, source.last_error


def test_busy_port_and_stop_free_the_port():
    with UdpProcessSource(VmcAdapter(), port=0) as first:
        port = first.address[1]
        with pytest.raises(OSError, match=f"127.0.0.1:{port}"):
            UdpProcessSource(VmcAdapter(), port=port).start()
        child = first._process
    assert child.poll() is not None  # the child has exited
    UdpProcessSource(VmcAdapter(), port=port).start().stop()


def test_bad_ring_size_is_refused():
    with pytest.raises(ValueError, match="ring_bytes: expected a multiple of 16"):
        UdpProcessSource(VmcAdapter(), port=0, ring_bytes=1000)


def test_the_child_leaves_when_the_parent_is_gone(tmp_path):
    import subprocess
    import sys

    script = (
        "import sys, time\n"
        "from facepuppet.runtime.inputs.udp_process import UdpProcessSource\n"
        "from facepuppet.runtime.inputs.vmc import VmcAdapter\n"
        "s = UdpProcessSource(VmcAdapter(), port=0).start()\n"
        "print(s._process.pid, flush=True)\n"
        "time.sleep(60)\n")
    parent = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        child_pid = int(parent.stdout.readline())
    finally:
        parent.kill()
        parent.wait()

    def gone():
        try:
            os.kill(child_pid, 0)
        except ProcessLookupError:
            return True
        with open(f"/proc/{child_pid}/stat") as f:  # a zombie (reaped later by init) counts as gone
            return f.read().split(")")[-1].split()[0] == "Z"

    wait_for(gone, "the orphaned child to exit")


def test_kill_9_of_the_child_leaves_what_it_sent_and_the_source_answering(udp_sender):
    """What the child sent before it died is still read; then nothing comes: a wait sleeps its timeout (no spin
    on a dead channel) and stop() returns at once, handing on the datagrams received."""
    seen = []
    with UdpProcessSource(make_adapter("livelinkface"), port=0, on_packet=lambda *a: seen.append(a)) as source:
        for i in range(10):
            udp_sender.sendto(encode_llf_packet([0.5] * 52, number=i), source.address)
        wait_for(lambda: source.counters["packets"] == 10, "10 datagrams")
        source._process.kill()
        source._process.wait()
        udp_sender.sendto(encode_llf_packet([0.5] * 52, number=100), source.address)
        assert source.latest()[0].number == 9
        cpu = time.thread_time()
        assert source.wait_for_frame(0.3) is False
        assert time.thread_time() - cpu < 0.15
        assert source.latest() == (None, 0) and source.counters["packets"] == 10
        t_stop = time.monotonic()
    assert time.monotonic() - t_stop < 2.0 and len(seen) == 10


def test_watched_messages_are_counted_without_on_packet_and_without_callbacks(udp_sender):
    with UdpProcessSource(VmcAdapter(), port=0, watch="/facepuppet/calibrate") as source:
        udp_sender.sendto(vmc_frame(0.2), source.address)
        poll_frame(source)
        assert source.watched == 0
        calibrate = osc("/facepuppet/calibrate")
        udp_sender.sendto(calibrate, source.address)
        udp_sender.sendto(calibrate, source.address)
        wait_for(lambda: source.counters["packets"] == 3, "both calibrate messages")
        assert source.watched == 2  # a count the filter stage reads each tick; nothing is called
    assert source.watched == 2  # kept after stop


def _flood(udp_sender, address, packets, pause_at):
    """Send ``packets`` as fast as the socket takes them, pausing once (the receiver's channel fills)."""
    def send():
        for i, packet in enumerate(packets):
            if i == pause_at:
                time.sleep(0.3)
            udp_sender.sendto(packet, address)
    thread = threading.Thread(target=send)
    thread.start()
    return thread


def _take_all(source, last_number, check):
    """Take frames until the one numbered ``last_number``; ``check`` each; the numbers only grow, each frame
    stands for as many completed frames as ``stale`` says. Sleeps a while once: frames pile up meanwhile."""
    previous, taken_before, seen, slept = -1, source.frames_taken, 0, False
    end = time.monotonic() + 30.0
    while previous != last_number:
        assert time.monotonic() < end, f"timed out at frame {previous} of {last_number}"
        frame, stale = source.latest()
        if frame is None:
            source.wait_for_frame(0.05)
            continue
        check(frame)
        assert frame.number > previous and frame.number - previous >= stale + 1
        assert source.frames_taken == taken_before + stale + 1
        previous, taken_before, seen = frame.number, source.frames_taken, seen + 1
        if not slept and seen == 20:
            time.sleep(0.3)
            slept = True
    return seen


def _flood_and_check(udp_sender, kind: str, packets: list, check) -> None:
    """Flood a process receiver of ``kind`` with ``packets`` (pausing the reader halfway, which fills the
    channel) and ``check`` every frame taken; the child counted no internal error."""
    with UdpProcessSource(make_adapter(kind), port=0) as source:
        sender = _flood(udp_sender, source.address, packets, pause_at=len(packets) // 2)
        try:
            _take_all(source, len(packets) - 1, check)
        finally:
            sender.join()
        assert source.counters["internal_error"] == 0, source.last_error


def test_a_fast_sender_never_shows_a_frame_mixed_from_two_datagrams(udp_sender):
    """Each Live Link Face datagram gets weights, head, number and sender time of its own, all derived from the
    number; each taken frame must agree with itself whatever the sender's pace, pauses of the reader included
    (the channel fills, the child drops older frames)."""
    n = 3000

    def weights(number):
        return (np.arange(52) * 31 + number) % 97 / 97.0

    def yaw(number):
        return (number % 101) / 101.0 - 0.5

    packets = [encode_llf_packet(weights(i), head=(yaw(i), 0.1, -0.1), number=i) for i in range(n)]

    def check(frame):
        i = frame.number
        np.testing.assert_allclose(frame.weights[:52], weights(i), atol=1e-6, err_msg=f"frame {i}")
        np.testing.assert_allclose(frame.head_rotation, euler_to_quat(yaw(i), 0.1, -0.1), atol=1e-5)
        assert frame.t_sender == pytest.approx(i / 60.0) and frame.source == "livelinkface"
        assert frame.channels == ARKIT_NAMES

    _flood_and_check(udp_sender, "livelinkface", packets, check)


def test_a_fast_sender_of_new_marker_layouts_never_shows_names_of_another_frame(udp_sender):
    """Each datagram declares a layout of its own (names carrying the frame number) and one frame in it, points
    derived from the number: more layouts than the name slots both processes keep, so slots are reused while
    frames are dropped and taken; a frame's names and points must come from the same datagram."""
    n, n_markers = 1500, 8

    def points(number):
        return (np.arange(3 * n_markers, dtype="<f4").reshape(-1, 3) + number).astype("<f4")

    packets = [bundle(msg(LAYOUT, i % 16, *[f"f{i}_m{k}" for k in range(n_markers)]),
                      msg(FRAME, i % 16, i, (i * 0.5, "d"), (points(i).tobytes(), "b"))) for i in range(n)]

    def check(frame):
        i = frame.number
        assert frame.marker_names == tuple(f"f{i}_m{k}" for k in range(n_markers)), i
        np.testing.assert_array_equal(frame.markers, points(i))
        assert frame.t_sender == i * 0.5 and frame.source == "markers"

    _flood_and_check(udp_sender, "markers", packets, check)
