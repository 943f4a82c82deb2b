"""The voice table: its file round trip, a damaged one refused naming the file and the field, silence a closed
mouth, a full-scale tone and white noise bounded, no allocation per evaluation."""

from __future__ import annotations

import json
import subprocess
import sys
import tracemalloc
import zipfile

import numpy as np
import pytest

from facepuppet.runtime.files.tables import TablesError
from facepuppet.runtime.voice.features import FeatureSpec, features_of
from facepuppet.runtime.voice.table import VoiceTable

from helpers.voice_tables import small_table, vowel_buzz


@pytest.mark.parametrize("model", ["level", "ridge", "kpls", "blend"])
def test_a_saved_table_loads_and_predicts_the_same(tmp_path, model):
    table = small_table(model)
    loaded = VoiceTable.load(table.save(tmp_path / "v.npz"))
    X = features_of(vowel_buzz(1.0), table.spec, np.arange(30) / 30)
    assert loaded.outputs == table.outputs and loaded.model == model
    np.testing.assert_array_equal(loaded.predict(X), table.predict(X))
    assert (tmp_path / "v.npz").stat().st_size < 1_000_000


@pytest.mark.parametrize("model", ["ridge", "kpls", "blend"])
def test_silence_is_a_closed_mouth_and_loud_sounds_stay_bounded(model):
    table = small_table(model)
    rate = int(table.spec.sample_rate)
    t = np.arange(rate) / rate
    sounds = {"silence": np.zeros(rate), "tone": np.sin(2 * np.pi * 300 * t),
              "noise": np.clip(np.random.default_rng(0).standard_normal(rate), -1, 1),
              "square": np.sign(np.sin(2 * np.pi * 100 * t))}
    for name, x in sounds.items():
        y = table.predict(features_of(x, table.spec, np.arange(1, 30) / 30))
        assert np.isfinite(y).all() and (y >= 0).all() and (y <= 1).all(), name
        if name == "silence":
            assert (y == 0).all()
    loud = table.predict(features_of(sounds["square"], table.spec, np.array([0.5])))
    assert loud.max() > 0  # the gate opens for a sound


@pytest.mark.parametrize("model", ["kpls", "blend"])
def test_an_evaluation_allocates_nothing_that_grows_with_the_table(model):
    table = small_table(model)
    ev = table.evaluator()
    x = features_of(vowel_buzz(0.5), table.spec, np.array([0.3]))[0]
    ev(x)
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        for _ in range(50):
            ev(x)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert peak < 512, peak


def _rewrite(src, dst, change, drop=None):
    """Copy a tables file, changing its arrays or manifest through ``change(name, bytes) -> bytes``, leaving out
    the member ``drop``."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            if item.filename == drop:
                continue
            zout.writestr(item, change(item.filename, zin.read(item.filename)))


def _npy(arr) -> bytes:
    import io

    buf = io.BytesIO()
    np.save(buf, arr, allow_pickle=False)
    return buf.getvalue()


def test_a_table_on_relative_features_keeps_their_time_constant(tmp_path):
    table = small_table("ridge", level_ref_s=3.0)
    loaded = VoiceTable.load(table.save(tmp_path / "r.npz"))
    assert loaded.spec.level_ref_s == 3.0 and loaded.spec == table.spec
    assert small_table("ridge").spec.level_ref_s == 0.0  # a table without the section reads dBFS
    with zipfile.ZipFile(tmp_path / "r.npz") as z:
        assert "feature_level_ref.npy" in z.namelist()


@pytest.mark.parametrize("section,value,field", [
    ("model_params", np.array([7.0, 1.0, 0.0, -60.0]), "model_params"),
    ("feature_spec", np.array([16000, 0.032, 0.01, 8, 80, 7000, 3.5, 2]), "feature_spec"),
    ("feature_scale", np.zeros(25, np.float32), "feature_scale"),
    ("feature_level_ref", np.array([0.01]), "feature_level_ref"),
    ("feature_level_ref", np.array([np.inf]), "feature_level_ref"),
])
def test_a_damaged_table_is_refused_naming_the_file_and_the_field(tmp_path, section, value, field):
    good = small_table("ridge", level_ref_s=3.0).save(tmp_path / "good.npz")
    bad = tmp_path / "bad.npz"
    _rewrite(good, bad, lambda name, data: _npy(value) if name == f"{section}.npy" else data)
    with pytest.raises(TablesError, match=rf"{bad}: {field}"):
        VoiceTable.load(bad)


def test_a_kpls_table_without_its_kernel_rows_is_refused(tmp_path):
    good = small_table("ridge").save(tmp_path / "good.npz")
    bad = tmp_path / "bad.npz"

    def change(name, data):
        if name == "model_params.npy":
            return _npy(np.array([2.0, 1.0, 0.0, -60.0]))
        return data
    _rewrite(good, bad, change)
    with pytest.raises(TablesError, match=rf"{bad}: train_inputs: the kpls model needs this section"):
        VoiceTable.load(bad)


@pytest.mark.parametrize("section,value,message", [
    ("tree_feature", np.full((8, 3), 25, np.int32), "feature indices must lie in 0..24"),
    ("tree_feature", np.full((8, 3), -1, np.int32), "feature indices must lie in 0..24"),
    ("tree_value", np.zeros((8, 5), np.float32), "are not complete trees"),
    ("tree_threshold", np.full((8, 3), np.nan), "NaN or infinity"),
    ("tree_value", None, "the blend model needs this section"),
])
def test_a_damaged_blend_table_is_refused_naming_the_tree_field(tmp_path, section, value, message):
    good = small_table("blend").save(tmp_path / "good.npz")
    bad = tmp_path / "bad.npz"
    with zipfile.ZipFile(good) as z:
        assert f"{section}.npy" in z.namelist()  # the section this case damages is one the table has
    if value is None:  # the section left out, and the manifest with it
        def change(name, data):
            if name == "__manifest__.npy":
                manifest = json.loads(np.load(__import__("io").BytesIO(data)).tobytes().decode())
                del manifest["sections"][section]
                return _npy(np.frombuffer(json.dumps(manifest).encode(), np.uint8))
            return data
    else:
        def change(name, data):
            if name == "__manifest__.npy":
                manifest = json.loads(np.load(__import__("io").BytesIO(data)).tobytes().decode())
                manifest["sections"][section]["shape"] = list(value.shape)
                manifest["sections"][section].pop("sha256", None)
                return _npy(np.frombuffer(json.dumps(manifest).encode(), np.uint8))
            return _npy(value) if name == f"{section}.npy" else data
    _rewrite(good, bad, change, drop=f"{section}.npy" if value is None else None)
    with pytest.raises(TablesError, match=rf"{bad}: {section}") as err:
        VoiceTable.load(bad)
    assert message in str(err.value), err.value


def test_run_refuses_a_damaged_voice_table_with_exit_2_naming_it(tmp_path):
    from helpers.small_characters import sphere_character

    good = small_table("ridge").save(tmp_path / "good.npz")
    bad = tmp_path / "bad.npz"

    def change(name, data):
        if name == "__manifest__.npy":
            manifest = json.loads(np.load(__import__("io").BytesIO(data)).tobytes().decode())
            manifest["channels"]["outputs"] = ["jawOpen"]
            return _npy(np.frombuffer(json.dumps(manifest).encode(), np.uint8))
        return data
    _rewrite(good, bad, change)
    char = sphere_character().save(tmp_path / "c.npz")
    wav = tmp_path / "s.wav"
    from helpers.voice_tables import write_wav

    write_wav(wav, vowel_buzz(0.3))
    proc = subprocess.run([sys.executable, "-m", "facepuppet", "run", "-c", str(char), "--input", "audio",
                           "--voice", str(bad), "--audio-file", str(wav), "--headless", "--duration", "0.2"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert str(bad) in proc.stderr and "outputs" in proc.stderr, proc.stderr


def test_a_spec_at_another_rate_keeps_the_bands_in_hertz():
    spec = FeatureSpec()
    other = spec.at_rate(48000)
    assert other.sample_rate == 48000 and other.fmax == spec.fmax and other.window_s == spec.window_s
