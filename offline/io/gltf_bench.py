"""``facepuppet bench gltf -c character.npz --json OUT.json``: export (and re-import) times of a character as GLB.

Each repeat writes the character as a GLB into a temporary folder (build, PNG
encoding, GLB packing, atomic write), runs the structural check on it and
imports it again. Medians and the worst
repeat are reported against the issue's goal (export and import of the ICT
head as GLB, 26k vertices and 57 morph targets, under 3 s each).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.model.character import Character

from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.gltf.write import export_character
from facepuppet.offline.io.gltf_check import check_gltf

GOAL_S = 3.0


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-c", "--character", type=Path, required=True, help="character table (.npz)")
    parser.add_argument("--repeats", type=int, default=5, help="repeats (default 5)")


def run_bench(args: argparse.Namespace) -> dict:
    if args.repeats < 1:
        raise UsageError(f"--repeats {args.repeats}: must be at least 1")
    character = Character.load(args.character)
    times: dict[str, list[float]] = {"export_s": [], "check_s": [], "import_s": []}
    size, problems = 0, []
    with tempfile.TemporaryDirectory(prefix="bench-gltf-") as tmp:
        for r in range(args.repeats):
            out = Path(tmp) / f"export{r}.glb"
            t = time.perf_counter()
            summary = export_character(character, out)
            times["export_s"].append(time.perf_counter() - t)
            t = time.perf_counter()
            problems = check_gltf(out)
            times["check_s"].append(time.perf_counter() - t)
            t = time.perf_counter()
            read_gltf(out)
            times["import_s"].append(time.perf_counter() - t)
            size = out.stat().st_size
            out.unlink()
    result: dict = {"character": str(args.character), "n_vertices": character.n_vertices,
                    "n_shapes": character.n_shapes, "file_mb": size / 1e6, "repeats": args.repeats,
                    "n_targets": summary.n_targets, "n_sparse_targets": summary.n_sparse_targets,
                    "check_problems": problems, "goal_s": GOAL_S}
    for key, values in times.items():
        if values:
            result[key] = {"median": float(np.median(values)), "max": float(np.max(values))}
        else:
            result[key] = None
    for key in ("export_s", "import_s"):
        if result[key] is not None:
            result[key]["meets_goal"] = result[key]["median"] < GOAL_S
    line = f"bench gltf: {character.n_vertices} vertices, {character.n_shapes} shapes, {size / 1e6:.1f} MB GLB; " \
           f"export {result['export_s']['median']:.3f} s, check {result['check_s']['median']:.3f} s"
    if result["import_s"] is not None:
        line += f", import {result['import_s']['median']:.3f} s"
    print(line + f" (medians of {args.repeats}; goal < {GOAL_S:g} s)")
    return result


def register_benches(register_bench: Callable[..., None]) -> None:
    """Entry of ``offline/commands.py``: add ``bench gltf``."""
    register_bench("gltf", run_bench, "export a character as GLB (and check and re-import it): times against "
                   "the < 3 s goal for the ICT head", _add_arguments)
