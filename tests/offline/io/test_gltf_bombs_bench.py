"""bench gltf-bombs: each forged file through both commands in a process of its own, judged against the budget;
the watcher measures the command's own peak memory and stops a hang or a memory bomb (no speed asserted)."""

from __future__ import annotations

import json
import sys

import pytest

from facepuppet.runtime.cli import main

from facepuppet.offline.io.gltf_bombs_bench import run_command


@pytest.mark.slow
def test_bench_gltf_bombs_writes_each_commands_exit_time_memory_and_verdict(tmp_path, capsys):
    out = tmp_path / "b.json"
    assert main(["bench", "gltf-bombs", "--cases", "nan_weights", "--json", str(out)]) == 0
    r = json.loads(out.read_text())["results"]
    assert set(r["cases"]) == {"nan_weights"} and r["budget"] == {"peak_rss_mb": 256.0, "seconds": 2.0}
    assert r["baseline"]["import_rig"]["exit"] == 0 and r["baseline"]["check_gltf"]["exit"] == 0
    case = r["cases"]["nan_weights"]
    rig = case["import_rig"]
    assert rig["exit"] == 2 and rig["killed"] is None and not rig["traceback"]
    assert "nan_weights.gltf: meshes[0].weights[0]: " in rig["message"]
    assert rig["peak_rss_mb"] > 10 and rig["seconds"] > 0
    assert rig["ok"] == (rig["flags"] == [])
    assert case["ok"] == (rig["ok"] and case["check_gltf"]["ok"]) and r["ok"] == (r["failing"] == [])
    assert "bench gltf-bombs:" in capsys.readouterr().out


@pytest.mark.parametrize("code, timeout_s, kill_mb, killed", [
    ("import time; time.sleep(60)", 1.0, 0, "hang"),
    ("import time; b = bytearray(400 << 20); b[::4096] = b'x' * len(b[::4096]); time.sleep(60)", 60.0, 200, "memory"),
])
def test_the_watcher_stops_a_hang_and_a_memory_bomb(code, timeout_s, kill_mb, killed):
    r = run_command([sys.executable, "-c", code], timeout_s, kill_mb)
    assert r["killed"] == killed and r["exit"] is None


def test_the_peak_memory_is_the_commands_own_not_the_benchmarks():
    """A command that touches 150 MB reports about that, and one that touches nothing far less, whatever the
    process running the benchmark holds."""
    ballast = bytearray(300 << 20)
    ballast[::4096] = b"x" * len(ballast[::4096])  # resident in the test's process
    big = run_command([sys.executable, "-c", "b = bytearray(150 << 20); b[::4096] = b'x' * len(b[::4096])"], 60, 0)
    small = run_command([sys.executable, "-c", "pass"], 60, 0)
    assert big["exit"] == 0 and small["exit"] == 0
    assert 150 < big["peak_rss_mb"] < 250 and small["peak_rss_mb"] < 100
    del ballast
