"""The panel's Input lines show the voice's mouth channels of each tick (``run --voice``)."""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.panel.status import InputStatus
from facepuppet.runtime.voice.stage import VoiceStage


class _Source:
    outputs = ("jawOpen", "mouthFunnel", "mouthSmileLeft")

    def __init__(self):
        self.value = np.array([0.42, 0.1, 0.0], np.float32)

    def channels(self, t):
        return self.value


def test_the_input_lines_carry_the_voice_channels_of_the_tick():
    source = _Source()
    stage = VoiceStage(source)
    status = InputStatus(input_kind="audio", address="voice", voice=stage)
    assert status.text(0.0)[1].endswith("\nvoice: -")  # before the first tick
    stage(None, 0.0)
    assert status.text(0.0)[1].endswith("\nvoice: jawOpen 0.42  Funnel 0.10  SmileL 0.00")
    source.value = np.array([0.9, 0.5, 0.25], np.float32)
    stage(None, 1 / 60)
    assert status.text(0.0)[1].endswith("\nvoice: jawOpen 0.90  Funnel 0.50  SmileL 0.25")
    assert "voice" not in InputStatus(input_kind="vmc").text(0.0)[1]
