"""The periodic phone request (PhoneRequester) over real UDP on 127.0.0.1, and the --phone address rules."""

from __future__ import annotations

import socket

import pytest

from facepuppet.runtime.inputs.phone import PhoneRequester, parse_phone

from helpers.udp_helpers import wait_for


@pytest.fixture
def phone():
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(10.0)
    yield sock
    sock.close()


def test_sends_at_once_repeats_and_stops_for_good(phone):
    port = phone.getsockname()[1]
    requester = PhoneRequester("127.0.0.1", port, b"start please", every_s=0.02)
    with requester:
        got = [phone.recvfrom(100)[0] for _ in range(3)]  # the first at once, then repeated
        assert got == [b"start please"] * 3
    sent = requester.counters["sent"]
    assert sent >= 3 and requester.counters["send_errors"] == 0
    requester.send_once()  # after stop: nothing can go out any more
    assert requester.counters["sent"] == sent
    phone.settimeout(0.5)
    rest = 0
    try:  # every payload counted as sent arrives (loopback), and nothing more
        while True:
            phone.recvfrom(100)
            rest += 1
    except TimeoutError:
        pass
    assert 3 + rest == sent


def test_a_send_that_fails_is_counted_not_raised():
    requester = PhoneRequester("127.0.0.1", 9, b"x" * 70_000, every_s=0.01)  # too big for one UDP datagram
    with requester:
        wait_for(lambda: requester.counters["send_errors"] >= 2, "two failed sends")
    assert requester.counters["sent"] == 0 and isinstance(requester.last_error, OSError)


def test_every_must_be_positive():
    with pytest.raises(ValueError, match="every_s"):
        PhoneRequester("127.0.0.1", 1, b"", every_s=0)


@pytest.mark.parametrize("text, port, expected", [
    ("192.168.1.20", 49983, ("192.168.1.20", 49983)),
    ("192.168.1.20:5000", 49983, ("192.168.1.20", 5000)),
    ("127.0.0.1", 21412, ("127.0.0.1", 21412)),
    ("[::1]:7000", 21412, ("::1", 7000)),
    ("fe80::1", 21412, ("fe80::1", 21412)),
    (" 10.0.0.2 ", 1, ("10.0.0.2", 1)),
])
def test_parse_phone(text, port, expected):
    assert parse_phone(text, port) == expected


@pytest.mark.parametrize("text, match", [
    ("localhost", "not an IP address"),      # names are refused, never looked up
    ("my-iphone.local", "not an IP address"),
    ("192.168.1.300", "not an IP address"),
    ("255.255.255.255", "broadcast"),
    ("224.0.0.1", "broadcast, multicast"),
    ("0.0.0.0", "unspecified"),
    ("10.0.0.2:0", "out of range"),
    ("10.0.0.2:70000", "out of range"),
    ("", "expected the phone's IP address"),
])
def test_parse_phone_refuses(text, match):
    with pytest.raises(ValueError, match="--phone") as info:
        parse_phone(text, 49983)
    assert match in str(info.value)
