"""The process receiver's channel on a real socket pair, without the processes: the child's Outbox never blocks,
keeps the order the parent must read, drops only older frames (and datagrams over its bound); the parent's
Inbox reassembles messages the socket cut and refuses a message over MAX_MESSAGE."""

from __future__ import annotations

import socket
import struct

import pytest

from facepuppet.runtime.inputs.udp_channel import (
    COUNTERS,
    FRAME,
    HEAD,
    MAX_MESSAGE,
    PACKET,
    ChannelError,
    Inbox,
    Outbox,
    message,
    packet_cost,
)


@pytest.fixture
def pair():
    a, b = socket.socketpair()
    for s in (a, b):
        s.setblocking(False)
    a.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)  # fills after a few messages
    yield a, b
    a.close()
    b.close()


def test_a_stuck_reader_costs_older_frames_only_and_the_order_holds(pair):
    """2,000 rounds of (datagram i, frame i, counters = i) while nobody reads: flush never blocks; read at
    last, the datagrams accepted come all and in order, each frame seen sits right after its own datagram,
    the newest frame comes, and a counters message follows the frame it counts, never precedes it."""
    a, b = pair
    count = [0]
    box = Outbox(a, 1 << 17, lambda item: message(FRAME, item),
                 lambda: message(COUNTERS, struct.pack("<q", count[0])))
    accepted, blocked = [], 0
    frame_body = bytes(3000)  # bigger than what the socket takes at a time: cut into parts
    for i in range(2000):
        if box.put(message(PACKET, b"%d|" % i + bytes(100)), packet_cost(9, 110)):
            accepted.append(i)
        box.put_frame(b"%d|" % i + frame_body)
        count[0] = i
        box.put_counters()
        blocked += not box.flush()
    assert blocked > 0 and 0 < len(accepted) < 2000  # the socket filled; the datagram bound was met
    inbox, got = Inbox(b), []
    while True:
        done = box.flush()
        got += inbox.read()
        if done and not box.blocked:
            got += inbox.read()
            break
    assert box.empty
    packets = [int(body.split(b"|")[0]) for kind, body in got if kind == PACKET]
    assert packets == accepted
    last_packet, last_frame, frames = -1, -1, []
    for kind, body in got:
        if kind == PACKET:
            last_packet = int(body.split(b"|")[0])
        elif kind == FRAME:
            i = int(body.split(b"|")[0])
            assert len(body) == len(b"%d|" % i) + len(frame_body)  # whole, reassembled
            assert i > last_frame and (i not in accepted or last_packet == i)
            last_frame = i
            frames.append(i)
        else:
            assert kind == COUNTERS
            assert struct.unpack("<q", body)[0] == last_frame  # counts nothing not read before it
    assert frames[-1] == 1999 and len(frames) < 2000  # the newest came, older ones were dropped


def test_the_inbox_refuses_a_message_over_the_bound_then_drops_what_follows(pair):
    a, b = pair
    inbox = Inbox(b)
    a.send(message(COUNTERS, struct.pack("<q", 7)))
    assert inbox.read() == [(COUNTERS, struct.pack("<q", 7))]
    a.send(HEAD.pack(MAX_MESSAGE + 1, FRAME) + bytes(64))
    with pytest.raises(ChannelError, match="over"):
        inbox.read()
    a.send(message(COUNTERS, struct.pack("<q", 8)))
    assert inbox.read() == [] and inbox.broken  # the stream cannot be resynchronised; nothing stays unread
    with pytest.raises(BlockingIOError):
        b.recv(1)
