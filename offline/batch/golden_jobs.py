"""One batch job's folder read as untrusted input: its manifest, its weights and its frames, never outside it.

A golden run may come from another machine, another person or an older facepuppet, so nothing in a job
folder is trusted. Every path a manifest names is relative to its job folder and must resolve (links
followed) to a regular file inside that folder; every size is checked before anything is allocated: the
manifest's bytes and nesting, the weights' shape from the ``.npy`` header (and the file's length against
it), each PNG's bytes and pixel count from its header. A refusal is a :class:`JobFolderError` naming the
file and the manifest field.

The folder's layout (the batch runner writes it)::

    RUN/<job id>/manifest.json   {"format": "facepuppet-batch-job", "version": 1, "job": id, "status": "ok",
                                  "take": path, "character": path, "inputs": {path: "sha256:" hex},
                                  "options": {...}, "facepuppet": version, "path": "cpu" | "gpu",
                                  "channels": [shape names, in the weights' column order],
                                  "outputs": {"weights": "weights.npy", "frames": [...], "frame_times": [...],
                                              "curves": ..., "video": ...}, "figures": {...}}
    RUN/<job id>/weights.npy     float32 (n_ticks, n_channels)
    RUN/<job id>/frames/frame_%05d.png

A folder without ``manifest.json`` is not a result (a job that never finished, or one being written).
"""

from __future__ import annotations

import logging
import math
import os
import re
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.files.input_files import regular_file
from facepuppet.runtime.files.json_limits import loads_limited

log = logging.getLogger(__name__)

FORMAT, VERSION = "facepuppet-batch-job", 1
MANIFEST = "manifest.json"
MAX_MANIFEST_BYTES = 16 << 20   # a take of an hour at 60 fps lists 216,000 frames: about 8 MB with their times
MAX_FRAMES = 1_000_000          # frames one job may list
MAX_CHANNELS = 4096             # shapes of a rig (ARKit has 52; the largest production rigs a few hundred)
MAX_WEIGHT_BYTES = 1 << 30      # weights.npy data: an hour at 60 fps of 500 shapes is 432 MB
MAX_PNG_BYTES = 256 << 20
MAX_PNG_PIXELS = 8192 * 8192    # 8K square: a 4K frame is a quarter of it
PATHS = ("cpu", "gpu")
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_SHA256 = re.compile(r"(sha256:)?[0-9a-f]{64}")


class JobFolderError(InputFileError):
    """A job folder's manifest, weights or frames cannot be used; the message names the file and field."""


@dataclass(frozen=True)
class Job:
    """A job folder as read: what the comparison needs, every path resolved and checked inside ``folder``.

    id : str, the folder's name (and the manifest's ``job``)
    folder : Path, resolved
    status : str, ``"ok"`` for a result; anything else is a job that failed (nothing below it is read)
    path : str, the deformation path the frames were drawn with (``"cpu"``/``"gpu"``), "" when not a result
    channels : tuple of str, the weights' columns
    inputs : dict of path -> ``sha256:`` hex digest (or None), the content of every input the job read
    take, character : str, keys of ``inputs`` (or names only; never opened here)
    options : dict, the replay options
    version : str, the facepuppet version that wrote it
    weights : Path or None; frames : tuple of Path; frame_times : tuple of float or None
    """

    id: str
    folder: Path
    status: str
    path: str = ""
    channels: tuple[str, ...] = ()
    inputs: dict[str, str | None] | None = None
    take: str = ""
    character: str = ""
    options: dict[str, Any] | None = None
    version: str = ""
    weights: Path | None = None
    frames: tuple[Path, ...] = ()
    frame_times: tuple[float, ...] | None = None

    @property
    def manifest(self) -> Path:
        return self.folder / MANIFEST


def list_jobs(run_dir: str | os.PathLike) -> dict[str, Path]:
    """The job folders of a run: name -> folder, for each sub-folder holding a ``manifest.json``.

    A sub-folder that is a link leading outside ``run_dir`` is refused (:class:`JobFolderError`): the
    comparison reads only inside the two runs it was given.
    """
    root = Path(run_dir)
    if not root.is_dir():
        raise JobFolderError(f"{root}: expected a folder of batch jobs, found "
                             f"{'nothing' if not root.exists() else 'a file'}")
    real = root.resolve()
    found = {}
    for entry in sorted(root.iterdir()):
        if not entry.is_dir() or not (entry / MANIFEST).exists():
            continue
        if entry.resolve().parent != real:
            raise JobFolderError(f"{entry}: the job folder leads outside {root} (a link); refused")
        found[entry.name] = entry
    return found


def read_job(folder: str | os.PathLike) -> Job:
    """The job in ``folder`` (its manifest checked field by field; the files it names found inside it).

    Raises
    ------
    JobFolderError
        naming the file and the field: not JSON, over a size limit, a wrong format or version, a field of the
        wrong type, a path outside the folder or to no regular file.
    """
    folder = Path(folder)
    real = folder.resolve()
    manifest = _inside(real, MANIFEST, folder / MANIFEST, "manifest")
    size = manifest.stat().st_size
    if size > MAX_MANIFEST_BYTES:
        raise JobFolderError(f"{manifest}: {size} bytes; a job manifest is at most {MAX_MANIFEST_BYTES}")
    doc = loads_limited(manifest.read_bytes(), str(manifest), max_bytes=MAX_MANIFEST_BYTES)
    m = _Fields(manifest, doc)
    if m.get("format", str) != FORMAT:
        m.fail("format", f"expected {FORMAT!r}")
    if m.get("version", int) != VERSION:
        m.fail("version", f"expected {VERSION} (this facepuppet reads version {VERSION} job folders)")
    if m.get("job", str) != folder.name:
        m.fail("job", f"expected the folder's name {folder.name!r}")
    status = m.get("status", str)
    if status != "ok":
        return Job(id=folder.name, folder=real, status=status)
    path = m.get("path", str)
    if path not in PATHS:
        m.fail("path", f"expected one of {', '.join(PATHS)}")
    channels = m.get("channels", list)
    if len(channels) > MAX_CHANNELS:
        m.fail("channels", f"{len(channels)} names; at most {MAX_CHANNELS}")
    for i, name in enumerate(channels):
        m.check(f"channels[{i}]", name, str)
    if len(set(channels)) != len(channels):
        m.fail("channels", "names a channel twice")
    inputs = m.get("inputs", dict)
    for key, digest in inputs.items():
        # null: an input the runner could not read (its job failed; kept so that the job is run again)
        if digest is not None and (not isinstance(digest, str) or not _SHA256.fullmatch(digest)):
            m.fail(f"inputs[{key!r}]", "expected a sha256 digest ('sha256:' and 64 lowercase hex digits) or null")
    outputs = m.get("outputs", dict)
    weights = frames = times = None
    if "weights" in outputs:
        weights = _inside(real, m.check("outputs.weights", outputs["weights"], str), manifest, "outputs.weights")
    if "frames" in outputs:
        names = m.check("outputs.frames", outputs["frames"], list)
        if len(names) > MAX_FRAMES:
            m.fail("outputs.frames", f"{len(names)} frames; at most {MAX_FRAMES}")
        frames = tuple(_inside(real, m.check(f"outputs.frames[{i}]", name, str), manifest, f"outputs.frames[{i}]")
                       for i, name in enumerate(names))
    if "frame_times" in outputs:
        raw = m.check("outputs.frame_times", outputs["frame_times"], list)
        for i, t in enumerate(raw):
            if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t):
                m.fail(f"outputs.frame_times[{i}]", "expected a finite number of seconds")
        times = tuple(float(t) for t in raw)
    return Job(id=folder.name, folder=real, status=status, path=path, channels=tuple(channels), inputs=inputs,
               take=m.get("take", str), character=m.get("character", str),
               options=m.get("options", dict, required=False) or {},
               version=str(m.get("facepuppet", str, required=False) or ""),
               weights=weights, frames=frames or (), frame_times=times)


def load_weights(job: Job) -> np.ndarray:
    """The job's weights, ndarray of shape (n_ticks, len(job.channels)), float32; the ``.npy`` header is
    read and checked (dtype, order, shape, the size it declares against the file's) before the data is."""
    path = job.weights
    assert path is not None
    with open(path, "rb") as f:
        try:
            major, minor = np.lib.format.read_magic(f)
            if (major, minor) == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
            elif (major, minor) == (2, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
            else:
                raise ValueError(f"unsupported .npy version {major}.{minor}")
        except (ValueError, SyntaxError) as exc:
            raise JobFolderError(f"{path} (outputs.weights): not a readable .npy header ({exc})") from None
        offset = f.tell()
    where = f"{path} (outputs.weights)"
    if dtype != np.dtype("<f4") or fortran:
        raise JobFolderError(f"{where}: expected little-endian float32 in C order, found {dtype} "
                             f"{'Fortran' if fortran else 'C'} order")
    if len(shape) != 2 or shape[1] != len(job.channels):
        raise JobFolderError(f"{where}: expected shape (n_ticks, {len(job.channels)}) (one column per name of "
                             f"'channels'), found {shape}")
    nbytes = shape[0] * shape[1] * 4
    if nbytes > MAX_WEIGHT_BYTES:
        raise JobFolderError(f"{where}: declares shape {shape}, {nbytes} bytes; at most {MAX_WEIGHT_BYTES} read")
    size = path.stat().st_size
    if size != offset + nbytes:
        raise JobFolderError(f"{where}: {size} bytes, but its header declares {offset + nbytes} for shape {shape}")
    return np.load(path, allow_pickle=False)


def load_frame(path: Path) -> np.ndarray:
    """One frame as ndarray of shape (h, w, 3) uint8 RGB; its bytes, and its pixel count from the PNG header,
    bounded before anything is decoded."""
    size = path.stat().st_size
    if size > MAX_PNG_BYTES:
        raise JobFolderError(f"{path}: {size} bytes; a frame is at most {MAX_PNG_BYTES}")
    with open(path, "rb") as f:
        head = f.read(24)   # the signature, then the IHDR chunk's length, type, width and height
    if len(head) < 24 or head[:8] != _PNG_SIGNATURE or head[12:16] != b"IHDR":
        raise JobFolderError(f"{path}: not a readable PNG (no PNG signature and header)")
    w, h = struct.unpack(">II", head[16:24])
    if w * h > MAX_PNG_PIXELS:
        raise JobFolderError(f"{path}: {w}x{h} pixels; a frame is at most {MAX_PNG_PIXELS}")
    try:
        with Image.open(path, formats=("PNG",)) as image:
            return np.asarray(image.convert("RGB"))
    except (OSError, SyntaxError, ValueError, Image.DecompressionBombError) as exc:
        raise JobFolderError(f"{path}: not a readable PNG ({exc})") from None


def _inside(real_folder: Path, name: str, where: Path, field: str) -> Path:
    """``name`` (a manifest's relative path) resolved inside ``real_folder``, a regular file; else refused."""
    if not name or "\x00" in name or os.path.isabs(name) or Path(name).is_absolute():
        raise JobFolderError(f"{where}: field {field}: {name!r} is not a path relative to the job folder")
    path = (real_folder / name).resolve()
    if not path.is_relative_to(real_folder):
        raise JobFolderError(f"{where}: field {field}: {name!r} leads outside the job folder {real_folder}; "
                             "refused")
    try:
        return regular_file(path, f"file named by {field}")
    except FileNotFoundError:
        raise JobFolderError(f"{where}: field {field}: {name!r} names no file in the job folder") from None


class _Fields:
    """A manifest's top-level fields read by type, each refusal naming the file and the field."""

    def __init__(self, manifest: Path, doc: Any) -> None:
        if not isinstance(doc, dict):
            raise JobFolderError(f"{manifest}: expected a JSON object, found {type(doc).__name__}")
        self.manifest, self.doc = manifest, doc

    def fail(self, field: str, problem: str) -> None:
        raise JobFolderError(f"{self.manifest}: field {field}: {problem}")

    def check(self, field: str, value: Any, kind: type) -> Any:
        if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
            self.fail(field, f"expected {_KIND_NAMES[kind]}, found {_json_name(value)}")
        return value

    def get(self, field: str, kind: type, required: bool = True) -> Any:
        if field not in self.doc:
            if required:
                self.fail(field, "missing")
            return None
        return self.check(field, self.doc[field], kind)


_KIND_NAMES = {str: "a string", int: "an integer", list: "a list", dict: "an object"}


def _json_name(value: Any) -> str:
    return {type(None): "null", bool: "true/false", str: "a string", int: "a number", float: "a number",
            list: "a list", dict: "an object"}.get(type(value), type(value).__name__)
