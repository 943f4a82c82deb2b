"""One batch job on a worker: ``facepuppet replay``'s own code on one take and character, outputs into place.

The job's options become ``replay``'s command line, parsed by ``replay``'s own parser into its
:class:`~facepuppet.runtime.commands.replay.ReplayPlan` and played by its
:func:`~facepuppet.runtime.commands.replay.replay`, so a job's weights are a plain replay's, bit for bit, and
its frames are a plain ``replay --out``'s, pixel for pixel. Two things differ, neither touching a result: the
worker draws every job in one headless EGL context (made once per worker thread: making one costs more than a
short take), and a job's frames at chosen times are read by an observer of its own instead of ``--out``
writing every tick.

Everything is written into a folder of its own under ``DIR/.partial/`` (named with the worker's process id, so
an operator, or a test, can tell which worker holds which job); the manifest is written there last, then the
folder is renamed onto ``DIR/<job id>`` (a previous result, now stale, is moved aside first and removed). A
worker killed at any moment leaves at most a folder under ``.partial``, never a folder that passes for a result.

A job that fails (a damaged take, a missing character, any error) returns its message instead of raising:
Dask's own resubmission is kept for what it is for, a worker that died.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import shutil
import threading
import time
import traceback
import uuid
from pathlib import Path

import numpy as np
from PIL import Image

from facepuppet.runtime.commands import replay as replay_command
from facepuppet.runtime.errors import FacepuppetError
from facepuppet.runtime.files.outputs import atomic_path
from facepuppet.runtime.live.loop import TickInfo
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.render.blas_threads import BlasThreads
from facepuppet.runtime.render.gl_context import GLTarget, create_context
from facepuppet.runtime.render.images import contact_sheet

from facepuppet.offline.batch.curves import write_curves
from facepuppet.offline.batch.jobs import Job
from facepuppet.offline.batch.manifest import input_hashes, manifest_of, write_manifest
from facepuppet.offline.io import capture_replay

logger = logging.getLogger(__name__)

PARTIAL = ".partial"
VIDEO = "take.mp4"
_EPS_S = 1e-9
_local = threading.local()


def worker_context() -> GLTarget:
    """This thread's headless context, made at its first job and kept for the next ones."""
    target = getattr(_local, "target", None)
    if target is None:
        target = create_context(headless=True)
        _local.target = target
    return target


def _quiet():
    stream = getattr(_quiet, "stream", None)
    if stream is None:
        stream = _quiet.stream = open(os.devnull, "w")  # kept open for the life of the process
    return stream


def replay_parser() -> argparse.ArgumentParser:
    parser = getattr(_local, "parser", None)
    if parser is None:
        capture_replay.register()  # marker takes, as the `facepuppet` command reads them
        parser = argparse.ArgumentParser(prog="facepuppet")
        replay_command.register(parser.add_subparsers(dest="command", required=True))
        _local.parser = parser
    return parser


def replay_argv(job: Job, video: Path | None = None) -> list[str]:
    """The ``facepuppet replay`` command line of ``job`` (without the program name)."""
    argv = ["replay", str(job.take), "-c", str(job.character), *job.replay_args]
    if video is not None:
        argv += ["--video", str(video)]
    return argv


class FramesAt:
    """Tick observer: PNGs of the first tick at or after each asked time, as ``folder/frame_%05d.png``.

    Attributes
    ----------
    names : list of str, the images written (relative to the job folder), in time order
    ticks : list of int, the tick each one shows
    images : list of ndarray, the pixels (for the contact sheet)
    """

    def __init__(self, folder: Path, times: tuple[float, ...], prefix: str = "frames") -> None:
        self.folder, self.times, self.prefix = folder, times, prefix
        self.names: list[str] = []
        self.ticks: list[int] = []
        self.images: list[np.ndarray] = []

    def __call__(self, info: TickInfo) -> None:
        pixels = None
        while len(self.names) < len(self.times) and info.t >= self.times[len(self.names)] - _EPS_S:
            if pixels is None:
                pixels = np.ascontiguousarray(info.renderer.read_pixels())
                self.folder.mkdir(exist_ok=True)
            name = f"frame_{len(self.names):05d}.png"
            with atomic_path(self.folder / name) as temp:
                Image.fromarray(pixels).save(temp, format="PNG")
            self.names.append(f"{self.prefix}/{name}")
            self.ticks.append(info.k)
            self.images.append(pixels)


def run_job(job: Job, out: str | os.PathLike) -> dict:
    """Run ``job``, its result into ``out/<job id>``; returns ``{"job", "status", "message", "ticks", "wall_s",
    "pid"}`` (``status`` "ok" or "failed"; never raises for a job's own failure)."""
    out = Path(out)
    start = time.perf_counter()
    staging = out / PARTIAL / f"{job.id}.{os.getpid()}.{uuid.uuid4().hex[:8]}"
    report = {"job": job.id, "status": "failed", "message": "", "ticks": 0, "wall_s": 0.0, "pid": os.getpid()}
    try:
        staging.mkdir(parents=True)
        # A worker's stderr may be the terminal the batch was started from: a replay's own progress line
        # there would be drawn over the batch's. (The null stream is never closed: a worker of more than one
        # thread may put back another job's swap.)
        with contextlib.redirect_stderr(_quiet()), BlasThreads(1):  # one BLAS thread, as `replay` has
            ticks = _play(job, staging, start)
        _into_place(staging, out / job.id)
        report.update(status="ok", ticks=ticks)
    except (FacepuppetError, OSError) as exc:  # a refusal: bad input, named by the reader
        report["message"] = str(exc)
    except Exception as exc:  # a bug: this job fails with its traceback, the others go on
        report["message"] = f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        report["wall_s"] = time.perf_counter() - start
    return report


def _play(job: Job, folder: Path, start: float) -> int:
    """Replay ``job`` into ``folder``, manifest last; the number of ticks."""
    hashes = input_hashes(job)  # what this worker read, not what the client saw
    asked = job.outputs
    video = folder / VIDEO if asked.video else None
    ns = replay_parser().parse_args(replay_argv(job, video))
    plan = replay_command.ReplayPlan.from_args(ns)
    frames = FramesAt(folder / "frames", asked.frames) if asked.frames else None
    result, _feed = replay_command.replay(plan, keep_weights=True, context=worker_context(),
                                          observers=(frames,) if frames else (), keeps_pictures=bool(frames))
    weights, times = result.weights.array, result.weights.times
    channels = _channels(job, weights)
    outputs: dict = {}
    if asked.weights:
        with atomic_path(folder / "weights.npy") as temp:
            np.save(temp, weights)
        outputs["weights"] = "weights.npy"
    if asked.curves:
        write_curves(folder / "curves.csv", times, weights, channels)
        outputs["curves"] = "curves.csv"
    if frames is not None:
        outputs["frames"] = frames.names
        outputs["frame_times"] = list(asked.frames[:len(frames.names)])
        outputs["frame_ticks"] = frames.ticks
        if len(frames.names) < len(asked.frames):
            outputs["frames_past_end"] = list(asked.frames[len(frames.names):])
        if asked.contact_sheet and frames.images:
            _sheet(folder / "sheet.png", frames.images, outputs["frame_times"])
            outputs["sheet"] = "sheet.png"
    if video is not None:
        outputs["video"] = VIDEO
    figures = {"ticks": int(result.loop.n_ticks), "wall_s": round(time.perf_counter() - start, 6),
               "fps": result.fps, "chain": result.chain}
    write_manifest(folder, manifest_of(job, hashes, outputs, channels, figures))
    return int(result.loop.n_ticks)


def _channels(job: Job, weights: np.ndarray) -> list[str]:
    """The names of the weights' columns: the character's shapes."""
    names = list(Character.load(job.character).shape_names)
    if weights.size and weights.shape[1] != len(names):
        raise FacepuppetError(f"{job.character}: {weights.shape[1]} weight columns for {len(names)} shapes")
    return names


def _sheet(path: Path, images: list[np.ndarray], times: list[float]) -> None:
    cells = [(f"t={t:g} s", image[:, :, :3]) for t, image in zip(times, images)]
    sheet = contact_sheet(cells, columns=min(len(cells), 4))
    with atomic_path(path) as temp:
        Image.fromarray(sheet).save(temp, format="PNG")


def _into_place(staging: Path, final: Path) -> None:
    """Rename the finished ``staging`` folder onto ``final``; a previous folder there is moved aside first."""
    if final.exists():
        aside = staging.with_name(staging.name + ".old")
        os.replace(final, aside)
        shutil.rmtree(aside, ignore_errors=True)
    os.replace(staging, final)
