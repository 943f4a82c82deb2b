"""``facepuppet batch`` on a real Dask LocalCluster of 2 worker processes: results equal a plain replay's,
a second run skips everything, a worker killed mid-job still yields every result once, a damaged take or a
missing character fails its own job only."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime import cli
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.recording.livelinkface_csv import read_llf_csv

from facepuppet.offline.batch.curves import arkit_curves
from facepuppet.offline.batch.job_run import PARTIAL
from helpers.batch_library import REPO, batch_command, library, run_batch, write_take

pytest.importorskip("distributed")
pytestmark = [pytest.mark.gl, pytest.mark.slow]  # the workers open EGL contexts; a cluster takes seconds to start

FRAMES = "weights = true\ncurves = true\nframes = [0.0, 0.4, 0.9]\ncontact_sheet = true"


def _manifests(out: Path) -> dict[str, dict]:
    return {p.parent.name: json.loads(p.read_text()) for p in out.glob("*/manifest.json")}


def _plain_replay(tmp: Path, manifest: dict, root: Path) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """The same job as a plain ``facepuppet replay``: its weights and its PNGs by tick."""
    options = manifest["options"]
    tmp.mkdir()
    pngs, weights = tmp / "pngs", tmp / "w.npy"
    assert cli.main(["replay", str(root / manifest["take"]), "-c", str(root / manifest["character"]), "--headless",
                     "--size", options["size"], "--path", options["path"], "--dump-weights", str(weights),
                     "--out", str(pngs)]) == 0
    with open(pngs / "frames.csv", newline="") as f:
        by_tick = {int(row["tick"]): np.asarray(Image.open(pngs / f"frame_{int(row['frame']):05d}.png"))
                   for row in csv.DictReader(f)}
    return np.load(weights), by_tick


def test_batch_equals_plain_replays_and_a_second_run_skips_everything(tmp_path, capsys):
    root = tmp_path / "lib"
    jobs = library(root, n_takes=2, outputs=FRAMES)
    out = tmp_path / "out"
    first = run_batch(str(jobs), "--out", str(out), "--workers", "2")
    assert first.returncode == 0, first.stdout + first.stderr
    assert "4 jobs in 1 group: 0 done already, 4 to run" in first.stdout
    assert "local cluster of 2 worker processes" in first.stdout
    manifests = _manifests(out)
    assert sorted(manifests) == sorted(f"take{i}--{c}--g" for i in range(2) for c in ("sphere", "bare"))
    assert not (out / PARTIAL).exists()
    for job_id, manifest in manifests.items():
        folder = out / job_id
        assert manifest["status"] == "ok" and manifest["path"] == "cpu"
        assert set(manifest["inputs"]) == {manifest["take"], manifest["character"]}
        weights, pngs = _plain_replay(tmp_path / job_id, manifest, root)
        ours = np.load(folder / manifest["outputs"]["weights"])
        assert ours.dtype == np.float32 and ours.shape == weights.shape == (30, 2)
        assert ours.tobytes() == weights.tobytes()  # bit for bit
        assert manifest["channels"] == ["jawOpen", "puff"]
        outputs = manifest["outputs"]
        assert outputs["frame_times"] == [0.0, 0.4, 0.9] and len(outputs["frames"]) == 3
        for name, tick in zip(outputs["frames"], outputs["frame_ticks"]):
            assert np.array_equal(np.asarray(Image.open(folder / name)), pngs[tick])  # pixel for pixel
        assert outputs["frame_ticks"] == [0, 12, 27]  # the first tick at or after each time, at 30 ticks/s
        curves = read_llf_csv(folder / outputs["curves"])
        assert [f.t for f in curves] == pytest.approx([k / 30 for k in range(30)], abs=1e-6)
        expected = arkit_curves(weights, manifest["channels"])
        names = {n.lower(): i for i, n in enumerate(curves[0].channels)}
        jaw = ARKIT_NAMES.index("jawOpen")
        assert np.allclose([f.weights[names["jawopen"]] for f in curves], expected[:, jaw], atol=1e-6)
        assert (folder / outputs["sheet"]).is_file()
    stamps = {p: p.stat().st_mtime_ns for p in out.glob("*/manifest.json")}

    second = run_batch(str(jobs), "--out", str(out), "--workers", "2")
    assert second.returncode == 0, second.stdout + second.stderr
    assert "4 jobs in 1 group: 4 done already, 0 to run" in second.stdout
    assert "local cluster" not in second.stdout  # nothing to run: no cluster started
    assert {p: p.stat().st_mtime_ns for p in out.glob("*/manifest.json")} == stamps
    assert json.loads((out / "batch.json").read_text())["counts"] == {"ok": 0, "skipped": 4, "failed": 0}


def test_a_worker_killed_mid_job_still_yields_every_result_once(tmp_path):
    root = tmp_path / "lib"
    jobs = library(root, n_takes=3, seconds=4.0)  # long enough takes that a job is caught running
    out = tmp_path / "out"
    proc = subprocess.Popen(batch_command("batch", str(jobs), "--out", str(out), "--workers", "2"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
    killed = None
    try:
        deadline = time.monotonic() + 180  # a guard against a hang, not a limit on speed
        while killed is None and proc.poll() is None and time.monotonic() < deadline:
            running = list((out / PARTIAL).glob("*.*.*")) if (out / PARTIAL).is_dir() else []
            if running:
                job_id, pid = running[0].name.split(".")[:2]
                os.kill(int(pid), signal.SIGKILL)  # the worker process running that job, mid-job
                killed = job_id
            time.sleep(0.01)
        stdout, stderr = proc.communicate(timeout=240)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert killed is not None, "no job was seen running"
    assert proc.returncode == 0, stdout + stderr
    manifests = _manifests(out)
    expected = sorted(f"take{i}--{c}--g" for i in range(3) for c in ("sphere", "bare"))
    assert sorted(manifests) == expected and killed in manifests
    assert sorted(p.name for p in out.iterdir()) == sorted([*expected, "batch.json"])  # nothing half-written
    summary = json.loads((out / "batch.json").read_text())
    assert summary["counts"] == {"ok": 6, "skipped": 0, "failed": 0} and sorted(summary["jobs"]) == expected
    assert stdout.count("FAILED") == 0
    for manifest in manifests.values():
        assert np.load(out / manifest["job"] / "weights.npy").shape == (120, 2)


def test_a_damaged_take_and_a_missing_character_fail_their_jobs_only(tmp_path):
    root = tmp_path / "lib"
    write_take(root / "takes" / "good.fps", 0.5)
    damaged = root / "takes" / "damaged.csv"
    damaged.write_text("Timecode,BlendShapeCount,JawOpen\n00:00:00:00.000,1,0.5\n00:00:00:01.000,1\n")
    library(root, n_takes=0)
    jobs = root / "jobs.toml"
    jobs.write_text('[groups.g]\ntakes = ["takes/good.fps", "takes/damaged.csv"]\n'
                    'characters = ["chars/sphere.npz", "chars/missing.npz"]\npath = "cpu"\nsize = "32x24"\n')
    out = tmp_path / "out"
    stale = out / "damaged--sphere--g"  # a result of other inputs, from an earlier run
    stale.mkdir(parents=True)
    (stale / "manifest.json").write_text("{}")
    result = run_batch(str(jobs), "--out", str(out), "--workers", "2")
    assert result.returncode == 1, result.stdout + result.stderr
    assert not stale.exists()  # a failed job leaves no folder a comparison could take for this run's
    assert sorted(_manifests(out)) == ["good--sphere--g"]
    failed = [line for line in result.stdout.splitlines() if "FAILED" in line]
    assert len(failed) == 3
    assert any(line.startswith("batch: damaged--sphere--g: FAILED") and "damaged.csv, line 3" in line
               for line in failed)
    assert any(line.startswith("batch: good--missing--g: FAILED") and "missing.npz" in line for line in failed)
    summary = json.loads((out / "batch.json").read_text())
    assert summary["counts"] == {"ok": 1, "skipped": 0, "failed": 3}
    assert "missing.npz" in summary["jobs"]["good--missing--g"]["message"]


def test_against_an_earlier_run_names_exactly_the_jobs_of_the_character_whose_shape_changed(tmp_path):
    root = tmp_path / "lib"
    jobs = library(root, n_takes=2, outputs="weights = true\nframes = [0.3, 0.6]")
    old, new = tmp_path / "old", tmp_path / "new"
    first = run_batch(str(jobs), "--out", str(old), "--workers", "2")
    assert first.returncode == 0, first.stdout + first.stderr
    bare = Character.load(root / "chars" / "bare.npz")
    positions = np.array(bare.delta_positions)
    positions[bare.shape_slice(bare.shape_names.index("puff"))] *= 1.5  # the rig change: one shape
    bare.with_parts(delta_positions=positions).save(root / "chars" / "bare.npz")
    second = run_batch(str(jobs), "--out", str(new), "--against", str(old), "--workers", "2")
    assert second.returncode == 1, second.stdout + second.stderr  # something changed beyond tolerance
    report = json.loads((new / "report" / "report.json").read_text())
    assert sorted(report["changed"]) == ["take0--bare--g", "take1--bare--g"]
    assert "2 changed beyond tolerance" in second.stdout and (new / "report" / "report.md").is_file()
    same = run_batch(str(jobs), "--out", str(new), "--against", str(new / ".." / "new"), "--workers", "2")
    assert same.returncode == 2 and "the same folder as --out" in same.stderr


def _free_tcp_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_batch_runs_on_an_existing_cluster_given_by_scheduler(tmp_path):
    """``--scheduler tcp://...``: a real ``dask scheduler`` and ``dask worker`` (separate processes, on
    127.0.0.1) run the jobs, with the same weights a local cluster gives."""
    import sys

    root = tmp_path / "lib"
    jobs = library(root, n_takes=1, outputs="weights = true")
    port = _free_tcp_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "PYTHONPATH": str(REPO / "tests")}
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                  "--port", str(port), "--no-dashboard"], cwd=REPO, env=env,
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "1",
                               "--nthreads", "1", "--host", "127.0.0.1", "--no-dashboard"], cwd=REPO, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        remote = run_batch(str(jobs), "--out", str(tmp_path / "remote"), "--scheduler", address)
        assert remote.returncode == 0, remote.stdout + remote.stderr
        assert "local cluster" not in remote.stdout and address in remote.stdout
        local = run_batch(str(jobs), "--out", str(tmp_path / "local"), "--workers", "1")
        assert local.returncode == 0, local.stdout + local.stderr
        ours, theirs = _manifests(tmp_path / "remote"), _manifests(tmp_path / "local")
        assert sorted(ours) == sorted(theirs) == ["take0--bare--g", "take0--sphere--g"]
        for job in ours:
            a = np.load(tmp_path / "remote" / job / "weights.npy")
            b = np.load(tmp_path / "local" / job / "weights.npy")
            assert a.tobytes() == b.tobytes()
    finally:
        for proc in (worker, scheduler):
            proc.terminate()
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
