"""fit-voice and voice-curves: contiguous folds, the runtime table predicting what the fit predicted, a kernel-PLS
table equal to the offline model, and the command line on the kit's speech pair."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from facepuppet.runtime.voice.features import FeatureSpec, features_of
from facepuppet.runtime.voice.table import VoiceTable

from facepuppet.offline.gestures.speech_intensity import read_speech
from facepuppet.offline.kpls.model import KernelPLS
from facepuppet.offline.voice.boost import BoostSetting
from facepuppet.offline.voice.fit import (
    Standardise,
    contiguous_folds,
    cross_validate,
    fit_voice,
    report_lines,
    to_table,
)
from helpers.voice_tables import write_wav


def synthetic_pair(tmp_path, seconds=12.0, rate=16000):
    """A buzz whose loudness and brightness change, with 'curves' that follow them: jaw ~ loudness, funnel ~ a
    darker timbre; the sheet maps two controls onto jawOpen and mouthFunnel."""
    t = np.arange(int(seconds * rate)) / rate
    env = 0.5 + 0.5 * np.sin(2 * np.pi * 0.7 * t)
    dark = (np.sin(2 * np.pi * 0.23 * t) > 0).astype(float)
    src = np.sign(np.sin(2 * np.pi * 130 * t))
    x = 0.3 * env * (dark * np.sin(2 * np.pi * 400 * t) + (1 - dark) * np.sin(2 * np.pi * 2500 * t)) * (src > -2)
    write_wav(tmp_path / "s.wav", x)
    frames = np.arange(int(seconds * 30)) / 30
    jaw = np.interp(frames, t, env)
    funnel = np.interp(frames, t, dark) * jaw
    rows = ["time_s,jaw_c,funnel_a,funnel_b"] + [f"{f:.5f},{a:.5f},{b:.5f},{b * 0.5:.5f}"
                                                  for f, a, b in zip(frames, jaw, funnel)]
    (tmp_path / "c.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "map.csv").write_text("arkit,voice2face,status,combine,sources,unknown_sources\n"
                                      "jawOpen,jaw_c,valid,single,jaw_c,\n"
                                      'mouthFunnel,"max(funnel_a,funnel_b)",valid,max,funnel_a;funnel_b,\n'
                                      "eyeBlinkLeft,jaw_c,Invalid,single,jaw_c,\n")
    return tmp_path / "s.wav", tmp_path / "c.csv", tmp_path / "map.csv"


def test_folds_are_contiguous_blocks_covering_every_frame():
    folds = contiguous_folds(103, 5)
    assert np.array_equal(np.concatenate(folds), np.arange(103))
    assert all(np.all(np.diff(f) == 1) for f in folds)


def test_the_fit_learns_the_synthetic_mouth_and_the_table_predicts_like_the_fit(tmp_path):
    pair = synthetic_pair(tmp_path)
    # dBFS features: this mouth follows a 1.4 s loudness cycle, which the default running level (3 s) partly
    # absorbs as a change of microphone gain; speech's jaw moves with its syllables, far faster
    table, report = fit_voice([pair], spec=FeatureSpec(), models=("level", "ridge"), folds=4)
    assert report["channels"] == ["jawOpen", "mouthFunnel"]
    r = report["held_out_r"]
    assert r["ridge"]["mouthFunnel"] > r["level"]["mouthFunnel"] + 0.2  # the timbre carries the funnel
    assert r["ridge"]["jawOpen"] > 0.8
    path = table.save(tmp_path / "v.npz")
    assert path.stat().st_size < 1_000_000
    loaded = VoiceTable.load(path)
    assert loaded.metadata["metrics"]["held_out_r"]["ridge"]["jawOpen"] == pytest.approx(r["ridge"]["jawOpen"])


def test_a_kernel_pls_table_evaluates_the_offline_model_with_runtime_code():
    rng = np.random.default_rng(0)
    spec = FeatureSpec(n_mels=6, n_taps=2, step=1)
    X = rng.normal(-40, 10, (200, spec.n_features))
    X[:, -1] = rng.uniform(-30, -5, 200)  # loud: the gate stays open
    Y = np.clip(np.c_[np.tanh(X[:, 0] / 20 + 2), (X[:, 1] + 60) / 60], 0, 1) * 0.8
    table = to_table("kpls", (5, 0.3), X, Y, ("jawOpen", "mouthFunnel"), spec, 0.0, -70.0, {})
    st = Standardise(X)
    model = KernelPLS(n_components=5, kernel="rbf", gamma=0.3 / X.shape[1]).fit(st(X), Y)
    expected = np.clip(model.predict(st(X[:20])), 0, 1)
    np.testing.assert_allclose(table.predict(X[:20]), expected, atol=2e-4)


def test_settings_are_chosen_without_the_held_out_folds(tmp_path):
    pair = synthetic_pair(tmp_path, seconds=8.0)
    from facepuppet.offline.voice.fit import read_pair

    p = read_pair(*pair, FeatureSpec())
    out = cross_validate(p.X, p.Y, 5, ("ridge",), test_folds=(3, 4))
    pred = out["ridge"]["pred"]
    folds = contiguous_folds(len(p.X), 5)
    assert np.isnan(pred[folds[0]]).all() and np.isfinite(pred[folds[4]]).all()


def test_fit_voice_and_voice_curves_from_the_command_line(tmp_path):
    wav, curves, mapping = synthetic_pair(tmp_path, seconds=6.0)
    out = tmp_path / "v.npz"
    proc = subprocess.run([sys.executable, "-m", "facepuppet", "fit-voice", str(wav), str(curves), "--map",
                           str(mapping), "-o", str(out), "--models", "level,ridge", "--folds", "3"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "held-out r (3 contiguous folds" in proc.stdout and "mouthFunnel" in proc.stdout
    csv = tmp_path / "curves.csv"
    proc = subprocess.run([sys.executable, "-m", "facepuppet", "voice-curves", str(out), str(wav), "-o", str(csv)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    lines = csv.read_text().splitlines()
    assert lines[0] == "time_s,jawOpen,mouthFunnel"
    assert len(lines) - 1 == int(6.0 * 30) + 1
    values = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    assert np.allclose(np.diff(values[:, 0]), 1 / 30, atol=1e-5)
    # what the CLI wrote is what the table gives through the runtime's own features
    table = VoiceTable.load(out)
    Y = table.predict(features_of(read_speech(wav), table.spec, values[:, 0]))
    np.testing.assert_allclose(values[:, 1:], Y, atol=1e-5)


def test_fit_voice_refuses_odd_paths_and_a_missing_map(tmp_path):
    wav, curves, _ = synthetic_pair(tmp_path, seconds=2.0)
    proc = subprocess.run([sys.executable, "-m", "facepuppet", "fit-voice", str(wav), "-o", str(tmp_path / "v.npz")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "SPEECH.wav CURVES.csv pairs" in proc.stderr
    proc = subprocess.run([sys.executable, "-m", "facepuppet", "fit-voice", str(wav), str(curves), "-o",
                           str(tmp_path / "v.npz")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "facegood_to_arkit.csv" in proc.stderr


@pytest.mark.data
@pytest.mark.slow
def test_on_the_kits_speech_every_model_is_scored_and_the_table_is_small(tmp_path):
    from conftest import need_shared

    d = need_shared("speech")
    pair = (d / "facegood_1114_3_15.wav", d / "facegood_1114_3_15_blendshapes.csv", d / "facegood_to_arkit.csv")
    table, report = fit_voice([pair], models=("level", "ridge", "blend"), folds=5)
    r, mean = report["held_out_r"], report["mean_r"]
    assert r["ridge"]["jawOpen"] > r["level"]["jawOpen"]  # measured 0.70 vs 0.63
    assert mean["blend"] > mean["ridge"]  # measured 0.300 vs 0.278
    assert r["blend"]["jawOpen"] > r["ridge"]["jawOpen"]  # measured 0.728 vs 0.700
    assert report["best"] == "blend" and table.model == "blend"
    assert VoiceTable.load(table.save(tmp_path / "b.npz")).metadata["settings"]["trees"]["n_trees"] == \
        BoostSetting().n_trees
    # the same speech 10 dB quieter (another microphone's gain) moves the same mouth once the running level
    # has followed it (the trees' thresholds would not forgive a shift in dBFS)
    assert table.spec.level_ref_s > 0
    speech = read_speech(pair[0])
    times = np.arange(300, 1400) / 30  # from 10 s: the running level has fallen to the quieter speech
    loud = table.predict(features_of(speech, table.spec, times))
    quiet = table.predict(features_of(speech * 10 ** (-10 / 20), table.spec, times))
    diff = np.abs(quiet - loud)
    # measured: p99 0.0012, max 0.018 (bands near the -100 dBFS floor); a blend on dBFS features: p99 0.12, max 0.21
    assert np.percentile(diff, 99) < 0.01 and diff.max() < 0.06
    assert r["ridge"]["mouthFunnel"] > r["level"]["mouthFunnel"]  # measured 0.50 vs 0.35
    assert table.save(tmp_path / "v.npz").stat().st_size < 1_000_000


def test_the_report_names_the_channels_the_kept_model_does_not_lift_above_the_level():
    report = {"folds": 5, "frames": 100, "best": "ridge", "channels": ["jawOpen", "mouthUpperUpLeft"],
              "held_out_r": {"level": {"jawOpen": 0.6, "mouthUpperUpLeft": 0.19},
                             "ridge": {"jawOpen": 0.7, "mouthUpperUpLeft": 0.17}},
              "mean_r": {"level": 0.4, "ridge": 0.43}}
    warnings = [line for line in report_lines(report) if line.startswith("warning:")]
    assert len(warnings) == 1 and "mouthUpperUpLeft" in warnings[0] and "jawOpen" not in warnings[0]
    report["held_out_r"]["ridge"]["mouthUpperUpLeft"] = 0.25  # above the level everywhere: nothing to say
    assert not [line for line in report_lines(report) if line.startswith("warning:")]
