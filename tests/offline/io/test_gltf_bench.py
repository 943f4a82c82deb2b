"""bench gltf: runs on a small character and writes its times and the check's verdict as JSON (no speed asserted)."""

from __future__ import annotations

import json
from pathlib import Path

from facepuppet.runtime.cli import main

TABLES_V1 = Path(__file__).resolve().parents[2] / "runtime" / "files" / "data" / "tables_v1" / "character.npz"


def test_bench_gltf_writes_its_json(tmp_path, capsys):
    out = tmp_path / "b.json"
    assert main(["bench", "gltf", "-c", str(TABLES_V1), "--repeats", "2", "--json", str(out)]) == 0
    r = json.loads(out.read_text())["results"]
    assert r["repeats"] == 2 and r["check_problems"] == [] and r["goal_s"] == 3.0
    assert r["export_s"]["median"] > 0 and r["export_s"]["max"] >= r["export_s"]["median"]
    assert r["file_mb"] > 0 and "bench gltf:" in capsys.readouterr().out
    assert main(["bench", "gltf", "-c", str(TABLES_V1), "--repeats", "0"]) == 2
