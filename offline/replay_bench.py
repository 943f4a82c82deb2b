"""``facepuppet bench replay --json OUT.json``: what a replay of a kit take to PNGs costs, with replay's defaults.

A user replays a Live Link Face take headless to PNG frames on the ICT head and waits; this bench is that
command, timed: the kit's ICT head imported (into ``--cache DIR`` or a temporary folder), the first
``--seconds`` of ``--take`` (a CSV under the data kit's ``tracker/``; default the 30 Hz one) replayed by
``facepuppet replay --headless --out DIR --stats`` in this process, with replay's defaults unless ``--fps`` or
``--size`` is given. Reported:

* ``ticks``, ``frames_received``, ``ticks_without_new_frame``, ``pngs``: what was drawn and written (a take
  drawn on a grid faster than its own rate draws frames twice: ``ticks_without_new_frame`` counts them);
* ``wall_per_take_second_ms``, ``cpu_per_take_second_ms``: wall and CPU time (every thread of the process)
  per second of take, the figures a user's wait scales with;
* ``stage_p50_ms``: the frame loop's median per stage (``sink`` holds the PNG writing the loop waits for).

The figures depend on the machine's load (``load_average`` is kept with them); compare runs made in one
sitting (``--against``).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from facepuppet.runtime.bench.registry import load_average
from facepuppet.runtime.cli import main
from facepuppet.runtime.errors import UsageError

from facepuppet.offline.bench_data import add_data_argument, data_dir
from facepuppet.offline.io.rig_import import import_rig

DEFAULT_TAKE = "livelinkface_alex_rom_3.csv"  # 30 Hz, the rate a 60 fps grid draws twice


def _add_arguments(p: argparse.ArgumentParser) -> None:
    add_data_argument(p)
    p.add_argument("--take", default=DEFAULT_TAKE, help=f"a Live Link Face CSV under the kit's tracker/ folder "
                                                         f"(default {DEFAULT_TAKE})")
    p.add_argument("--seconds", type=float, default=10.0, help="seconds of the take replayed (default 10)")
    p.add_argument("--fps", type=float, default=None, help="replay's --fps (default: replay's own default)")
    p.add_argument("--size", default=None, help="replay's --size (default: replay's own, 1280x720)")
    p.add_argument("--cache", type=Path, default=None, metavar="DIR",
                   help="keep the imported ICT head here and use it again (default: a temporary folder)")


def _ict(kit: Path, folder: Path) -> Path:
    """The kit's ICT head as a character table in ``folder`` (imported once there)."""
    path = folder / "ict.npz"
    if not path.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        ict = kit / "ict-facekit"
        import_rig(ict / "generic_neutral_mesh.obj", ict).save(path)
    return path


def run_bench(args: argparse.Namespace) -> dict:
    kit = data_dir(args.data)
    take = kit / "tracker" / Path(args.take).name
    if not take.is_file():
        raise UsageError(f"bench replay --take: {take} does not exist")
    if not args.seconds > 0:
        raise UsageError(f"bench replay --seconds: expected a positive number, got {args.seconds!r}")
    with tempfile.TemporaryDirectory(prefix="facepuppet-bench-replay-") as tmp:
        character = _ict(kit, args.cache if args.cache is not None else Path(tmp))
        argv = ["replay", str(take), "-c", str(character), "--headless", "--duration", f"{args.seconds:g}",
                "--out", str(Path(tmp) / "png"), "--stats"]
        argv += ["--fps", f"{args.fps:g}"] if args.fps is not None else []
        argv += ["--size", args.size] if args.size is not None else []
        out = io.StringIO()
        wall, cpu = time.perf_counter(), time.process_time()
        with contextlib.redirect_stdout(out):
            code = main(argv)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        pngs = len(list((Path(tmp) / "png").glob("frame_*.png")))
    if code != 0:
        raise UsageError(f"bench replay: the replay failed (exit {code}): {out.getvalue()[-2000:]}")
    stats = json.loads(next(line for line in out.getvalue().splitlines() if line.startswith("{")))
    c = stats["counters"]
    summary = out.getvalue().splitlines()[0]
    return {
        "take": take.name, "seconds": args.seconds, "options": argv[4:], "summary": summary,
        "ticks": stats["n_ticks"], "frames_received": c["frames_received"],
        "ticks_without_new_frame": c["ticks_without_new_frame"], "pngs": pngs, "path": stats["path"],
        "wall_s": wall, "cpu_s": cpu,
        "wall_per_take_second_ms": 1e3 * wall / args.seconds, "cpu_per_take_second_ms": 1e3 * cpu / args.seconds,
        "stage_p50_ms": {name: t["p50_ms"] for name, t in stats["timings_ms"].items()},
        "load_average": load_average(),
    }


def register_benches(register_bench: Callable[..., None]) -> None:
    """Entry of ``offline/commands.py``: add ``bench replay``."""
    register_bench("replay", run_bench, "replay of a kit Live Link Face take to PNGs on the ICT head with replay's "
                   "defaults: ticks, frames drawn twice, PNGs, wall and CPU time per take second, stage medians",
                   _add_arguments, comparable=True)
