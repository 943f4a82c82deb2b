"""``facepuppet bench tables``: runs, writes JSON, and every forgery is refused by name (a small bomb here)."""

from __future__ import annotations

import json
from pathlib import Path

from facepuppet.runtime.cli import main

CHARACTER = Path(__file__).resolve().parents[1] / "files" / "data" / "tables_v1" / "character.npz"


def test_bench_tables_refuses_each_forgery_and_writes_json(tmp_path, capsys):
    out = tmp_path / "tables.json"
    assert main(["bench", "tables", "--json", str(out), "-c", str(CHARACTER), "--inflate-mb", "100"]) == 0
    results = json.loads(out.read_text())["results"]
    assert results["baseline"]["said"] == "loaded"
    for case in ("section_bomb", "consistent_section_bomb", "padded_manifest"):
        said = results[case]["said"]
        assert said.startswith("TablesError: ") and case in said, said
        assert results[case]["file_bytes"] < 100e6 / 50  # a bomb: tiny on disk
        # refused before inflating: the child's peak stays near loading the real file (the old loader
        # held the 100 MB it inflated, twice)
        assert results[case]["peak_rss_mb"] < results["baseline"]["peak_rss_mb"] + 30
