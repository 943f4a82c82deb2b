"""A batch run against an earlier (golden) run: which jobs now draw or drive differently, most changed first.

When a rig, a profile, a retarget table or facepuppet changes, the question is which takes now look
different. Each job present in either run is compared with its namesake:

* present on one side only, or failed in one run: changed, beyond any tolerance;
* its inputs (the manifests' content hashes): reported, never a change by itself (a new character that
  draws the same is no regression);
* its weights, channel by channel matched by name: the largest |Δweight| over the ticks; a channel added or
  removed, or a different tick count, is a change;
* its frames, in order: the mean absolute difference (0-255 levels) and the fraction of pixels whose
  largest channel difference exceeds ``pixel_level``; only when both runs drew on the same deformation path
  (the CPU and GPU paths differ by rounding at every edge), else the report says the frames are not
  comparable; a different frame count or frame size is a change.

A job changed beyond tolerance when its largest |Δweight| exceeds ``weight_tol`` or one of its frames has
more than ``pixel_tol`` of its pixels over ``pixel_level``. Jobs are ranked by how far past their tolerance
they are (the larger of the two ratios), structural changes (missing, failed, channels, counts) first.

Everything read comes from inside the two run folders, through :mod:`golden_jobs`, which bounds every size
before it loads anything. ``facepuppet batch-compare`` (:mod:`golden_report`) and ``facepuppet batch
--against`` call :func:`compare_runs`.
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from facepuppet.offline.batch.golden_jobs import Job, list_jobs, load_frame, load_weights, read_job

log = logging.getLogger(__name__)

WEIGHT_TOL = 1e-4      # a replay is bit-exact on one machine; this leaves room for another machine's BLAS
PIXEL_LEVEL = 8        # of 255: above the rounding and edge antialiasing of another GPU or driver
PIXEL_TOL = 1e-3       # a tenth of a percent of a frame's pixels over PIXEL_LEVEL


@dataclass
class FrameDiff:
    """One frame of a job against its golden.

    index : int, its position in the job's ``outputs.frames``
    new, golden : Path, the two PNGs
    mean_abs : float, mean |difference| over pixels and RGB, 0-255 levels (nan when the sizes differ)
    over : float, fraction of pixels whose largest RGB difference exceeds the comparison's ``pixel_level``
        (1.0 when the sizes differ)
    note : str, what makes the two incomparable ("" when nothing does)
    t : float or None, the take time the new frame shows (its manifest's ``frame_times``)
    """

    index: int
    new: Path
    golden: Path
    mean_abs: float
    over: float
    note: str = ""
    t: float | None = None


@dataclass
class JobDiff:
    """What differs in one job. ``problems`` are structural changes (always beyond tolerance); ``notes`` say
    what differs without being a change in what was drawn (inputs, options, version, frames on another path)."""

    job: str
    problems: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    inputs_changed: list[str] = field(default_factory=list)
    channel_delta: dict[str, float] = field(default_factory=dict)
    channels_added: list[str] = field(default_factory=list)
    channels_removed: list[str] = field(default_factory=list)
    frames_comparable: bool = True
    frames: list[FrameDiff] = field(default_factory=list)
    score: float = 0.0
    changed: bool = False

    @property
    def max_weight_delta(self) -> float:
        return max(self.channel_delta.values(), default=0.0)

    @property
    def worst_channel(self) -> str | None:
        """The channel of the largest |Δweight|; None when no channel differs."""
        if self.max_weight_delta == 0:
            return None
        return max(self.channel_delta, key=self.channel_delta.__getitem__)

    def worst_frames(self, n: int = 3) -> list[FrameDiff]:
        """The ``n`` frames with the most pixels over the level (then the largest mean difference) that
        differ at all."""
        ranked = sorted(self.frames, key=lambda f: (-f.over, -_num(f.mean_abs), f.index))
        return [f for f in ranked if f.over > 0 or _num(f.mean_abs) > 0][:n]

    def summary(self) -> str:
        """One line: what changed."""
        parts = list(self.problems)
        if self.worst_channel is not None:
            parts.append(f"max |Δweight| {self.max_weight_delta:.3g} ({self.worst_channel})")
        worst = self.worst_frames(1)
        if worst:
            f = worst[0]
            parts.append(f"frame {f.index}: {f.over:.2%} of pixels over the level, mean |Δ| {f.mean_abs:.2f}")
        if self.inputs_changed:
            parts.append("inputs changed: " + ", ".join(self.inputs_changed))
        return "; ".join(parts) or "no difference"

    def to_json(self, worst: int = 3) -> dict[str, Any]:
        return {"job": self.job, "changed": self.changed, "score": self.score, "problems": self.problems,
                "notes": self.notes, "inputs_changed": self.inputs_changed,
                "channel_delta": self.channel_delta, "max_weight_delta": self.max_weight_delta,
                "worst_channel": self.worst_channel, "channels_added": self.channels_added,
                "channels_removed": self.channels_removed, "frames_comparable": self.frames_comparable,
                "frames_compared": len(self.frames),
                "max_frame_over": max((f.over for f in self.frames), default=0.0),
                "worst_frames": [{"index": f.index, "t": f.t, "new": str(f.new), "golden": str(f.golden),
                                  "mean_abs": f.mean_abs, "over": f.over, "note": f.note}
                                 for f in self.worst_frames(worst)]}


@dataclass
class Report:
    """Every job of both runs compared (``jobs``, by id) and the tolerances used."""

    new_dir: Path
    golden_dir: Path
    weight_tol: float
    pixel_tol: float
    pixel_level: int
    jobs: list[JobDiff]

    @property
    def changed(self) -> list[JobDiff]:
        """The jobs changed beyond tolerance, most changed first."""
        return sorted((j for j in self.jobs if j.changed), key=lambda j: (-j.score, j.job))

    def to_json(self, worst: int = 3) -> dict[str, Any]:
        return {"format": "facepuppet-batch-compare", "version": 1, "new": str(self.new_dir),
                "golden": str(self.golden_dir), "weight_tol": self.weight_tol, "pixel_tol": self.pixel_tol,
                "pixel_level": self.pixel_level, "jobs": len(self.jobs),
                "changed": [j.job for j in self.changed],
                "results": [j.to_json(worst) for j in self.jobs]}


def compare_runs(new_dir: str | os.PathLike, golden_dir: str | os.PathLike, *, weight_tol: float = WEIGHT_TOL,
                 pixel_tol: float = PIXEL_TOL, pixel_level: int = PIXEL_LEVEL,
                 progress: Callable[[int, int, str], None] | None = None) -> Report:
    """Compare every job of the run in ``new_dir`` with the job of the same id in ``golden_dir``.

    Parameters
    ----------
    new_dir, golden_dir : folders of job folders (``<job id>/manifest.json`` ...), as ``facepuppet batch``
        writes them; only what is inside them is read
    weight_tol : float >= 0, the largest |Δweight| of any channel at any tick that is not a change
    pixel_tol : float in [0, 1], the fraction of a frame's pixels allowed over ``pixel_level``
    pixel_level : int in [0, 255], the largest RGB difference of a pixel that counts as the same
    progress : called as ``progress(done, total, job_id)`` after each job

    Returns
    -------
    Report; ``report.changed`` lists the jobs changed beyond tolerance, most changed first.

    Raises
    ------
    JobFolderError (an InputFileError)
        a run folder, manifest, weights file or frame that cannot be read or leads outside its folder;
        the message names the file and the manifest field.
    ValueError
        a tolerance out of range (a caller's bug; the command checks its options first).
    """
    if not (weight_tol >= 0 and 0 <= pixel_tol <= 1 and 0 <= pixel_level <= 255):
        raise ValueError(f"compare_runs: weight_tol >= 0, pixel_tol in [0, 1] and pixel_level in [0, 255], got "
                         f"{weight_tol}, {pixel_tol}, {pixel_level}")
    new_jobs, golden_jobs = list_jobs(new_dir), list_jobs(golden_dir)
    ids = sorted(set(new_jobs) | set(golden_jobs))
    diffs = []
    for i, job_id in enumerate(ids):
        if job_id not in golden_jobs:
            diff = JobDiff(job_id, problems=["not in the golden run"])
        elif job_id not in new_jobs:
            diff = JobDiff(job_id, problems=["missing from the new run"])
        else:
            diff = _compare_job(read_job(new_jobs[job_id]), read_job(golden_jobs[job_id]), pixel_level)
        _judge(diff, weight_tol, pixel_tol)
        log.debug("%s: %s", job_id, diff.summary())
        diffs.append(diff)
        if progress is not None:
            progress(i + 1, len(ids), job_id)
    return Report(Path(new_dir), Path(golden_dir), weight_tol, pixel_tol, pixel_level, diffs)


def _compare_job(new: Job, golden: Job, pixel_level: int) -> JobDiff:
    diff = JobDiff(new.id)
    for run, job in (("new", new), ("golden", golden)):
        if job.status != "ok":
            diff.problems.append(f"failed in the {run} run (status {job.status!r})")
    if diff.problems:
        return diff
    diff.inputs_changed = _inputs_changed(new, golden)
    if new.options != golden.options:
        keys = sorted(k for k in set(new.options) | set(golden.options) if new.options.get(k) != golden.options.get(k))
        diff.notes.append("options differ: " + ", ".join(keys))
    if new.version != golden.version:
        diff.notes.append(f"facepuppet {golden.version} -> {new.version}")
    _compare_weights(new, golden, diff)
    _compare_frames(new, golden, diff, pixel_level)
    return diff


def _inputs_changed(new: Job, golden: Job) -> list[str]:
    """The inputs whose content differs: the take and the character by role (their paths may move between
    runs), any other input by its path."""
    changed = []
    for role in ("take", "character"):
        a, b = getattr(new, role), getattr(golden, role)
        if new.inputs.get(a) != golden.inputs.get(b):
            changed.append(f"{role} ({Path(a).name})" if Path(a).name == Path(b).name
                           else f"{role} ({Path(b).name} -> {Path(a).name})")
    roles = {new.take, new.character, golden.take, golden.character}
    for key in sorted((set(new.inputs) | set(golden.inputs)) - roles):
        if new.inputs.get(key) != golden.inputs.get(key):
            side = "" if key in new.inputs and key in golden.inputs else (
                " (new input)" if key in new.inputs else " (no longer an input)")
            changed.append(f"{Path(key).name}{side}")
    return changed


def _compare_weights(new: Job, golden: Job, diff: JobDiff) -> None:
    if (new.weights is None) != (golden.weights is None):
        diff.problems.append("weights written by " + ("the new run only" if new.weights else "the golden run only"))
        return
    if new.weights is None:
        return
    a, b = load_weights(new), load_weights(golden)
    if len(a) != len(b):
        diff.problems.append(f"{len(a)} ticks of weights, golden {len(b)} (the first {min(len(a), len(b))} compared)")
    n = min(len(a), len(b))
    golden_column = {name: i for i, name in enumerate(golden.channels)}
    diff.channels_added = [c for c in new.channels if c not in golden_column]
    diff.channels_removed = [c for c in golden.channels if c not in set(new.channels)]
    if diff.channels_added:
        diff.problems.append("channels added: " + ", ".join(diff.channels_added))
    if diff.channels_removed:
        diff.problems.append("channels removed: " + ", ".join(diff.channels_removed))
    for i, name in enumerate(new.channels):
        if name in golden_column and n:
            x, y = a[:n, i].astype(np.float64), b[:n, golden_column[name]].astype(np.float64)
            both_nan = np.isnan(x) & np.isnan(y)
            delta = np.where(both_nan, 0.0, np.abs(x - y))   # NaN on one side only stays NaN: counted as inf
            diff.channel_delta[name] = float(np.nan_to_num(delta, nan=np.inf).max())


def _compare_frames(new: Job, golden: Job, diff: JobDiff, pixel_level: int) -> None:
    if not new.frames and not golden.frames:
        return
    if len(new.frames) != len(golden.frames):
        diff.problems.append(f"{len(new.frames)} frames, golden {len(golden.frames)}")
    if new.path != golden.path:
        diff.frames_comparable = False
        diff.notes.append(f"frames not comparable: drawn on the {new.path} path, the golden on the {golden.path} "
                          "path")
        return
    if new.frame_times and golden.frame_times:
        n = min(len(new.frame_times), len(golden.frame_times))
        if not np.allclose(new.frame_times[:n], golden.frame_times[:n], rtol=0, atol=1e-6):
            diff.notes.append("frames drawn at other times")
    times = new.frame_times or ()
    for i, (path_new, path_golden) in enumerate(zip(new.frames, golden.frames, strict=False)):
        frame = frame_difference(i, path_new, path_golden, pixel_level)
        frame.t = times[i] if i < len(times) else None
        diff.frames.append(frame)
    sizes = [f for f in diff.frames if f.note]
    if sizes:
        diff.problems.append(f"{len(sizes)} frames of another size (first: frame {sizes[0].index}, {sizes[0].note})")


def frame_difference(index: int, new: Path, golden: Path, pixel_level: int = PIXEL_LEVEL) -> FrameDiff:
    """How frame ``new`` differs from ``golden`` (see :class:`FrameDiff`)."""
    a, b = load_frame(new), load_frame(golden)
    if a.shape != b.shape:
        return FrameDiff(index, new, golden, math.nan, 1.0,
                         note=f"{a.shape[1]}x{a.shape[0]}, golden {b.shape[1]}x{b.shape[0]}")
    d = np.abs(a.astype(np.int16) - b.astype(np.int16))
    over = float((d.max(axis=2) > pixel_level).mean())
    return FrameDiff(index, new, golden, float(d.mean()), over)


def difference_map(new: np.ndarray, golden: np.ndarray) -> np.ndarray:
    """Per pixel, the largest RGB difference of two frames of one size: (h, w) uint8, 0-255 levels."""
    return np.abs(new.astype(np.int16) - golden.astype(np.int16)).max(axis=2).astype(np.uint8)


def _judge(diff: JobDiff, weight_tol: float, pixel_tol: float) -> None:
    """Set ``diff.score`` (how many times its tolerance the job is past; inf for a structural change) and
    ``diff.changed``."""
    if diff.problems:
        diff.score, diff.changed = math.inf, True
        return
    ratios = [_ratio(diff.max_weight_delta, weight_tol),
              _ratio(max((f.over for f in diff.frames), default=0.0), pixel_tol)]
    diff.score = max(ratios)
    diff.changed = diff.score > 1.0


def _ratio(value: float, tol: float) -> float:
    if value <= tol:
        return value / tol if tol > 0 else 0.0
    return value / tol if tol > 0 else math.inf


def _num(value: float) -> float:
    return 0.0 if math.isnan(value) else value
