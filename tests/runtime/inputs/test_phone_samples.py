"""The committed samples (tests/data/phone, made by our own sender: see its README) decode to what was sent."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from facepuppet.runtime.inputs.kinds import make_adapter
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.recording.replay_source import open_recording
from facepuppet.runtime.recording.session import read_session

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "phone"
N = 40


def sent(k: int) -> np.ndarray:
    """Frame k's weights in Apple's order, as README.md says they were made."""
    return np.array([0.5 + 0.5 * math.sin(0.3 * k + 0.1 * i) for i in range(52)])


@pytest.mark.parametrize("kind, frames, lost, unknown, step", [
    ("ifacialmocap", N, 0, N, 0.01),     # integers 0-100: within 0.005 of the value
    ("vtubestudio", N - 5, 5, 0, 1e-4),  # 4 decimals
])
def test_samples_decode_to_what_the_sender_sent(kind, frames, lost, unknown, step):
    path = SAMPLES / f"{kind}_sample.fps"
    session = read_session(path)
    assert session.complete and len(session.packets) == N
    decoded = open_recording(path)
    assert len(decoded) == frames
    for k, frame in enumerate(decoded):
        assert frame.channels == ARKIT_NAMES and frame.source == kind
        np.testing.assert_allclose(frame.weights, sent(k), atol=step / 2 + 1e-6)
        assert frame.head_rotation is not None
    adapter = make_adapter(kind)  # the raw datagrams again, with the counters
    for packet in session.packets:
        adapter.handle(packet.data, packet.t)
    c = adapter.counters
    assert (c["frames"], c.get("face_lost", 0), c["unknown_key"], c["malformed"], c["nonfinite"]) == \
        (frames, lost, unknown, 0, 0)
