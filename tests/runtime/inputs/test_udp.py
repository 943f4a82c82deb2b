"""UdpSource over real UDP on 127.0.0.1: newest-frame slot, stale count, sender filter, errors,
and end to end with an independent OSC implementation (liblo's oscsend)."""

from __future__ import annotations

import shutil
import subprocess
import time

import numpy as np
import pytest

from facepuppet.runtime.inputs.kinds import INPUT_KINDS, make_adapter
from facepuppet.runtime.inputs.livelinkface import encode_llf_packet
from facepuppet.runtime.inputs.udp import UdpSource, bind_udp, enable_kernel_stamps, receive
from facepuppet.runtime.inputs.vmc import VmcAdapter
from facepuppet.runtime.mapping.channels import ARKIT_NAMES

from helpers.osc_helpers import vmc_frame
from helpers.udp_helpers import poll_frame, wait_for

JAW = ARKIT_NAMES.index("jawOpen")


def test_registry_and_default_ports():
    ports = {k: make_adapter(k).default_port for k in INPUT_KINDS}
    assert ports == {"vmc": 39539, "facecap": 9000, "faceosc": 8338, "markers": 9763, "livelinkface": 11111,
                     "openseeface": 11573,
                     "ifacialmocap": 49983, "vtubestudio": 21412}
    assert all(make_adapter(k).kind == k for k in INPUT_KINDS)
    with pytest.raises(ValueError, match="unknown input kind 'osc'; expected one of: vmc, facecap"):
        make_adapter("osc")


def test_frame_arrives_and_latest_takes_it_once(udp_sender):
    with UdpSource(VmcAdapter(), port=0) as source:
        host, port = source.address
        assert host == "127.0.0.1" and port > 0
        assert source.latest() == (None, 0)
        udp_sender.sendto(vmc_frame(0.6), source.address)
        frame = poll_frame(source)
        assert frame.weights[JAW] == pytest.approx(0.6) and frame.source == "vmc"
        assert source.latest() == (None, 0)  # taken: nothing new
        assert source.counters["frames"] == 1 and source.counters["packets"] == 1


def test_newest_frame_wins_and_overwritten_frames_are_counted_stale(udp_sender):
    with UdpSource(VmcAdapter(), port=0) as source:
        for i in range(5):
            udp_sender.sendto(vmc_frame(i / 10), source.address)
        wait_for(lambda: source.counters["frames"] == 5, "5 frames handled")
        frame, stale = source.latest(123.0)
        assert frame.weights[JAW] == pytest.approx(0.4) and stale == 4
        assert source.counters["stale_dropped"] == 4
        udp_sender.sendto(vmc_frame(0.9), source.address)
        frame, stale = poll_frame(source), source.counters["stale_dropped"]
        assert frame.weights[JAW] == pytest.approx(0.9) and stale == 4


def test_receive_time_comes_from_the_given_clock(udp_sender):
    ticks = iter(range(1000, 2000))
    with UdpSource(VmcAdapter(), port=0, clock=lambda: float(next(ticks))) as source:
        udp_sender.sendto(vmc_frame(0.1), source.address)
        assert poll_frame(source).t == 1000.0


def test_default_receive_time_is_the_kernel_arrival_not_the_read(udp_sender):
    with UdpSource(VmcAdapter(), port=0) as source:
        t_sent = time.monotonic()
        udp_sender.sendto(vmc_frame(0.1), source.address)
        frame = poll_frame(source)
        assert t_sent - 0.002 <= frame.t <= time.monotonic()
    # a read 50 ms after arrival, made here (not by the thread, whose timing is the scheduler's): the
    # time is the kernel's arrival stamp, and the late read is counted
    sock, _ = bind_udp("127.0.0.1", 0, "vmc", stamps=True)
    with sock:
        assert enable_kernel_stamps(sock)
        t_sent = time.monotonic()
        udp_sender.sendto(vmc_frame(0.2), sock.getsockname())
        time.sleep(0.05)
        own = {"waited_over_1ms": 0}
        data, sender, t = receive(sock, True, time.monotonic, own)
        assert data == vmc_frame(0.2) and t - t_sent < 0.04, "stamped when read, not when it arrived"
        assert own["waited_over_1ms"] == 1


def test_senders_outside_allow_are_dropped_and_counted(udp_sender):
    with UdpSource(VmcAdapter(), port=0, allow={"10.1.2.3"}) as source:
        udp_sender.sendto(vmc_frame(0.5), source.address)
        wait_for(lambda: source.counters["filtered_sender"] == 1, "the filtered packet")
        assert source.latest() == (None, 0) and source.counters["datagrams"] == 0
    with UdpSource(VmcAdapter(), port=0, allow={"127.0.0.1"}) as source:
        udp_sender.sendto(vmc_frame(0.5), source.address)
        assert poll_frame(source).weights[JAW] == pytest.approx(0.5)


def test_on_packet_sees_raw_bytes_and_its_errors_are_counted(udp_sender):
    seen = []

    def record(data, t, who):
        seen.append((data, t, who))
        if len(seen) == 1:
            raise RuntimeError("recorder failed")

    with UdpSource(VmcAdapter(), port=0, on_packet=record) as source:
        udp_sender.sendto(b"first", source.address)
        wait_for(lambda: source.counters["internal_error"] == 1, "the recorder error")
        assert isinstance(source.last_error, RuntimeError)
        udp_sender.sendto(vmc_frame(0.3), source.address)  # the thread goes on
        assert poll_frame(source).weights[JAW] == pytest.approx(0.3)
    assert seen[0][0] == b"first" and seen[1][0] == vmc_frame(0.3)
    assert seen[0][2][0] == "127.0.0.1"


def test_busy_port_raises_naming_the_address():
    with UdpSource(VmcAdapter(), port=0) as first:
        port = first.address[1]
        with pytest.raises(OSError, match=f"127.0.0.1:{port}"):
            UdpSource(VmcAdapter(), port=port).start()


def test_stop_ends_the_thread_and_frees_the_port():
    source = UdpSource(make_adapter("livelinkface"), port=0).start()
    port = source.address[1]
    thread = source._thread
    source.stop()
    assert not thread.is_alive()
    UdpSource(VmcAdapter(), port=port).start().stop()  # the port can be bound again


def test_livelinkface_packets_over_udp(udp_sender):
    weights = [0.0] * 52
    weights[JAW] = 0.8
    with UdpSource(make_adapter("livelinkface"), port=0) as source:
        udp_sender.sendto(encode_llf_packet(weights, number=77), source.address)
        frame = poll_frame(source)
        assert frame.weights[JAW] == pytest.approx(0.8) and frame.number == 77


def oscsend(port: int, *args: str):
    if shutil.which("oscsend") is None:
        pytest.skip("liblo's oscsend is not installed (Debian package liblo-tools; the Makefile installs it)")
    subprocess.run(["oscsend", "127.0.0.1", str(port), *args], check=True, timeout=10)


def test_vmc_end_to_end_from_liblo_oscsend():
    with UdpSource(make_adapter("vmc"), port=0) as source:
        port = source.address[1]
        oscsend(port, "/VMC/Ext/Blend/Val", "sf", "JawOpen", "0.8")
        oscsend(port, "/VMC/Ext/Blend/Val", "sf", "Blink", "0.5")
        oscsend(port, "/VMC/Ext/Bone/Pos", "sfffffff", "Head", "0", "1.5", "0", "0", "0.2588190", "0", "0.9659258")
        oscsend(port, "/VMC/Ext/Blend/Apply", "")
        frame = poll_frame(source)
        assert frame.weights[JAW] == pytest.approx(0.8)
        assert frame.weights[ARKIT_NAMES.index("eyeBlinkRight")] == pytest.approx(0.5)
        np.testing.assert_allclose(frame.head_rotation, [0, -0.2588190, 0, 0.9659258], atol=1e-6)  # x mirrored
        assert frame.head_translation is None  # the bone's local offset from the neck moves nothing
        assert source.counters["datagrams"] == 4 and source.counters["malformed"] == 0


def test_facecap_and_faceosc_end_to_end_from_liblo_oscsend():
    with UdpSource(make_adapter("facecap"), port=0) as source:
        port = source.address[1]
        oscsend(port, "/W", "if", "24", "0.5")
        oscsend(port, "/HT", "fff", "0", "0", "2")
        frame = poll_frame(source)
        assert frame.weights[JAW] == pytest.approx(0.5)
        np.testing.assert_allclose(frame.head_translation, [0, 0, 2])
    with UdpSource(make_adapter("faceosc"), port=0) as source:
        oscsend(source.address[1], "/found", "i", "0")
        assert np.isnan(poll_frame(source).weights).all()
