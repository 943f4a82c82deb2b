"""``make bench-check``: the render and latency benchmarks of the working tree against an earlier commit's
build, in one sitting, so that a change to the renderer or the frame loop shows its cost before it lands.

Timings of two runs an hour apart differ by more than most regressions on a shared 2-core machine; two
builds measured in the same minutes, taking turns, meet the same load. So the sitting:

1. checks the base (``--base``, default ``HEAD~1``) out into ``OUT/base`` and makes an import shim for each side
   (:mod:`~facepuppet.runtime.bench.revision`): both run with this environment's Python, each importing its own
   tree's code (checked, and the paths printed);
2. imports the ICT head from the data kit (``--data`` or ``$FACEPUPPET_DATA``, which ``make`` sets) with each
   side's own importer;
3. runs ``bench render`` and ``bench latency`` on each side by turns, working tree then base, ``--rounds`` times
   (:func:`schedule`), each run a separate ``facepuppet`` process writing its ``--json``;
4. takes the median of each figure over each side's rounds (:func:`median_report`) and compares the working
   tree's medians with the base's (:mod:`~facepuppet.runtime.bench.compare`): the ratio per figure, figures
   more than ``--threshold`` worse flagged, configuration that differs (say, the default samples) said first.

The runs' JSON, the medians and ``bench-check.json`` (both comparisons) stay in ``OUT``; the base's worktree
is removed at the end (``--keep`` keeps it). The exit code is 0 whatever the figures (benchmarks inform), 1
with ``--fail-worse`` when one is flagged, 2 when the sitting cannot run.

Run with ``python -m facepuppet.runtime.bench.bench_check``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from facepuppet.runtime.bench import compare, revision
from facepuppet.runtime.commands.options import parse_size
from facepuppet.runtime.errors import FacepuppetError, UsageError

SIDES = ("head", "base")  # A (the working tree), B (the base commit)
ICT_OBJ = ("ict-facekit", "generic_neutral_mesh.obj")


def bench_options(args: argparse.Namespace) -> dict[str, list[str]]:
    """The options of each benchmark in a round (options every version of the benchmarks takes)."""
    try:
        width, height = parse_size(args.render_size)
    except UsageError:
        raise UsageError(f"--render-size: expected WIDTHxHEIGHT such as 1280x720, got {args.render_size!r}") from None
    return {"render": ["--frames", str(args.render_frames), "--width", str(width), "--height", str(height)],
            "latency": ["--seconds", repr(float(args.latency_seconds))]}


def schedule(rounds: int, benches: tuple[str, ...], sides: tuple[str, ...] = SIDES) -> list[tuple[int, str, str]]:
    """(round, bench, side) in the order run: each bench on each side by turns (A, B, A, B ...), round by round."""
    return [(r, bench, side) for r in range(1, rounds + 1) for bench in benches for side in sides]


def median_report(reports: list[dict]) -> dict:
    """One report whose every number is the median of that number over ``reports`` (those that have it,
    finite); everything else (text, lists, flags) as the first report has it."""
    def merge(trees: list):
        first = trees[0]
        if isinstance(first, dict):
            return {k: merge([t[k] for t in trees if isinstance(t, dict) and k in t]) for k in first}
        if isinstance(first, (int, float)) and not isinstance(first, bool):
            values = [float(t) for t in trees
                      if isinstance(t, (int, float)) and not isinstance(t, bool) and math.isfinite(t)]
            return float(np.median(values)) if values else first
        return first

    if not reports:
        raise ValueError("median_report: no reports")
    return merge(reports)


def data_folder(option: str | None) -> Path:
    """The data kit: ``--data``, else ``$FACEPUPPET_DATA`` (``make bench-check`` sets it)."""
    named = option or os.environ.get("FACEPUPPET_DATA")
    if not named:
        raise UsageError("--data: the data kit folder is needed (the ICT head both sides import); pass --data DIR "
                         "or set FACEPUPPET_DATA")
    chosen = Path(named)
    obj = chosen.joinpath(*ICT_OBJ)
    if not obj.is_file():
        raise UsageError(f"--data {chosen}: {'/'.join(ICT_OBJ)} not found (the ICT head both sides import); "
                         "pass --data DIR or set FACEPUPPET_DATA")
    return chosen


def facepuppet(shim: Path, argv: list[str], python: str = sys.executable) -> None:
    """``facepuppet ARGV`` run by ``python`` importing through ``shim``; UsageError with the tail of its error output
    when it fails."""
    done = subprocess.run([python, "-m", "facepuppet", *argv], env=revision.shim_env(shim), cwd=str(shim),
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if done.returncode != 0:
        raise UsageError(f"facepuppet {' '.join(argv)} (through {shim}) exited {done.returncode}:\n"
                         + "\n".join(done.stdout.strip().splitlines()[-15:]))


def run_sitting(args: argparse.Namespace, run: Callable[[Path, list[str]], None] = facepuppet,
                log: Callable[[str], None] = print) -> dict:
    """The whole sitting (see the module doc); ``run(shim, argv)`` runs one ``facepuppet`` command. Returns what
    ``bench-check.json`` holds."""
    start = time.monotonic()

    def say(text: str) -> None:
        log(f"[{time.monotonic() - start:5.0f} s] {text}")

    options = bench_options(args)  # a bad --render-size is refused before anything is checked out
    repo = Path(revision.git(args.repo, "rev-parse", "--show-toplevel"))
    out = Path(args.out) if Path(args.out).is_absolute() else repo / args.out
    data = data_folder(args.data)
    base_sha = revision.resolve(repo, args.base)
    dirty = bool(revision.git(repo, "status", "--porcelain", "--untracked-files=no"))
    trees = {"head": repo, "base": revision.add_worktree(repo, base_sha, out / "base")}
    labels = {"head": f"working tree at {revision.describe(repo, 'HEAD')}"
                      + (" + uncommitted changes" if dirty else ""),
              "base": f"{args.base} = {revision.describe(repo, base_sha)}"}
    try:
        shims = {side: revision.make_shim(trees[side], out / f"shim-{side}") for side in SIDES}
        for side in SIDES:
            where = revision.check_shim(shims[side], trees[side])
            say(f"{side}: {labels[side]}; imports facepuppet.runtime from {Path(where['facepuppet.runtime'])}")
        characters = {}
        for side in SIDES:
            characters[side] = (out / "characters" / side / "ict.npz").resolve()  # one file name: alike
            characters[side].parent.mkdir(parents=True, exist_ok=True)
            say(f"{side}: importing the ICT head with its own import-rig")
            characters[side].unlink(missing_ok=True)  # no --force: older versions do not take it
            run(shims[side], ["import-rig", str(data.joinpath(*ICT_OBJ)), str(data / ICT_OBJ[0]), "-o",
                              str(characters[side])])
        runs = out / "runs"
        runs.mkdir(parents=True, exist_ok=True)
        files: dict[tuple[str, str], list[Path]] = {}
        for r, bench, side in schedule(args.rounds, tuple(options)):
            path = (runs / f"{side}-{bench}-{r}.json").resolve()
            say(f"round {r}/{args.rounds}: bench {bench} {' '.join(options[bench])} on {side}")
            path.unlink(missing_ok=True)
            run(shims[side], ["bench", bench, "-c", str(characters[side]), *options[bench], "--json", str(path)])
            files.setdefault((bench, side), []).append(path)
    finally:
        if not args.keep:
            revision.remove_worktree(repo, trees["base"])
    result = {"base": base_sha, "base_label": labels["base"], "head_label": labels["head"], "rounds": args.rounds,
              "options": options, "threshold": args.threshold, "comparisons": {}}
    for bench in options:
        medians = {}
        for side in SIDES:
            medians[side] = median_report([json.loads(p.read_text()) for p in files[(bench, side)]])
            medians[side]["rounds"] = [str(p) for p in files[(bench, side)]]
            (out / f"{side}-{bench}-median.json").write_text(json.dumps(medians[side], indent=2, sort_keys=True))
        comparison = compare.compare(medians["base"], medians["head"], args.threshold,
                                     baseline_path=f"the base (bench {bench}, median of {args.rounds})")
        log("")
        log(f"bench {bench}: the working tree against the base, medians of {args.rounds} rounds each")
        log("\n".join(comparison.lines()))
        result["comparisons"][bench] = comparison.to_json()
    (out / "bench-check.json").write_text(json.dumps(result, indent=2, sort_keys=True))
    say(f"wrote {out / 'bench-check.json'}")
    return result


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m facepuppet.runtime.bench.bench_check",
        description="bench render and bench latency of the working tree against an earlier commit, A/B by turns "
                    "in one sitting; the medians compared (make bench-check)")
    parser.add_argument("--base", default="HEAD~1", help="the commit to compare with (HEAD~1)")
    parser.add_argument("--rounds", type=int, default=3, help="runs of each benchmark on each side (3; at least 2)")
    parser.add_argument("--out", default=".bench", help="folder for the base's worktree, the shims and the JSON "
                                                        "(.bench in the repository, ignored by git)")
    parser.add_argument("--data", default=None, help="the data kit (default: $FACEPUPPET_DATA)")
    parser.add_argument("--render-frames", type=int, default=60, help="bench render --frames (60)")
    parser.add_argument("--render-size", default="1280x720", help="bench render --width x --height (1280x720)")
    parser.add_argument("--latency-seconds", type=float, default=5.0, help="bench latency --seconds (5)")
    parser.add_argument("--threshold", type=compare.threshold_percent, default=compare.THRESHOLD, metavar="PCT",
                        help=f"flag a figure worse by more than this ({compare.THRESHOLD * 100:g} %%)")
    parser.add_argument("--fail-worse", action="store_true", help="exit 1 when a figure is flagged")
    parser.add_argument("--keep", action="store_true", help="keep the base's worktree in OUT/base")
    parser.add_argument("--repo", default=".", help=argparse.SUPPRESS)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.rounds < 2 or args.render_frames < 2 or args.latency_seconds <= 0:
        print("bench-check: error: --rounds and --render-frames at least 2, --latency-seconds above 0", file=sys.stderr)
        return 2
    try:
        result = run_sitting(args)
    except (FacepuppetError, OSError) as exc:
        print(f"bench-check: error: {exc}", file=sys.stderr)
        return 2
    flagged = any(c["flagged"] for c in result["comparisons"].values())
    return 1 if args.fail_worse and flagged else 0


if __name__ == "__main__":
    raise SystemExit(main())
