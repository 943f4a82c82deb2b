"""``perfect-sync`` without ``--source``: the data kit's ICT head, fitted once and cached; without a kit,
a refusal saying what to pass, before any work and writing nothing."""

import re

import numpy as np
import pytest

from facepuppet.runtime.cli import main
from facepuppet.runtime.model.character import Character

from facepuppet.offline.perfect_sync.source import cache_dir, default_source
from helpers.logs import said
from tests.conftest import need_shared


def test_no_source_and_no_kit_is_refused_naming_both_ways(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("FACEPUPPET_DATA", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    char = tmp_path / "char.npz"
    from facepuppet.runtime.demo.head import build_demo_character

    build_demo_character().save(char)
    out = tmp_path / "out.npz"
    assert main(["perfect-sync", str(char), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--source" in err and "$FACEPUPPET_DATA" in err and "--data" in err
    assert main(["perfect-sync", str(char), "-o", str(out), "--data", str(tmp_path)]) == 2
    assert str(tmp_path / "ict-facekit") in capsys.readouterr().err  # the kit folder it looked for
    assert not out.exists() and not (tmp_path / "cache").exists()


@pytest.mark.data
@pytest.mark.slow
def test_default_source_is_fitted_once_cached_and_refitted_when_the_cache_is_bad(tmp_path, monkeypatch, capsys):
    kit = need_shared("ict-facekit").parent
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("FACEPUPPET_DATA", raising=False)
    godette = tmp_path / "godette.npz"
    assert main(["import-rig", str(need_shared("gltf", "Godette_vrm_v4.vrm")), "-o", str(godette)]) == 0
    out = tmp_path / "out.npz"
    assert main(["perfect-sync", str(godette), "-o", str(out), "--data", str(kit)]) == 0
    assert "fitting the ICT head" in said(capsys)   # logged (stderr): not a result of the command
    cached = list(cache_dir().glob("ict_elastic_*.npz"))
    assert len(cached) == 1 and cached[0].parent == tmp_path / "cache" / "facepuppet"
    synced = Character.load(out)
    assert "jawOpen" in synced.shape_names and "eyeBlinkLeft" in synced.shape_names

    logged = []
    again = default_source(kit, log=logged.append)  # the second time: read, not fitted
    assert len(logged) == 1 and "fitted before" in logged[0]
    first = default_source(kit, log=lambda _: None)
    assert again.control_names == first.control_names
    assert np.array_equal(again.arrays["params"], first.arrays["params"])

    cached[0].write_bytes(b"not a table")  # a damaged cache: refused by the table checks, fitted again
    logged.clear()
    refit = default_source(kit, log=logged.append)
    assert "does not load" in logged[0] and "fitting the ICT head" in logged[1]
    # the fit's steps are said as they come (a first run waits tens of seconds on it)
    assert re.fullmatch(r"perfect-sync: source: 5\d shapes read in [\d.]+ s; fitting the elastic basis \(\d+ "
                        r"vertices, \d+ control points\)", logged[2]), logged
    assert re.fullmatch(r"perfect-sync: source: fitted in [\d.]+ s", logged[3]), logged
    assert np.allclose(refit.arrays["params"], first.arrays["params"])
    assert default_source(kit, log=logged.append) is not None and "fitted before" in logged[-1]
