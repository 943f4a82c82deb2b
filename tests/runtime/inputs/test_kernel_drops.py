"""Datagrams the kernel drops (the socket's receive buffer full) are counted, exactly, from the kernel's own
count (SO_RXQ_OVFL): a real socket on 127.0.0.1 with a small buffer, flooded while its reader is paused."""

from __future__ import annotations

import signal
import socket
import sys
import threading
import time

import pytest

from facepuppet.runtime.inputs import udp
from facepuppet.runtime.inputs.udp import UdpSource, enable_drop_count, receive
from facepuppet.runtime.inputs.udp_process import UdpProcessSource
from facepuppet.runtime.inputs.vmc import VmcAdapter
from facepuppet.runtime.panel.status import InputStatus

from helpers.osc_helpers import vmc_frame
from helpers.udp_helpers import wait_for

FLOOD = 2000  # datagrams sent while the reader is paused: far more than a 4 KiB buffer holds
linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="SO_RXQ_OVFL is Linux's")


@linux
def test_receive_keeps_the_kernel_drop_count_equal_to_sent_minus_received():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as r, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        r.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        r.bind(("127.0.0.1", 0))
        assert enable_drop_count(r)
        r.settimeout(0.2)
        for _ in range(FLOOD):  # nobody reads meanwhile
            s.sendto(b"x" * 100, r.getsockname())
        own: dict = {}
        received = 0
        while True:
            try:
                receive(r, False, time.monotonic, own)
                received += 1
            except TimeoutError:
                break
        # the datagrams queued before the drops carry no count; the next one queued after them does
        s.sendto(b"y", r.getsockname())
        receive(r, False, time.monotonic, own)
        received += 1
    print(f"socket: sent {FLOOD + 1}, received {received}, kernel_dropped {own['kernel_dropped']}")
    assert 0 < received < FLOOD
    assert own["kernel_dropped"] == FLOOD + 1 - received


class _GatedVmc(VmcAdapter):
    """A VMC adapter whose first datagram holds the receive thread until ``gate`` is set: the thread is paused
    (reads nothing) while the test floods."""

    def __init__(self) -> None:
        super().__init__()
        self.gate, self.holding = threading.Event(), threading.Event()

    def handle(self, data, t):
        if not self.gate.is_set():
            self.holding.set()
            self.gate.wait(30)
        return super().handle(data, t)


def _settled(source, marker_to) -> None:
    """Wait until the receiver has read all it will of the flood, then send one more datagram and wait for it
    (the kernel hands its drop count with the first datagram queued after the drops)."""
    last, still = -1, 0.0
    while still < 0.3:
        now = source.counters["packets"]
        still = still + 0.05 if now == last else 0.0
        last = now
        time.sleep(0.05)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(vmc_frame(0.1), marker_to)
    wait_for(lambda: source.counters["packets"] == last + 1, "the datagram after the flood")


@linux
@pytest.mark.parametrize("receiver", ["thread", "process"])
def test_a_receiver_counts_the_kernel_drops_exactly(monkeypatch, receiver):
    monkeypatch.setattr(udp, "SOCKET_BUFFER", 4096)  # the smallest buffer the kernel grants
    if receiver == "thread":
        adapter = _GatedVmc()
        source = UdpSource(adapter, port=0)
    else:
        source = UdpProcessSource(VmcAdapter(), port=0)
    sent = 0
    with source, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        if receiver == "thread":  # the thread holds its first datagram: paused
            s.sendto(vmc_frame(0.5), source.address)
            sent += 1
            assert adapter.holding.wait(10)
        else:  # the receiving process, stopped
            source._process.send_signal(signal.SIGSTOP)
        try:
            for _ in range(FLOOD):
                s.sendto(vmc_frame(0.5), source.address)
                sent += 1
        finally:
            if receiver == "thread":
                adapter.gate.set()
            else:
                source._process.send_signal(signal.SIGCONT)
        _settled(source, source.address)
        sent += 1
        counters = source.counters
    assert source.drops_reported
    print(f"{receiver}: sent {sent}, received {counters['packets']}, kernel_dropped {counters['kernel_dropped']}")
    assert 0 < counters["kernel_dropped"] == sent - counters["packets"], counters


def test_where_the_kernel_does_not_report_drops_they_are_unknown_not_zero(monkeypatch, udp_sender):
    monkeypatch.setattr(udp, "enable_drop_count", lambda sock: False)  # as on a system without SO_RXQ_OVFL
    with UdpSource(VmcAdapter(), port=0) as source:
        udp_sender.sendto(vmc_frame(0.5), source.address)
        wait_for(lambda: source.counters["packets"] == 1, "the datagram")
        assert source.counters["kernel_dropped"] is None


def test_the_panel_shows_kernel_drops_among_the_drops_and_says_when_they_are_unknown():
    for udp_counters, shown in (({"packets": 9, "kernel_dropped": 491}, "drops: kernel_dropped 491"),
                                ({"packets": 9, "kernel_dropped": 0}, "drops: none"),
                                ({"packets": 9, "kernel_dropped": None},
                                 "drops: none; kernel_dropped unknown (this system does not report it)")):
        status = InputStatus(counters=lambda c=udp_counters: {"udp": c, "loop": {}})
        status.refresh(1.0)
        assert status.text(1.0)[1] == shown
