"""Batch job folders made from real replays: ``facepuppet replay --out --dump-weights`` of a take on a character,
with the manifest the batch runner writes around its outputs (``offline/batch/golden_jobs.py`` says the layout)."""

from __future__ import annotations

import csv
import hashlib
import json
from pathlib import Path

import numpy as np

from facepuppet.runtime import cli
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.recording.session import SessionWriter

from facepuppet import __version__

SIZE = "64x64"


def write_take(path: Path, drives: dict[str, float], n: int = 12, rate: float = 30.0) -> Path:
    """A session file of ``n`` frames at ``rate`` Hz; each channel of ``drives`` swings up to its amplitude."""
    names = tuple(drives)
    with SessionWriter(path) as w:
        for i in range(n):
            weights = np.array([a * (0.5 + 0.5 * np.sin(i / 2 + k)) for k, a in enumerate(drives.values())],
                               np.float32)
            w.write_frame(Frame(t=i / rate, source="test", channels=names, weights=weights))
    return path


def sha256(path: Path) -> str:
    return "sha256:" + hashlib.sha256(Path(path).read_bytes()).hexdigest()


def replay_job(run_dir: Path, job_id: str, take: Path, character: Path, path: str = "cpu") -> Path:
    """``run_dir/job_id``: a real replay's frames and weights, and its manifest; returns the folder."""
    folder = run_dir / job_id
    folder.mkdir(parents=True)
    rc = cli.main(["replay", str(take), "-c", str(character), "--headless", "--size", SIZE, "--path", path,
                   "--out", str(folder / "frames"), "--dump-weights", str(folder / "weights.npy")])
    assert rc == 0, f"replay of {take} on {character} exited {rc}"
    with open(folder / "frames" / "frames.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    manifest = {
        "format": "facepuppet-batch-job", "version": 1, "job": job_id, "take": str(take),
        "character": str(character), "inputs": {str(take): sha256(take), str(character): sha256(character)},
        "options": {"size": SIZE, "path": path}, "facepuppet": __version__, "path": path,
        "outputs": {"weights": "weights.npy", "frames": [f"frames/frame_{int(r['frame']):05d}.png" for r in rows],
                    "frame_times": [float(r["t"]) for r in rows]},
        "channels": list(Character.load(character).shape_names),
        "figures": {"ticks": len(np.load(folder / "weights.npy")), "wall_s": 0.0}, "status": "ok"}
    (folder / "manifest.json").write_text(json.dumps(manifest, indent=1))
    return folder


def edit_manifest(folder: Path, **fields: object) -> None:
    """Set top-level fields of ``folder``'s manifest (``outputs`` replaced whole when given)."""
    path = folder / "manifest.json"
    doc = json.loads(path.read_text())
    doc.update(fields)
    path.write_text(json.dumps(doc))
