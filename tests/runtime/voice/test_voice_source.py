"""The voice's channel sources: --voice-delay holds the channels back whole hops; a WAV on the run's clock gives
the channels of the samples before each tick, and silence past its end."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.voice.source import VoiceChannels, WavVoice

from helpers.voice_tables import small_table, vowel_buzz, write_wav


def _per_hop(voice: VoiceChannels, x: np.ndarray) -> np.ndarray:
    hop = voice.features.hop_n
    out = []
    for start in range(0, len(x) - hop + 1, hop):
        voice.push(x[start:start + hop])
        out.append(voice.values())
    return np.array(out)


def test_a_delay_holds_the_channels_back_whole_hops():
    table = small_table()
    x = vowel_buzz(1.0, on_off_hz=3.0)
    plain = _per_hop(VoiceChannels(table, 16000), x)
    late = _per_hop(VoiceChannels(table, 16000, delay_s=0.05), x)
    assert np.ptp(plain[:, 0]) > 0.1
    np.testing.assert_array_equal(late[5:], plain[:-5])
    assert (late[:5] == 0).all()
    with pytest.raises(ValueError, match="voice delay"):
        VoiceChannels(table, 16000, delay_s=2.0)


def test_a_wav_plays_on_the_ticks_and_is_silent_past_its_end(tmp_path):
    table = small_table()
    write_wav(tmp_path / "s.wav", vowel_buzz(0.5, on_off_hz=0.5))  # sound for the whole half second
    wav = WavVoice(tmp_path / "s.wav", table)
    assert (wav.channels(0.0) == 0).all()
    during = wav.channels(0.3)
    assert during[0] > 0.1
    again = wav.channels(0.3)  # the same tick time again: nothing more is pushed
    np.testing.assert_array_equal(again, during)
    after = wav.channels(1.0)
    assert (after == 0).all()  # silence past the end closes the mouth


def test_run_with_a_voice_and_nothing_to_listen_to_is_refused(tmp_path):
    import subprocess
    import sys

    from helpers.small_characters import sphere_character
    from helpers.udp_helpers import free_udp_port

    table = small_table().save(tmp_path / "v.npz")
    char = sphere_character().save(tmp_path / "c.npz")
    proc = subprocess.run([sys.executable, "-m", "facepuppet", "run", "-c", str(char), "--input", "vmc", "--voice",
                           str(table), "--headless", "--duration", "0.2", "--listen", f"127.0.0.1:{free_udp_port()}"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "--voice" in proc.stderr and "--audio" in proc.stderr
