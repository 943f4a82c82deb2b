"""Audio level: dBFS of generated WAV files, noise floor, attack/release, and a missing device."""

from __future__ import annotations

import math
import wave

import numpy as np
import pytest
from scipy.io import wavfile

from facepuppet.runtime.inputs.audio import LevelMeter, WavLevel, open_audio

RATE = 48000  # 800 samples per 60 Hz tick: a 600 Hz sine fills each tick with whole cycles


def write_int16(path, samples, rate=RATE, channels=1):
    data = np.clip(np.round(np.asarray(samples) * 32767), -32768, 32767).astype("<i2")
    with wave.open(str(path), "wb") as w:
        w.setnchannels(channels)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(data.tobytes())
    return path


def sine(amplitude, seconds, freq=600.0, rate=RATE):
    t = np.arange(int(seconds * rate)) / rate
    return amplitude * np.sin(2 * np.pi * freq * t)


def levels(source, seconds, fps=60.0):
    return np.array([source.level(k / fps) for k in range(1, int(seconds * fps) + 1)])


def test_sine_at_known_amplitude_gives_its_dbfs(tmp_path):
    path = write_int16(tmp_path / "sine.wav", sine(0.5, 1.0))
    got = levels(WavLevel(path), 1.0)
    expected = 20 * math.log10(0.5 / math.sqrt(2))  # -9.03 dBFS
    assert got[-1] == pytest.approx(expected, abs=0.05)
    assert LevelMeter(RATE).block_db(sine(1.0, 0.1)) == pytest.approx(-3.01, abs=0.01)


def test_stereo_float_file_is_mixed_to_mono(tmp_path):
    s = sine(0.25, 1.0).astype(np.float32)
    path = tmp_path / "stereo.wav"
    wavfile.write(path, RATE, np.stack([s, s], axis=1))
    assert levels(WavLevel(path), 1.0)[-1] == pytest.approx(20 * math.log10(0.25 / math.sqrt(2)), abs=0.05)


def test_silence_and_the_end_of_the_file_go_to_the_noise_floor(tmp_path):
    path = write_int16(tmp_path / "quiet.wav", np.zeros(RATE // 2))
    src = WavLevel(path, floor_db=-70.0)
    got = levels(src, 2.0)  # past the end: silence
    np.testing.assert_array_equal(got, -70.0)


def test_attack_is_fast_release_is_slow(tmp_path):
    loud = sine(0.5, 0.5)
    path = write_int16(tmp_path / "burst.wav", np.concatenate([np.zeros(RATE // 2), loud, np.zeros(RATE)]))
    src = WavLevel(path, attack_s=0.01, release_s=0.3, floor_db=-60.0)
    got = levels(src, 2.0)
    target = 20 * math.log10(0.5 / math.sqrt(2))
    k_on, k_off = 30, 60  # ticks at 0.5 s and 1.0 s
    assert got[k_on - 1] == -60.0
    assert got[k_on + 3] > target - 1.0  # within 1 dB after 4 ticks (67 ms, ~7 attack constants)
    # release: one tick after the end it has fallen by (1 - exp(-dt / release)) of the gap, as designed
    gap = -60.0 - got[k_off - 1]
    assert got[k_off] - got[k_off - 1] == pytest.approx(gap * (1 - math.exp(-(1 / 60) / 0.3)), rel=0.05)
    assert got[k_off + 12] > -40.0  # still well above the floor 0.2 s later
    assert got[-1] < -55.0


def test_level_per_tick_uses_only_that_ticks_samples(tmp_path):
    path = write_int16(tmp_path / "step.wav", np.concatenate([np.zeros(RATE), sine(0.9, 1.0)]))
    src = WavLevel(path, attack_s=1e-4)
    assert src.level(0.99) == -60.0  # the loud part starts at 1.0 s
    assert src.level(1.02) > -10.0


def test_not_a_wav_file_names_the_file(tmp_path):
    path = tmp_path / "fake.wav"
    path.write_bytes(b"RIFF\x00\x00\x00\x00nope")
    with pytest.raises(ValueError, match="fake.wav: not a readable WAV file"):
        WavLevel(path)


def test_missing_device_gives_a_message_and_no_audio():
    messages = []
    assert open_audio(device="no such microphone 4242", log=messages.append) is None
    assert len(messages) == 1 and "no audio" in messages[0] and "goes on without audio" in messages[0]
    assert "no such microphone 4242" in messages[0]


def test_read_wav_refuses_stereo_and_non_finite_samples_when_asked(tmp_path):
    from facepuppet.runtime.inputs.audio import read_wav

    s = sine(0.25, 0.1).astype(np.float32)
    stereo = tmp_path / "st.wav"
    wavfile.write(stereo, RATE, np.stack([s, -s], axis=1))
    x, rate = read_wav(stereo)
    assert rate == RATE and x.shape == s.shape and np.abs(x).max() < 1e-7  # mixed: the channels cancel
    with pytest.raises(ValueError, match="st.wav: expected a mono WAV, found 2 channels"):
        read_wav(stereo, stereo="refuse")
    s[10] = np.nan
    bad = tmp_path / "nan.wav"
    wavfile.write(bad, RATE, s)
    with pytest.warns(UserWarning, match=r"nan\.wav: 1 samples NaN or infinite \(read as silence\)"):
        assert read_wav(bad)[0][10] == 0.0  # cleaned, and said once
    with pytest.raises(ValueError, match="nan.wav: 1 samples are NaN"):
        read_wav(bad, finite=True)
    u8 = tmp_path / "u8.wav"
    wavfile.write(u8, RATE, np.array([0, 128, 255], np.uint8))
    np.testing.assert_allclose(read_wav(u8)[0], [-1.0, 0.0, 127 / 128])


def test_a_wav_truncated_to_30_bytes_is_refused_naming_the_file(tmp_path):
    from facepuppet.runtime.errors import InputFileError
    from facepuppet.runtime.inputs.audio import read_wav

    whole = tmp_path / "whole.wav"
    wavfile.write(whole, RATE, (sine(0.25, 0.1) * 32767).astype(np.int16))
    cut = tmp_path / "cut.wav"
    cut.write_bytes(whole.read_bytes()[:30])
    with pytest.raises(InputFileError, match=r"cut\.wav: not a readable WAV file"):
        read_wav(cut)


def test_a_float_wav_of_1e30_samples_reads_at_most_full_scale_and_says_so_once(tmp_path):
    import warnings

    from facepuppet.runtime.inputs.audio import WavLevel

    loud = tmp_path / "loud.wav"
    s = np.full(RATE // 2, 1e30, np.float32)
    s[::2] = -1e30
    s[5] = np.inf
    wavfile.write(loud, RATE, s)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        level = WavLevel(loud, attack_s=0.001)
        levels = [level.level(t) for t in np.arange(1, 40) * 0.01]
    said = [str(w.message) for w in caught]
    assert len(said) == 1 and "loud.wav: 1 samples NaN or infinite" in said[0] and "beyond full scale" in said[0]
    assert max(levels) <= 0.0 and max(levels) > -1.0  # clipped full scale: 0 dBFS, not 600
