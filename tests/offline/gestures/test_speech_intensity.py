"""Speech intensity: dB per animation frame; other rates, silence, stereo and NaN handled clearly."""

import numpy as np
import pytest
from scipy.io import wavfile

from facepuppet.runtime.gestures.layer import SILENCE_Z

from facepuppet.offline.gestures.speech_intensity import FLOOR_DB, SpeechInputError, speech_intensity
from tests.conftest import need_shared


def tone(rate, seconds=2.0, amp=0.5):
    t = np.arange(int(rate * seconds)) / rate
    x = amp * np.sin(2 * np.pi * 220 * t) * (t >= 1.0)  # silence, then a tone
    return x


def test_int16_level_in_dbfs_and_silence_at_floor(tmp_path):
    wavfile.write(tmp_path / "a.wav", 16000, (tone(16000) * 32767).astype(np.int16))
    level, z, (mean, std, gate) = speech_intensity(tmp_path / "a.wav", fps=30)
    assert len(level) == 60
    assert level[45] == pytest.approx(20 * np.log10(0.5 / np.sqrt(2)), abs=0.1)  # sine RMS
    assert level[10] == FLOOR_DB and z[10] == SILENCE_Z


def test_another_rate_is_resampled_to_the_same_levels(tmp_path):
    wavfile.write(tmp_path / "a.wav", 16000, tone(16000).astype(np.float32))
    wavfile.write(tmp_path / "b.wav", 44100, tone(44100).astype(np.float32))
    la, _, _ = speech_intensity(tmp_path / "a.wav")
    lb, _, _ = speech_intensity(tmp_path / "b.wav")
    np.testing.assert_allclose(la[35:], lb[35:], atol=0.2)


def test_all_silence_gives_the_floor_and_warns(tmp_path):
    wavfile.write(tmp_path / "s.wav", 16000, np.zeros(16000, np.int16))
    with pytest.warns(RuntimeWarning, match="silence"):
        level, z, _ = speech_intensity(tmp_path / "s.wav")
    assert (level == FLOOR_DB).all() and (z == SILENCE_Z).all()


def test_stereo_is_refused_unless_mixed(tmp_path):
    x = tone(16000).astype(np.float32)
    wavfile.write(tmp_path / "st.wav", 16000, np.column_stack([x, x]))
    with pytest.raises(SpeechInputError, match="mono.*2 channels"):
        speech_intensity(tmp_path / "st.wav")
    level, _, _ = speech_intensity(tmp_path / "st.wav", stereo="mix")
    assert level[45] > -10


def test_nan_samples_are_refused(tmp_path):
    x = tone(16000).astype(np.float32)
    x[100] = np.nan
    wavfile.write(tmp_path / "n.wav", 16000, x)
    with pytest.raises(SpeechInputError, match="NaN"):
        speech_intensity(tmp_path / "n.wav")


@pytest.mark.data
def test_real_speech_is_loud_in_the_middle_and_quiet_at_the_ends():
    path = need_shared("speech", "arctic_a0007.wav")
    level, z, _ = speech_intensity(path, fps=30)
    assert len(level) == 120
    assert np.median(level[30:90]) > np.median(level[:8]) + 20


def test_room_noise_before_the_words_is_gated_to_silence(tmp_path):
    rate = 16000
    rng = np.random.default_rng(0)
    x = rng.normal(0, 10 ** (-48 / 20), 3 * rate)            # -48 dBFS room noise throughout
    x[rate:2 * rate] += 0.3 * np.sin(np.arange(rate) / rate * 2 * np.pi * 220)
    wavfile.write(tmp_path / "n.wav", rate, x.astype(np.float32))
    level, z, (mean, std, gate) = speech_intensity(tmp_path / "n.wav", fps=30)
    assert -49 < level[10] < -46 and level[45] > -20
    assert -45 < gate < -40                                   # 10th percentile (~-48) + 6 dB
    assert (z[:25] == SILENCE_Z).all() and (z[35:55] > SILENCE_Z).all()
    assert mean == pytest.approx(np.mean(level[level > gate]))
