"""Both receivers (the thread and the child process), one behaviour: calibrate messages are counted only when
decoded as OSC messages to the address, and ``--allow`` matches IPv4 senders on a dual-stack socket however
the address is written. Real UDP on loopback only."""

from __future__ import annotations

import socket

import pytest

from facepuppet.runtime.inputs.livelinkface import LiveLinkFaceAdapter, encode_llf_packet
from facepuppet.runtime.inputs.osc import CALIBRATE_ADDRESS
from facepuppet.runtime.inputs.udp import UdpSource, normalise_host
from facepuppet.runtime.inputs.udp_process import UdpProcessSource
from facepuppet.runtime.inputs.vmc import VmcAdapter
from facepuppet.runtime.mapping.channels import ARKIT_NAMES

from helpers.osc_helpers import bundle, msg, osc, vmc_frame
from helpers.udp_helpers import poll_frame, wait_for

RECEIVERS = {"thread": UdpSource, "process": UdpProcessSource}


@pytest.fixture(params=sorted(RECEIVERS))
def receiver(request):
    return RECEIVERS[request.param]


def test_only_decoded_calibrate_messages_count_not_the_bytes_anywhere(receiver, udp_sender):
    weights = [0.1] * len(ARKIT_NAMES)
    with receiver(LiveLinkFaceAdapter(), port=0, watch=CALIBRATE_ADDRESS) as source:
        # a Live Link Face device whose name carries the address, padding and all
        tricky = encode_llf_packet(weights, name="phone /facepuppet/calibrate\x00\x00\x00,\x00\x00\x00")
        assert CALIBRATE_ADDRESS.encode() + b"\x00" in tricky
        udp_sender.sendto(tricky, source.address)
        assert poll_frame(source) is not None  # the packet is a good frame ...
        assert source.watched == 0  # ... and no calibration request
        udp_sender.sendto(osc("/facepuppet/calibrate"), source.address)  # a real request
        wait_for(lambda: source.counters["packets"] == 2, "the calibrate message")
        assert source.watched == 1
        # kept from the Live Link Face adapter: not its protocol, and not a drop (it counted malformed before)
        assert source.counters["malformed"] == 0
    with receiver(VmcAdapter(), port=0, watch=CALIBRATE_ADDRESS) as source:
        sent = [
            osc("/VMC/Ext/Blend/Val", "/facepuppet/calibrate", 0.5),  # the address as a string argument: no
            osc("/facepuppet/calibrate/now"),                          # another address that starts alike: no
            bundle(msg("/VMC/Ext/Blend/Apply"), msg("/facepuppet/calibrate")),  # inside a bundle: yes
            b"/facepuppet/calibrate\x00\x00\x00,\x00",                 # truncated, malformed OSC: no
            vmc_frame(0.3),
        ]
        for data in sent:
            udp_sender.sendto(data, source.address)
        wait_for(lambda: source.counters["packets"] == len(sent), "every datagram")
        assert source.watched == 1
        # the request in the bundle is not an unknown address (the look-alike is), the truncated one malformed
        assert source.counters["unknown_address"] == 1 and source.counters["malformed"] == 1


def dual_stack_listener(receiver, allow):
    """A receiver on an IPv6 socket bound to the IPv4-mapped loopback (IPv4 senders arrive as ::ffff:a.b.c.d)."""
    return receiver(VmcAdapter(), host="::ffff:127.0.0.1", port=0, allow=allow)


@pytest.mark.parametrize("written", ["127.0.0.2", "::ffff:127.0.0.2", "::FFFF:7f00:2"])
def test_allow_matches_ipv4_senders_on_a_dual_stack_socket(receiver, written):
    with dual_stack_listener(receiver, {written}) as source, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as allowed, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:
        allowed.bind(("127.0.0.2", 0))
        other.bind(("127.0.0.3", 0))
        port = source.address[1]
        other.sendto(vmc_frame(0.9), ("127.0.0.1", port))
        wait_for(lambda: source.counters["filtered_sender"] == 1, "the other sender filtered")
        allowed.sendto(vmc_frame(0.4), ("127.0.0.1", port))
        frame = poll_frame(source)
        assert frame.weights[frame.channels.index("jawOpen")] == pytest.approx(0.4)
        assert source.counters["filtered_sender"] == 1


def test_normalise_host():
    assert normalise_host("::ffff:127.0.0.2") == "127.0.0.2"
    assert normalise_host("::FFFF:7F00:0002") == "127.0.0.2"
    assert normalise_host("127.0.0.2") == "127.0.0.2"
    assert normalise_host("0:0::1") == "::1"
    assert normalise_host("not an address") == "not an address"


def layout_and_frame(layout_id: int, names: list[str], number: int) -> tuple[bytes, bytes]:
    import numpy as np

    from facepuppet.runtime.inputs.markers import FRAME, LAYOUT

    points = np.arange(3 * len(names), dtype="<f4").reshape(-1, 3) + number
    return osc(LAYOUT, layout_id, *names), osc(FRAME, layout_id, number, (0.5, "d"), (points.tobytes(), "b"))


def test_a_flood_of_new_marker_layouts_never_shuts_out_the_next_one(receiver, udp_sender):
    from facepuppet.runtime.inputs.markers import MarkersAdapter

    with receiver(MarkersAdapter(), port=0) as source:
        def accepted(layout_id: int, names: list[str], number: int) -> bool:
            layout, frame = layout_and_frame(layout_id, names, number)
            udp_sender.sendto(layout, source.address)
            udp_sender.sendto(frame, source.address)
            got = poll_frame(source)  # each frame is taken before the next layout is sent
            return got.marker_names == tuple(names) and got.number == number

        # the attack: 48 layouts of 1,000 distinct 24-character names (~1.2 MB of names, more than the old log)
        # while a steady layout (re-declared each time, as a bridge does) keeps being drawn
        steady = [f"steady_{i}" for i in range(30)]
        for k in range(48):
            assert accepted(k, [f"attack{k:04d}_marker_{i:06d}" for i in range(1000)], k)
            assert accepted(999, steady, 10_000 + k)
        # then a mocap bridge's ordinary layouts: every one gets in
        taken = sum(accepted(1000 + k, [f"bridge{k}_m{i}" for i in range(200)], 5000 + k) for k in range(40))
        assert taken == 40
        assert source.counters.get("names_full", 0) == 0 and source.counters["internal_error"] == 0


def test_the_arrival_waiter_wakes_on_a_frame_of_any_of_its_receivers(receiver, udp_sender):
    """Two receivers of one kind; a frame reaches the second only: the first's own wait times out (what the
    loop slept in before), the waiter wakes; once taken, nothing is pending."""
    from facepuppet.runtime.inputs.arrival import ArrivalWaiter

    with receiver(VmcAdapter(), port=0) as first, receiver(VmcAdapter(), port=0) as second:
        waiter = ArrivalWaiter([first, second])
        assert waiter.wait(0.0) is False
        udp_sender.sendto(vmc_frame(0.4), second.address)
        assert waiter.wait(30.0) is True  # only an arrival ends the wait before its timeout
        wait_for(second.pending, "the second receiver's frame")
        assert first.wait_for_frame(0.05) is False and not first.pending()
        frame, _ = second.latest()
        assert frame is not None
        assert waiter.wait(0.0) is False  # taken: nothing pending
        udp_sender.sendto(vmc_frame(0.5), first.address)
        assert waiter.wait(30.0) is True
        wait_for(first.pending, "the first receiver's frame")


def test_the_arrival_waiter_refuses_sources_it_cannot_wait_on():
    from facepuppet.runtime.inputs.arrival import ArrivalWaiter

    with pytest.raises(ValueError, match="every source needs pending"):
        ArrivalWaiter([object()])
    with pytest.raises(ValueError, match="neither all thread receivers nor all started process receivers"):
        ArrivalWaiter([UdpSource(VmcAdapter(), port=0), UdpProcessSource(VmcAdapter(), port=0)])
