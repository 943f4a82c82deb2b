"""Re-calibration during a run: the live voice's hops taken as silence and the five vowels, a new profile swapped
in at the last hop; a take that cannot make one leaves the old profile."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.voice.recalibrate import PHASES, Recalibration
from facepuppet.runtime.voice.source import VoiceChannels
from facepuppet.runtime.voice.vowels import VOWELS, build_profile, voiced_hops

RATE = 16000


def tone(hz: float, seconds: float, amplitude: float = 0.3) -> np.ndarray:
    t = np.arange(int(seconds * RATE)) / RATE
    return amplitude * np.sin(2 * np.pi * hz * t) * (1 + 0.3 * np.sin(2 * np.pi * 3 * hz * t))


OLD = {v: tone(300 + 500 * i, 1.0) for i, v in enumerate(VOWELS)}   # the first calibration's "vowels"
NEW = {v: tone(450 + 700 * i, 1.0) for i, v in enumerate(VOWELS)}   # the user's voice now


def test_the_live_takes_become_the_profile_in_use():
    profile, _ = build_profile(OLD, RATE, silence=np.zeros(RATE))
    channels = VoiceChannels(profile, RATE)
    recal = Recalibration(channels, seconds=0.5).start()
    assert recal.message == "stay quiet..."
    channels.push(np.zeros(RATE // 2))
    assert recal.phase == 1 and recal.message == "hold the vowel A..."
    for v in VOWELS:
        channels.push(NEW[v][:RATE // 2])
    assert recal.done and recal.profile is not None and channels.table is recal.profile
    assert channels.listener is None and "in use" in recal.message
    for i, v in enumerate(VOWELS):
        X = voiced_hops(recal.profile, NEW[v], RATE)
        assert (recal.profile.classify(X) == i).mean() > 0.9, v


def test_a_silent_vowel_take_leaves_the_old_profile_and_says_why():
    profile, _ = build_profile(OLD, RATE)
    channels = VoiceChannels(profile, RATE)
    recal = Recalibration(channels, seconds=0.2).start()
    channels.push(np.zeros(int(RATE * 0.2) * len(PHASES)))
    assert recal.done and recal.profile is None and channels.table is profile
    assert "failed" in recal.message and "silent" in recal.message


def test_only_a_vowel_profile_is_recalibrated():
    from helpers.voice_tables import small_table

    with pytest.raises(ValueError, match="not a vowel profile"):
        Recalibration(VoiceChannels(small_table(), RATE))
