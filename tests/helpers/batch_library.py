"""A small take library for ``facepuppet batch``: short session takes, two small characters, a jobs file."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.recording.session import SessionWriter

from helpers.small_characters import sphere_character

REPO = Path(__file__).resolve().parents[2]


def write_take(path: Path, seconds: float, phase: float = 0.0, rate: float = 30.0) -> Path:
    """A session take driving jawOpen and puff (the sphere's shapes) for ``seconds`` at ``rate`` frames/s."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with SessionWriter(path, overwrite=True) as w:
        for i in range(int(round(seconds * rate))):
            w.write_frame(Frame(t=i / rate, source="test", channels=("jawOpen", "puff"),
                                weights=np.array([0.5 + 0.5 * np.sin(i / 5 + phase), 0.25 + 0.2 * np.cos(i / 7)],
                                                 np.float32)))
    return path


def write_characters(folder: Path) -> list[Path]:
    """Two small characters: the sphere with its hidden occluder and without (different meshes, same shapes)."""
    folder.mkdir(parents=True, exist_ok=True)
    return [sphere_character(True).save(folder / "sphere.npz"),
            sphere_character(False).save(folder / "bare.npz")]


def library(root: Path, n_takes: int = 2, seconds: float = 1.0, outputs: str = "", group: str = "g") -> Path:
    """Takes ``root/takes/take{i}.fps``, the characters in ``root/chars``, and ``root/jobs.toml`` crossing them
    on the CPU path at 64x48; ``outputs``: the lines of the group's outputs table. The jobs file's path."""
    for i in range(n_takes):
        write_take(root / "takes" / f"take{i}.fps", seconds, phase=i)
    write_characters(root / "chars")
    jobs = root / "jobs.toml"
    jobs.write_text(f'[groups.{group}]\ntakes = ["takes/*.fps"]\ncharacters = ["chars/*.npz"]\npath = "cpu"\n'
                    f'size = "64x48"\n[groups.{group}.outputs]\n{outputs}\n')
    return jobs


def batch_command(*args: str) -> list[str]:
    """The real ``facepuppet`` command (this interpreter's) with ``args``."""
    return [sys.executable, "-m", "facepuppet", *args]


def run_batch(*args: str, timeout_s: float = 240.0) -> subprocess.CompletedProcess:
    """``facepuppet batch ARGS`` in a subprocess; its exit code and output (a hang ends at ``timeout_s``)."""
    return subprocess.run(batch_command("batch", *args), capture_output=True, text=True, timeout=timeout_s,
                          cwd=REPO)
