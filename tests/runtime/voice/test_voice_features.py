"""The streaming log-mel features: the DFT written as matrices against NumPy's FFT, block sizes that do not
matter, no allocation per block, silence at the floor."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from facepuppet.runtime.voice.features import FLOOR_DB, FeatureSpec, VoiceFeatures, features_of, mel_filters


def test_band_energies_equal_those_of_numpys_fft():
    spec = FeatureSpec(n_mels=12, n_taps=1, step=1)
    ex = VoiceFeatures(spec)
    n = ex.window_n
    x = np.random.default_rng(1).uniform(-0.5, 0.5, ex.hop_n * (n // ex.hop_n + 1))
    ex.push(x)  # the last hop ends with the last sample: its window is the last n samples
    x = x[-n:]
    hann = 0.5 - 0.5 * np.cos(2 * np.pi * (np.arange(n) + 0.5) / n)
    power = np.abs(np.fft.rfft(x * hann)) ** 2 / (hann.sum() / 2) ** 2
    bands = 10 * np.log10(mel_filters(12, n, spec.sample_rate, spec.fmin, spec.fmax) @ power)
    np.testing.assert_allclose(ex.vector()[:12], bands, atol=1e-6)


def test_a_full_scale_sine_reads_about_0_db_in_its_band():
    spec = FeatureSpec(n_taps=1)
    t = np.arange(int(0.1 * spec.sample_rate)) / spec.sample_rate
    v = features_of(np.sin(2 * np.pi * 1000 * t), spec, np.array([0.1]))[0]
    assert -12.0 < v[:-1].max() < 0.5  # band energies are averages over the band's bins
    assert v[-1] == pytest.approx(-3.01, abs=0.1)  # the level: a full-scale sine's RMS


def test_the_features_do_not_depend_on_how_the_samples_are_cut_into_blocks():
    spec = FeatureSpec()
    x = np.random.default_rng(2).uniform(-0.3, 0.3, 8000)
    whole = VoiceFeatures(spec)
    whole.push(x)
    cut = VoiceFeatures(spec)
    rng = np.random.default_rng(3)
    at = 0
    while at < len(x):
        k = int(rng.integers(1, 700))
        cut.push(x[at:at + k])
        at += k
    assert cut.hops == whole.hops == len(x) // whole.hop_n
    np.testing.assert_array_equal(cut.vector(), whole.vector())


def test_silence_is_the_floor_and_features_are_causal():
    spec = FeatureSpec()
    x = np.zeros(16000)
    x[8000:] = 0.5 * np.sin(np.arange(8000) * 0.3)
    f = features_of(x, spec, np.array([0.4, 0.49, 0.6]))
    assert (f[0] == FLOOR_DB).all() and (f[1] == FLOOR_DB).all()  # before the sound starts: nothing of it
    assert f[2][-1] > -10


@pytest.mark.parametrize("level_ref_s", [0.0, 3.0])
def test_a_block_allocates_nothing_that_grows_with_the_spectrum(level_ref_s):
    ex = VoiceFeatures(FeatureSpec(level_ref_s=level_ref_s))
    block = np.random.default_rng(4).uniform(-0.3, 0.3, 480)
    for _ in range(5):
        ex.push(block)
        ex.vector()
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        for _ in range(50):
            ex.push(block)
            ex.vector()
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    # a spectrum is (window // 2 + 1) float64 = 4 KiB; per-block temporaries of that size would show here
    assert peak < 1024, peak


def _speechlike(seconds: float, rate: int = 16000) -> np.ndarray:
    """Bursts of a buzzy vowel with pauses, its loudness wandering by +-6 dB."""
    t = np.arange(int(seconds * rate)) / rate
    buzz = np.sign(np.sin(2 * np.pi * 140 * t)) * np.sin(2 * np.pi * 700 * t) + 0.5 * np.sin(2 * np.pi * 2300 * t)
    gain = 10 ** (6 * np.sin(2 * np.pi * 0.3 * t) / 20)
    return 0.2 * gain * buzz * (np.sin(2 * np.pi * 2.1 * t) > -0.3)


def test_with_a_running_level_a_quieter_microphone_gives_the_same_features():
    x = _speechlike(12.0)
    relative = FeatureSpec(level_ref_s=3.0)
    early, late = np.arange(60, 90) / 30, np.arange(240, 360) / 30  # 2-3 s, 8-12 s

    def gap(times):
        return np.abs(features_of(x * 10 ** (-10 / 20), relative, times) - features_of(x, relative, times)).max()
    # the running level follows the quieter microphone down (falling with its 3 s time constant): measured
    # 2.9 dB apart at 2 s, 0.23 dB from 8 s on
    assert gap(late) < 0.5 and gap(late) < gap(early) / 4
    # in dBFS the same two stay 10 dB apart
    dbfs_loud = features_of(x, FeatureSpec(), late)
    dbfs_quiet = features_of(x * 10 ** (-10 / 20), FeatureSpec(), late)
    voiced = dbfs_loud[:, -1] > -40
    np.testing.assert_allclose(dbfs_loud[voiced, -1] - dbfs_quiet[voiced, -1], 10.0, atol=1e-6)
    # silence stays the floor under the running level
    f = features_of(np.r_[x[:16000], np.zeros(16000)], relative, np.array([1.9]))
    assert (f == -60.0).all()


def test_a_pause_with_a_rooms_noise_does_not_drag_the_running_level_down_to_it():
    rate = 16000
    x = _speechlike(6.0)
    noise = 10 ** (-40 / 20) * np.random.default_rng(0).uniform(-1, 1, 6 * rate)  # -45 dBFS: ~29 dB under
    ex = VoiceFeatures(FeatureSpec(level_ref_s=3.0))
    ex.push(x)
    speaking = ex.ref_db
    ex.push(noise)
    assert ex.ref_db > speaking - 1.0, (speaking, ex.ref_db)


@pytest.mark.parametrize("bad", [{"n_mels": 0}, {"hop_s": 0.5}, {"fmax": 9000.0}, {"window_s": float("nan")},
                                 {"level_ref_s": -1.0}, {"level_ref_s": 0.01}])
def test_a_bad_spec_is_refused_naming_the_field(bad):
    with pytest.raises(ValueError, match="FeatureSpec"):
        FeatureSpec(**bad)
