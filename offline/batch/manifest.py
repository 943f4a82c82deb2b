"""A job's manifest: what it read (content hashes), how (options, facepuppet's version), what it wrote.

The manifest is the whole claim that a job folder is a result (the format is in
:mod:`~facepuppet.offline.batch.jobs`): written last and atomically, and read back to decide whether a job can
be skipped: only when every input's hash, the options and facepuppet's version are those of the job now, and
every output it lists is there. Anything else (no manifest, a damaged one, another version) runs the job again.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from facepuppet.runtime.files.json_limits import dumps_strict, loads_limited
from facepuppet.runtime.files.outputs import write_atomic

from facepuppet import __version__
from facepuppet.offline.batch.jobs import FORMAT, VERSION, Job

MANIFEST = "manifest.json"
MAX_MANIFEST_BYTES = 16 << 20
_CHUNK = 1 << 20


def file_hash(path: Path) -> str | None:
    """``sha256:`` hex digest of the file's bytes; None when it cannot be read (its job will say why)."""
    digest = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            while chunk := f.read(_CHUNK):
                digest.update(chunk)
    except OSError:
        return None
    return "sha256:" + digest.hexdigest()


def input_hashes(job: Job, cache: dict[Path, str | None] | None = None) -> dict[str, str | None]:
    """Each file the job reads (relative to the jobs file's folder) -> its hash; ``cache`` spares hashing a
    take or character shared by many jobs twice."""
    hashes = {}
    for path in job.files:
        if cache is not None and path in cache:
            value = cache[path]
        else:
            value = file_hash(path)
            if cache is not None:
                cache[path] = value
        hashes[job.relative(path)] = value
    return hashes


def read_manifest(folder: Path) -> dict | None:
    """The manifest of a job folder, or None when it has none that can be read (not a result)."""
    path = folder / MANIFEST
    try:
        if not path.is_file() or path.stat().st_size > MAX_MANIFEST_BYTES:
            return None
        manifest = loads_limited(path.read_bytes(), str(path), max_bytes=MAX_MANIFEST_BYTES)
    except (OSError, ValueError):
        return None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT or manifest.get("version") != VERSION:
        return None
    return manifest


def output_files(outputs: dict) -> list[str]:
    """The files a manifest's ``outputs`` lists (relative to the job folder)."""
    names = [outputs[k] for k in ("weights", "curves", "video", "sheet") if isinstance(outputs.get(k), str)]
    frames = outputs.get("frames", [])
    return names + [f for f in frames if isinstance(f, str)] if isinstance(frames, list) else names


def is_done(job: Job, hashes: dict[str, str | None], out: Path) -> bool:
    """Whether ``out/<job id>`` holds this job's result already (see the module docstring)."""
    if any(value is None for value in hashes.values()):
        return False
    folder = out / job.id
    manifest = read_manifest(folder)
    if manifest is None or manifest.get("status") != "ok":
        return False
    if manifest.get("inputs") != hashes or manifest.get("facepuppet") != __version__:
        return False
    if json.loads(dumps_strict(job.options)) != manifest.get("options"):
        return False
    outputs = manifest.get("outputs")
    if not isinstance(outputs, dict):
        return False
    return all(_inside_is_file(folder, name) for name in output_files(outputs))


def _inside_is_file(folder: Path, name: str) -> bool:
    path = (folder / name).resolve()
    return path.is_relative_to(folder.resolve()) and path.is_file()


def manifest_of(job: Job, hashes: dict[str, str | None], outputs: dict, channels: list[str], figures: dict
                ) -> dict:
    """The manifest of a finished job (key order as the format lists it)."""
    return {"format": FORMAT, "version": VERSION, "job": job.id, "group": job.group,
            "take": job.relative(job.take), "character": job.relative(job.character), "inputs": hashes,
            "options": job.options, "facepuppet": __version__, "path": job.path, "outputs": outputs,
            "channels": channels, "figures": figures, "status": "ok"}


def write_manifest(folder: Path, manifest: dict) -> Path:
    """Write ``folder/manifest.json`` atomically (temporary file, then rename)."""
    text = dumps_strict(manifest, indent=1)
    return write_atomic(folder / MANIFEST, lambda temp: temp.write_text(text + "\n", encoding="utf-8"))
