"""The report of a run against its goldens, for a person (Markdown with pictures) and for a program (JSON);
and ``facepuppet batch-compare``, which compares two runs on its own.

A table says which jobs changed and how; a number does not show where a face went wrong, so under it each
changed job's worst frames are laid side by side, golden | new | difference, the difference as a heat map on
one fixed scale (black: equal; red, yellow, white: 1/3, 2/3, all of ``HEAT_FULL`` levels or more) so two
pictures' heat can be compared at a glance.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import numpy as np
from PIL import Image

from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.files.json_limits import dumps_strict
from facepuppet.runtime.files.outputs import write_atomic
from facepuppet.runtime.render.images import contact_sheet, save_png

from facepuppet.offline.batch.golden import (
    PIXEL_LEVEL,
    PIXEL_TOL,
    WEIGHT_TOL,
    FrameDiff,
    Report,
    compare_runs,
    difference_map,
)
from facepuppet.offline.batch.golden_jobs import load_frame

REPORT_MD, REPORT_JSON, THUMBS = "report.md", "report.json", "thumbs"
HEAT_FULL = 64          # levels of difference drawn white
THUMB_HEIGHT = 192      # pixels of each picture of a side-by-side
WORST_FRAMES = 3        # frames shown per changed job


def write_report(report: Report, out_dir: Path, *, worst: int = WORST_FRAMES,
                 thumb_height: int = THUMB_HEIGHT) -> list[Path]:
    """Write ``report.md``, ``report.json`` and the side-by-side PNGs of each changed job's ``worst`` frames
    (``thumbs/<rank>_<job>_frame_<index>.png``) into ``out_dir`` (made if missing); returns the files written."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    pictures: dict[str, list[tuple[FrameDiff, str]]] = {}
    for rank, job in enumerate(report.changed, 1):
        for frame in job.worst_frames(worst):
            if frame.note:        # frames of two sizes: nothing to lay side by side
                continue
            # the rank keeps two ids that differ only in characters a file name avoids apart
            name = f"{THUMBS}/{rank:04d}_{_file_name(job.job)}_frame_{frame.index:05d}.png"
            (out_dir / THUMBS).mkdir(exist_ok=True)
            written.append(save_png(out_dir / name, side_by_side(frame, thumb_height)))
            pictures.setdefault(job.job, []).append((frame, name))
    md = markdown(report, pictures)
    written.append(write_atomic(out_dir / REPORT_MD, lambda p: p.write_text(md, encoding="utf-8")))
    text = dumps_strict(report.to_json(worst), indent=1)
    written.append(write_atomic(out_dir / REPORT_JSON, lambda p: p.write_text(text + "\n", encoding="utf-8")))
    return written


def side_by_side(frame: FrameDiff, height: int = THUMB_HEIGHT) -> np.ndarray:
    """golden | new | heat map of their difference, each ``height`` pixels high, labelled: (h, w, 3) uint8."""
    new, golden = load_frame(frame.new), load_frame(frame.golden)
    diff = difference_map(new, golden)
    when = "" if frame.t is None else f" ({frame.t:.3f} s)"
    cells = [(f"golden, frame {frame.index}{when}", golden), ("new", new),
             (f"difference, max {int(diff.max())} levels", heat_map(diff))]
    return contact_sheet([(label, _scaled(rgb, height)) for label, rgb in cells], columns=3)


def heat_map(diff: np.ndarray) -> np.ndarray:
    """(h, w) uint8 levels of difference as (h, w, 3) uint8 RGB: black, red, yellow, white at ``HEAT_FULL``."""
    t = np.clip(diff.astype(np.float32) / HEAT_FULL, 0.0, 1.0)[..., None] * 3.0
    rgb = np.clip(t - np.array([0.0, 1.0, 2.0], np.float32), 0.0, 1.0)
    return (rgb * 255.0 + 0.5).astype(np.uint8)


def markdown(report: Report, pictures: dict[str, list[tuple[FrameDiff, str]]]) -> str:
    """The report as Markdown: the tolerances, the table of changed jobs, then each one's worst frames."""
    changed = report.changed
    lines = ["# Batch run against its goldens", "",
             f"- new run: `{report.new_dir}`", f"- golden run: `{report.golden_dir}`",
             f"- tolerances: |Δweight| ≤ {report.weight_tol:g}; at most {report.pixel_tol:.3%} of a frame's "
             f"pixels more than {report.pixel_level} levels apart",
             f"- {len(report.jobs)} jobs compared, **{len(changed)} changed beyond tolerance**", ""]
    if changed:
        lines += ["| rank | job | max \\|Δweight\\| (channel) | worst frame: pixels over / mean \\|Δ\\| "
                  "| what changed |",
                  "|---:|---|---|---|---|"]
        for rank, job in enumerate(changed, 1):
            weight = ("-" if not job.channel_delta else "0" if job.worst_channel is None
                      else f"{job.max_weight_delta:.3g} ({_cell(job.worst_channel)})")
            worst = job.worst_frames(1)
            frame = (f"{worst[0].index}: {worst[0].over:.2%} / {worst[0].mean_abs:.2f}" if worst else
                     "not comparable" if not job.frames_comparable else "-")
            what = "; ".join(job.problems + ([f"inputs: {', '.join(job.inputs_changed)}"] if job.inputs_changed
                                             else []) + job.notes) or "within the table's figures"
            lines.append(f"| {rank} | {_cell(job.job)} | {weight} | {frame} | {_cell(what)} |")
        lines.append("")
    quiet = [j for j in report.jobs if not j.changed and (j.inputs_changed or j.notes)]
    if quiet:
        lines += [f"{len(quiet)} job{'s' if len(quiet) > 1 else ''} within tolerance with other inputs or notes: "
                  + ", ".join(f"{_cell(j.job)} ({_cell('; '.join(j.inputs_changed + j.notes))})" for j in quiet),
                  ""]
    for job in changed:
        shown = pictures.get(job.job)
        if not shown:
            continue
        lines += [f"## {job.job}", "", job.summary(), ""]
        for frame, name in shown:
            when = "" if frame.t is None else f" at {frame.t:.3f} s"
            lines += [f"frame {frame.index}{when}: {frame.over:.2%} of pixels over {report.pixel_level} levels, "
                      f"mean |Δ| {frame.mean_abs:.2f} (heat: white at {HEAT_FULL} levels)", "",
                      f"![{_cell(job.job)} frame {frame.index}: golden, new, difference]({name})", ""]
    return "\n".join(lines)


def print_summary(report: Report) -> None:
    """The comparison in a few lines on stdout: the counts, then one line per changed job."""
    changed = report.changed
    n = len(report.jobs)
    print(f"batch-compare: {n} job{'' if n == 1 else 's'}, {len(changed)} changed beyond tolerance "
          f"(|Δweight| > {report.weight_tol:g} or more than {report.pixel_tol:.3%} of a frame's pixels over "
          f"{report.pixel_level} levels)")
    for job in changed:
        print(f"  {job.job}: {job.summary()}")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``batch-compare`` to the ``facepuppet`` parser."""
    p = subparsers.add_parser(
        "batch-compare", help="compare a batch run's job folders with an earlier (golden) run's",
        description="Compare each job of a batch run with the job of the same id in an earlier run: missing "
                    "jobs, changed inputs (content hashes), the largest |Δweight| per channel, each frame's "
                    "difference (on one deformation path). Lists the jobs changed beyond tolerance, most "
                    "changed first; with --out, writes report.md (a table, and the worst frames of each changed "
                    "job side by side: golden | new | difference), report.json and the pictures. Exit 0 when "
                    "nothing changed beyond tolerance, 1 when something did, 2 for input it cannot read.")
    p.add_argument("new_dir", type=Path, metavar="NEW_DIR", help="the run to check (folder of job folders)")
    p.add_argument("golden_dir", type=Path, metavar="GOLDEN_DIR", help="the earlier run it is compared with")
    p.add_argument("--out", type=Path, metavar="REPORT_DIR", help="folder to write the report into")
    add_tolerance_arguments(p)
    p.set_defaults(func=_batch_compare)


def _batch_compare(args: argparse.Namespace) -> int:
    check_tolerances(args)
    bar = Progress("batch-compare", unit="jobs")

    with bar:
        report = compare_runs(args.new_dir, args.golden_dir, weight_tol=args.weight_tol,
                              pixel_tol=args.pixel_tol, pixel_level=args.pixel_level, progress=bar.step)
    print_summary(report)
    if args.out is not None:
        write_report(report, args.out)
        print(f"batch-compare: wrote {args.out / REPORT_MD} and {args.out / REPORT_JSON}")
    return 1 if report.changed else 0


def _scaled(rgb: np.ndarray, height: int) -> np.ndarray:
    """``rgb`` resized to ``height`` rows at its aspect: blocky when enlarged (pixels stay visible), smooth when
    shrunk."""
    h, w = rgb.shape[:2]
    width = max(1, round(w * height / h))
    resample = Image.NEAREST if height >= h else Image.LANCZOS
    return np.asarray(Image.fromarray(rgb).resize((width, height), resample))


def _file_name(job: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]", "_", job)


def _cell(text: object) -> str:
    """``text`` safe inside a Markdown table cell and heading: pipes escaped, one line."""
    return str(text).replace("|", "\\|").replace("\n", " ")


def add_tolerance_arguments(p: argparse.ArgumentParser, when: str = "") -> None:
    """``--weight-tol``, ``--pixel-tol`` and ``--pixel-level`` (``batch-compare``'s, and ``batch --against``'s
    with ``when`` = "with --against, ")."""
    p.add_argument("--weight-tol", type=float, default=WEIGHT_TOL,
                   help=f"{when}the largest |Δweight| of a channel that is no change (default {WEIGHT_TOL:g})")
    p.add_argument("--pixel-tol", type=float, default=PIXEL_TOL,
                   help=f"{when}the fraction of a frame's pixels that may differ by more than --pixel-level "
                        f"(default {PIXEL_TOL:g})")
    p.add_argument("--pixel-level", type=int, default=PIXEL_LEVEL,
                   help=f"{when}the largest difference of a pixel (0-255, its most different RGB channel) that "
                        f"counts as equal (default {PIXEL_LEVEL})")


def check_tolerances(args: argparse.Namespace) -> None:
    """UsageError for a tolerance out of its range."""
    if not args.weight_tol >= 0:
        raise UsageError(f"--weight-tol {args.weight_tol}: expected a number >= 0")
    if not 0 <= args.pixel_tol <= 1:
        raise UsageError(f"--pixel-tol {args.pixel_tol}: expected a fraction of the pixels, in [0, 1]")
    if not 0 <= args.pixel_level <= 255:
        raise UsageError(f"--pixel-level {args.pixel_level}: expected 0 to 255")
