"""The default source of ``perfect-sync``: the data kit's ICT head, fitted once and cached.

``perfect-sync`` clones the expressions of an elastic table (``fit-elastic``
of a head with ARKit shapes). Without ``--source`` it makes that table from
the ICT FaceKit in the data kit (``--data DIR`` or ``$FACEPUPPET_DATA``):
import the neutral OBJ and its shapes, place the 47 control points from the
kit's landmark file, fit the elastic basis (a few seconds), and keep the
result under ``$XDG_CACHE_HOME/facepuppet`` (``~/.cache`` without it) under a
name made from the kit files' sizes and times, so a changed kit is fitted
afresh. The cache is written atomically and read back through the table
checks like any elastic table; a cache that does not load is fitted again.
"""

from __future__ import annotations

import hashlib
import logging
import os
import time
from collections.abc import Callable
from pathlib import Path

from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.elastic.model import ElasticModel
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.files.outputs import OutputSet
from facepuppet.runtime.files.tables import TablesError

from facepuppet.offline.bench_data import ENV
from facepuppet.offline.elastic.commands import main_front
from facepuppet.offline.elastic.control_points import ict_control_points
from facepuppet.offline.elastic.params import fit_character
from facepuppet.offline.io.rig_import import import_rig, read_ict_landmarks

logger = logging.getLogger(__name__)

KIT_FOLDER = "ict-facekit"
NEUTRAL = "generic_neutral_mesh.obj"
LANDMARKS = "vertex_indices.json"
VERSION = 1  # bump when the fit that makes the default source changes


def cache_dir() -> Path:
    """``$XDG_CACHE_HOME/facepuppet`` (``~/.cache/facepuppet`` without an absolute XDG_CACHE_HOME)."""
    base = os.environ.get("XDG_CACHE_HOME") or ""
    root = Path(base) if base and Path(base).is_absolute() else Path.home() / ".cache"
    return root / "facepuppet"


def kit_folder(data: str | os.PathLike | None) -> Path:
    """The ICT FaceKit folder of the data kit; ValueError saying what to pass when there is none."""
    chosen = data if data is not None else os.environ.get(ENV)
    hint = ("pass --source ELASTIC.npz (fit-elastic of a head with ARKit shapes), or the data kit with "
            f"--data DIR or ${ENV} (its {KIT_FOLDER}/ folder is fitted once and cached)")
    if not chosen:
        raise UsageError(f"perfect-sync: no source: {hint}")
    folder = Path(chosen) / KIT_FOLDER
    for need in (folder / NEUTRAL, folder / LANDMARKS):
        if not need.is_file():
            raise UsageError(f"perfect-sync: no source: {need} does not exist; {hint}")
    return folder


def _key(folder: Path) -> str:
    """A name for the cache from the kit files' names, sizes and modification times."""
    h = hashlib.sha256(f"v{VERSION}".encode())
    for path in sorted(p for p in folder.iterdir() if p.suffix.lower() in (".obj", ".json")):
        st = path.stat()
        h.update(f"{path.name}:{st.st_size}:{st.st_mtime_ns};".encode())
    return h.hexdigest()[:16]


def fit_kit_source(folder: Path, log: Callable[[str], None] = logger.info) -> ElasticModel:
    """fit-elastic of the ICT head in ``folder`` with the kit's control points (no muscles).

    It takes tens of seconds on a slow machine, once: the shapes read are shown as a progress line (count,
    rate, time left; on a terminal) and each step is said in ``log`` as it starts and ends, so neither a
    terminal nor a log sits on one line with no sign of life.
    """
    start = time.perf_counter()
    bar = Progress("perfect-sync: source: reading the ICT shapes", unit="shapes")

    with bar:
        ict = import_rig(folder / NEUTRAL, folder, progress=bar.step)
    read_s = time.perf_counter() - start
    marks = read_ict_landmarks(folder / LANDMARKS, ict.n_vertices)
    points = ict_control_points(marks, ict.vertices, ict.triangles, main_front(ict))
    log(f"perfect-sync: source: {ict.n_shapes} shapes read in {read_s:.1f} s; fitting the elastic basis "
        f"({ict.n_vertices} vertices, {len(points.vertices)} control points)")
    model = fit_character(ict, points, with_muscles=False)[0]
    log(f"perfect-sync: source: fitted in {time.perf_counter() - start:.1f} s")
    return model


def default_source(data: str | os.PathLike | None = None,
                   log: Callable[[str], None] = logger.info) -> ElasticModel:
    """The kit's ICT head as an elastic table: from the cache, else fitted and cached (see the module doc)."""
    folder = kit_folder(data)
    path = cache_dir() / f"ict_elastic_{_key(folder)}.npz"
    if path.is_file():
        try:
            model = ElasticModel.load(path)
            log(f"perfect-sync: source: {folder} (fitted before, {path})")
            return model
        except (TablesError, OSError, ValueError) as exc:
            log(f"perfect-sync: the cached source {path} does not load ({exc}); fitting it again")
    log(f"perfect-sync: source: fitting the ICT head of {folder} (once; kept in {path.parent})")
    model = fit_kit_source(folder, log)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with OutputSet() as outputs:
            model.save(outputs.path(path))
    except OSError as exc:  # a read-only home: the fit is used, only not kept
        log(f"perfect-sync: could not keep the fitted source in {path.parent} ({exc}); it is used all the same")
    return model
