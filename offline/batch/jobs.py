"""The jobs file of ``facepuppet batch`` and the job folder each job leaves: the contract between the batch,
its resumption and the comparison against an earlier run.

The jobs file (TOML) names groups; each group crosses its takes with its characters, and every pair is one
job, a replay on recorded time with the group's options::

    [groups.arkit]
    takes = ["takes/*.csv", "takes/extra.fps"]     # files or globs, relative to this file's folder
    characters = ["characters/*.npz"]
    path = "cpu"                 # deformation path: "gpu" (default) or "cpu"
    size = "640x360"             # picture WIDTHxHEIGHT (default 640x360)
    fps = 30                     # ticks per second of recorded time (default: the take's own)
    duration = 2.5               # seconds played (default: the whole take)
    config = "live.toml"         # or profile = "profile.toml"; and actor, pair, marker_units, retarget,
                                 # elastic, gestures, gesture_seed, calibrate, pipeline, max_gap, as `replay`
    [groups.arkit.outputs]
    weights = true               # weights.npy (default true)
    curves = true                # curves.csv: ARKit's 52 curves as a Live Link Face CSV
    video = true                 # take.mp4
    frames = [0.5, 1.0, 2.0]     # PNGs at these take times (seconds)
    contact_sheet = true         # sheet.png: those frames side by side, labelled with their times

Every path stays inside the jobs file's folder (a cluster's workers see the library at the same place; a jobs
file cannot make them read elsewhere). A glob that matches nothing, an unknown key or a value of the wrong type
is refused naming the file and the key (exit 2); a named file that is missing is left to its job, which fails
with the reader's message while the others run.

The job folder, ``DIR/<job id>/``::

    manifest.json : {"format": "facepuppet-batch-job", "version": 1, "job": id, "take": path, "character": path,
        "inputs": {path: sha256 for the take, the character and every table/config the job reads},
        "options": {...}, "facepuppet": version, "path": "cpu"|"gpu",
        "outputs": {"weights": "weights.npy", "curves": "curves.csv",
                    "frames": ["frames/frame_00000.png", ...], "frame_times": [t, ...], "video": "take.mp4"}
                   (only those asked; "sheet": "sheet.png" with contact_sheet),
        "channels": [shape names in weights column order], "figures": {"ticks": n, "wall_s": s}, "status": "ok"}
    weights.npy : float32 (n_ticks, n_shapes), the drawn weights per tick (as replay --dump-weights gives)
    frames/frame_%05d.png : PNGs at the asked times (consecutive numbering), frame_times in the manifest: each is
        the first tick at or after its time (``frame_ticks`` gives that tick's index); a time past the take's end
        draws no frame and is listed in ``frames_past_end``

Paths in the manifest are relative: the take, character and inputs to the jobs file's folder, the outputs to
the job folder. The manifest is written last, atomically (temporary file, then rename), and the whole folder
is built beside the others (``DIR/.partial/``) and renamed into place: a folder without manifest.json is not a
result. The job id is a readable slug of take stem, character stem and group name, stable across runs; two
jobs of one file that would share it get a short hash of their take and character paths appended.
"""

from __future__ import annotations

import glob
import hashlib
import math
import re
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from facepuppet.runtime.commands.options import parse_size
from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.files.input_files import regular_file

FORMAT = "facepuppet-batch-job"
VERSION = 1
MAX_JOBS_FILE_BYTES = 1 << 20
MAX_JOBS = 100_000
MAX_FRAMES = 1000
DEFAULT_SIZE = "640x360"
PATHS = ("gpu", "cpu")

# Stage options given as files (relative to the jobs file), in the order `replay` is given them.
_FILE_OPTIONS = ("config", "profile", "actor", "pair", "retarget", "elastic", "gestures")
_OUTPUT_KEYS = {"weights": bool, "curves": bool, "video": bool, "frames": list, "contact_sheet": bool}
_GROUP_KEYS = {"takes", "characters", "path", "size", "fps", "duration", "marker_units", "gesture_seed",
               "calibrate", "pipeline", "max_gap", "outputs", *_FILE_OPTIONS}
_GLOB_CHARS = re.compile(r"[*?\[]")


class JobsFileError(InputFileError):
    """The jobs file cannot be used as written; the message names the file and the key."""


@dataclass(frozen=True)
class Outputs:
    """What a job writes besides its manifest.

    Attributes
    ----------
    weights, curves, video, contact_sheet : bool
    frames : tuple of float, take times (s) of the PNGs, ascending
    """

    weights: bool = True
    curves: bool = False
    video: bool = False
    frames: tuple[float, ...] = ()
    contact_sheet: bool = False

    def asked(self) -> dict:
        return {"weights": self.weights, "curves": self.curves, "video": self.video, "frames": list(self.frames),
                "contact_sheet": self.contact_sheet}


@dataclass(frozen=True)
class Job:
    """One replay of one take on one character with one group's options (picklable: it travels to workers).

    Attributes
    ----------
    id : str, the job folder's name
    group : str
    take, character : Path, absolute
    root : Path, the jobs file's folder (what manifest paths are relative to)
    replay_args : tuple of str, the options of ``facepuppet replay`` besides the take, ``-c`` and outputs
    files : tuple of Path, every file the job reads (take, character, tables, config), absolute
    options : dict, the options that decide the result (kept in the manifest, compared on resumption)
    outputs : Outputs
    path : str, ``cpu`` or ``gpu``
    """

    id: str
    group: str
    take: Path
    character: Path
    root: Path
    replay_args: tuple[str, ...]
    files: tuple[Path, ...]
    options: dict = field(hash=False)
    outputs: Outputs
    path: str

    def relative(self, path: Path) -> str:
        """``path`` relative to the jobs file's folder, with forward slashes."""
        return path.relative_to(self.root).as_posix()


def load_jobs(path: str | Path) -> list[Job]:
    """Read and check a jobs file; its jobs in group order, then take, then character order.

    Raises
    ------
    JobsFileError
        naming the file and the key: not TOML, an unknown key, a wrong type, a path outside the file's folder, a
        glob that matches nothing, no groups, more than ``MAX_JOBS`` jobs.
    """
    path = regular_file(path, "jobs file")
    size = path.stat().st_size
    if size > MAX_JOBS_FILE_BYTES:
        raise JobsFileError(f"{path}: {size} bytes; a jobs file is at most {MAX_JOBS_FILE_BYTES} bytes")
    try:
        data = tomllib.loads(path.read_bytes().decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise JobsFileError(f"{path}: not a TOML jobs file: {exc}") from None
    unknown = set(data) - {"groups"}
    if unknown:
        raise JobsFileError(f"{path}: {sorted(unknown)[0]}: unknown key (a jobs file has [groups.NAME] tables)")
    groups = data.get("groups")
    if not isinstance(groups, dict) or not groups:
        raise JobsFileError(f"{path}: groups: no [groups.NAME] table; name at least one group of takes and "
                            "characters")
    root = path.resolve().parent
    jobs: list[Job] = []
    for name, table in groups.items():
        jobs += _group_jobs(path, root, name, table)
        if len(jobs) > MAX_JOBS:
            raise JobsFileError(f"{path}: groups: more than {MAX_JOBS} jobs; split the jobs file")
    return _unique_ids(jobs)


def slug(text: str) -> str:
    """Lower-case letters, digits, ``-`` and ``_``; anything else as ``-`` (at most 60 characters)."""
    return re.sub(r"[^a-z0-9_]+", "-", text.lower()).strip("-")[:60] or "x"


def _unique_ids(jobs: list[Job]) -> list[Job]:
    seen: dict[str, int] = {}
    for job in jobs:
        seen[job.id] = seen.get(job.id, 0) + 1
    out = []
    for job in jobs:
        if seen[job.id] > 1:
            tag = hashlib.sha256(f"{job.relative(job.take)}\n{job.relative(job.character)}".encode()).hexdigest()
            job = replace(job, id=f"{job.id}--{tag[:8]}")
        out.append(job)
    return out


def _group_jobs(path: Path, root: Path, name: Any, table: Any) -> list[Job]:
    key = f"groups.{name}"
    if not isinstance(table, dict):
        raise JobsFileError(f"{path}: {key}: expected a table of the group's takes, characters and options")
    if not re.fullmatch(r"[A-Za-z0-9_.-]{1,60}", str(name)):
        raise JobsFileError(f"{path}: {key}: a group's name is 1 to 60 letters, digits, '_', '.' or '-'")
    unknown = sorted(set(table) - _GROUP_KEYS)
    if unknown:
        raise JobsFileError(f"{path}: {key}.{unknown[0]}: unknown key (known: {', '.join(sorted(_GROUP_KEYS))})")
    takes = _paths(path, root, table, key, "takes")
    characters = _paths(path, root, table, key, "characters")
    options, args, files = _replay_options(path, root, table, key)
    outputs = _outputs(path, table.get("outputs", {}), f"{key}.outputs")
    options["outputs"] = outputs.asked()
    jobs = []
    for take in takes:
        for character in characters:
            job_id = f"{slug(take.stem)}--{slug(character.stem)}--{slug(str(name))}"
            jobs.append(Job(job_id, str(name), take, character, root, tuple(args), (take, character, *files),
                            dict(options), outputs, options["path"]))
    return jobs


def _inside(path: Path, root: Path, text: str, where: str) -> Path:
    """``text`` relative to ``root``, resolved, refused when it leads outside ``root``."""
    if Path(text).is_absolute():
        raise JobsFileError(f"{path}: {where}: {text!r}: give paths relative to the jobs file's folder")
    full = (root / text).resolve()
    if not full.is_relative_to(root):
        raise JobsFileError(f"{path}: {where}: {text!r} leads outside the jobs file's folder {root}")
    return full


def _paths(path: Path, root: Path, table: dict, key: str, name: str) -> list[Path]:
    where = f"{key}.{name}"
    values = table.get(name)
    if isinstance(values, str):
        values = [values]
    if not isinstance(values, list) or not values or not all(isinstance(v, str) and v for v in values):
        raise JobsFileError(f"{path}: {where}: expected a file name or glob, or a list of them")
    found: list[Path] = []
    for text in values:
        if not _GLOB_CHARS.search(text):
            found.append(_inside(path, root, text, where))
            continue
        _inside(path, root, text, where)  # the pattern itself must not lead out
        matches = sorted(Path(m) for m in glob.glob(str(root / text), recursive=True) if Path(m).is_file())
        if not matches:
            raise JobsFileError(f"{path}: {where}: {text!r} matches no file")
        found += [_inside(path, root, m.relative_to(root).as_posix(), where) for m in matches]
    return list(dict.fromkeys(found))


def _typed(path: Path, table: dict, key: str, name: str, kinds: tuple, what: str) -> Any:
    value = table.get(name)
    if value is None:
        return None
    if isinstance(value, bool) and bool not in kinds or not isinstance(value, kinds):
        raise JobsFileError(f"{path}: {key}.{name}: expected {what}, got {value!r}")
    return value


def _positive(path: Path, table: dict, key: str, name: str) -> float | None:
    value = _typed(path, table, key, name, (int, float), "a positive number")
    if value is not None and not (math.isfinite(value) and value > 0):
        raise JobsFileError(f"{path}: {key}.{name}: expected a positive number, got {value!r}")
    return None if value is None else float(value)


def _replay_options(path: Path, root: Path, table: dict, key: str) -> tuple[dict, list[str], list[Path]]:
    """The options that decide a result (canonical), ``replay``'s arguments for them, the files they name."""
    job_path = _typed(path, table, key, "path", (str,), f"one of {', '.join(PATHS)}") or PATHS[0]
    if job_path not in PATHS:
        raise JobsFileError(f"{path}: {key}.path: expected one of {', '.join(PATHS)}, got {job_path!r}")
    size = _typed(path, table, key, "size", (str,), "WIDTHxHEIGHT") or DEFAULT_SIZE
    try:
        width, height = parse_size(size)
    except ValueError as exc:
        raise JobsFileError(f"{path}: {key}.size: {exc}") from None
    fps, duration = _positive(path, table, key, "fps"), _positive(path, table, key, "duration")
    max_gap = _positive(path, table, key, "max_gap")
    units = _typed(path, table, key, "marker_units", (str,), "mm, cm or m")
    if units is not None and units not in ("mm", "cm", "m"):
        raise JobsFileError(f"{path}: {key}.marker_units: expected mm, cm or m, got {units!r}")
    seed = _typed(path, table, key, "gesture_seed", (int,), "an integer")
    calibrate = _typed(path, table, key, "calibrate", (bool,), "true or false")
    pipeline = _typed(path, table, key, "pipeline", (bool,), "true or false")
    if table.get("config") is not None and table.get("profile") is not None:
        raise JobsFileError(f"{path}: {key}: config and profile: choose one")
    options: dict[str, Any] = {"path": job_path, "size": f"{width}x{height}", "fps": fps, "duration": duration,
                               "max_gap": max_gap, "marker_units": units, "gesture_seed": seed,
                               "calibrate": bool(calibrate), "pipeline": pipeline}
    args = ["--headless", "--size", f"{width}x{height}", "--path", job_path]
    files: list[Path] = []
    for name in _FILE_OPTIONS:
        text = _typed(path, table, key, name, (str,), "a file name")
        options[name] = text
        if text is not None:
            full = _inside(path, root, text, f"{key}.{name}")
            files.append(full)
            args += [f"--{name}", str(full)]
    for flag, value in (("--fps", fps), ("--duration", duration), ("--max-gap", max_gap),
                        ("--marker-units", units), ("--gesture-seed", seed)):
        if value is not None:
            args += [flag, repr(value) if isinstance(value, float) else str(value)]
    if calibrate:
        args.append("--calibrate")
    if pipeline is not None:
        args.append("--pipeline" if pipeline else "--no-pipeline")
    return options, args, files


def _outputs(path: Path, table: Any, key: str) -> Outputs:
    if not isinstance(table, dict):
        raise JobsFileError(f"{path}: {key}: expected a table (weights, curves, video, frames, contact_sheet)")
    for name, value in table.items():
        kind = _OUTPUT_KEYS.get(name)
        if kind is None:
            raise JobsFileError(f"{path}: {key}.{name}: unknown key (known: {', '.join(_OUTPUT_KEYS)})")
        if not isinstance(value, kind):
            raise JobsFileError(f"{path}: {key}.{name}: expected {'true or false' if kind is bool else 'a list'}, "
                                f"got {value!r}")
    times = table.get("frames", [])
    if len(times) > MAX_FRAMES:
        raise JobsFileError(f"{path}: {key}.frames: {len(times)} times; at most {MAX_FRAMES}")
    for t in times:
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not (math.isfinite(t) and t >= 0):
            raise JobsFileError(f"{path}: {key}.frames: expected times in seconds (numbers >= 0), got {t!r}")
    sheet = table.get("contact_sheet", False)
    if sheet and not times:
        raise JobsFileError(f"{path}: {key}.contact_sheet: needs frames = [times] to put side by side")
    outputs = Outputs(table.get("weights", True), table.get("curves", False), table.get("video", False),
                      tuple(sorted(float(t) for t in times)), sheet)
    if not (outputs.weights or outputs.curves or outputs.video or outputs.frames):
        raise JobsFileError(f"{path}: {key}: every output is off; ask for weights, curves, video or frames")
    return outputs
