"""``facepuppet batch JOBS.toml --out DIR``: every job of a jobs file replayed on a Dask cluster, resumably.

Read and check the jobs file (:mod:`~facepuppet.offline.batch.jobs`; a bad one exits 2 before anything runs,
and so does a group whose options ``replay`` itself refuses), hash every input once, skip each job whose folder
in DIR already holds its result (:func:`~facepuppet.offline.batch.manifest.is_done`), run the others on the
cluster (:mod:`~facepuppet.offline.batch.cluster`) with a progress line, then say what failed and why and write
``DIR/batch.json`` (each job's status, message, ticks and wall time; the counts). A failed job's folder, which
can only hold the result of other inputs, is removed. With ``--against GOLDEN_DIR`` the run is then compared
with an earlier one (:mod:`~facepuppet.offline.batch.golden`), the report in ``DIR/report/``. Exit 0 when every
job has its result (and, with ``--against``, none changed beyond tolerance), 1 otherwise.

DIR is not refused when it exists: resuming into it is the point. One batch at a time writes into a DIR: the
unfinished folders of ``DIR/.partial`` are removed when a batch ends.
"""

from __future__ import annotations

import argparse
import os
import shutil
import time
from pathlib import Path

from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.commands.replay import ReplayPlan
from facepuppet.runtime.errors import FacepuppetError, UsageError
from facepuppet.runtime.files.json_limits import dumps_strict
from facepuppet.runtime.files.outputs import write_atomic

from facepuppet.offline.batch import cluster
from facepuppet.offline.batch.golden import PIXEL_LEVEL, PIXEL_TOL, WEIGHT_TOL, compare_runs
from facepuppet.offline.batch.golden_report import (
    REPORT_MD,
    add_tolerance_arguments,
    check_tolerances,
    print_summary,
    write_report,
)
from facepuppet.offline.batch.job_run import PARTIAL, VIDEO, replay_argv, replay_parser
from facepuppet.offline.batch.jobs import Job, JobsFileError, load_jobs
from facepuppet.offline.batch.manifest import input_hashes, is_done

SUMMARY = "batch.json"
REPORT = "report"  # DIR/report/: --against's report (no manifest there: not a job folder)
PIPED_EVERY_S = 10.0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``batch`` to the ``facepuppet`` parser."""
    p = subparsers.add_parser(
        "batch", help="replay many takes on many characters (a jobs file) on a Dask cluster, resumably",
        description="Run every job of a jobs file (groups of takes x characters with replay's options and the "
                    "outputs to keep: weights, ARKit curves, video, frames at chosen times, a contact sheet) on a "
                    "Dask cluster, each job into DIR/<job id>/ with a manifest (inputs' hashes, options, "
                    "version, figures). A job whose result is already in DIR is skipped; a job that fails is "
                    "reported and the others go on. With --against, the run is then compared with an earlier "
                    "one (see batch-compare). Exit 0 when all passed, 1 when some failed (or changed, with "
                    "--against), 2 for a bad jobs file. Needs the extra 'batch' (Dask distributed).")
    p.add_argument("jobs", type=Path, metavar="JOBS.toml", help="the jobs file (docs/batch.md)")
    p.add_argument("--out", dest="out_dir", type=Path, required=True, metavar="DIR",
                   help="folder of the job folders; an existing one is resumed (its finished jobs skipped)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run on this existing Dask cluster (its workers need facepuppet and the jobs file's folder "
                        "at the same path); default: a local cluster")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--against", type=Path, default=None, metavar="GOLDEN_DIR",
                   help="after the run, compare each job folder of DIR with the one of the same id in GOLDEN_DIR "
                        "(an earlier run) as batch-compare does: the jobs changed beyond tolerance, most changed "
                        "first, and DIR/report/ (report.md with the worst frames side by side, report.json); "
                        "exit 1 when any changed")
    add_tolerance_arguments(p, when="with --against, ")
    p.set_defaults(func=run_batch)


def run_batch(args: argparse.Namespace) -> int:
    """Run the ``batch`` command from parsed ``args``; returns the exit code."""
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers: expected a number of processes >= 1, got {args.workers}")
    if args.workers is not None and args.scheduler is not None:
        raise UsageError("--workers: the workers of --scheduler's cluster are that cluster's; give one of them")
    _check_against(args)
    start = time.perf_counter()
    jobs = load_jobs(args.jobs)
    check_groups(args.jobs, jobs)
    out: Path = args.out_dir
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    out = out.resolve()
    cache: dict = {}
    todo = [job for job in jobs if not is_done(job, input_hashes(job, cache), out)]
    skipped = len(jobs) - len(todo)
    groups = len({job.group for job in jobs})
    print(f"batch: {len(jobs)} job{'s' if len(jobs) != 1 else ''} in {groups} group{'s' if groups != 1 else ''}: "
          f"{skipped} done already, {len(todo)} to run")
    reports = run_on_cluster(todo, out, args.scheduler, args.workers) if todo else []
    failed = [r for r in reports if r["status"] != "ok"]
    for report in failed:
        print(f"batch: {report['job']}: FAILED: {report['message'].strip()}")
        _discard(out, report["job"])
    wall = time.perf_counter() - start
    _write_summary(out, jobs, reports, wall)
    ran = len(reports) - len(failed)
    print(f"batch: {ran} ran, {skipped} skipped, {len(failed)} failed, in {wall:.1f} s; results in {out}/<job id>, "
          f"the list in {out / SUMMARY}")
    changed = _compare(out, args) if args.against is not None else []
    return 1 if failed or changed else 0


def _check_against(args: argparse.Namespace) -> None:
    """Refuse ``--against`` and its tolerances before anything runs."""
    if args.against is None:
        for flag, value, default in (("--weight-tol", args.weight_tol, WEIGHT_TOL),
                                     ("--pixel-tol", args.pixel_tol, PIXEL_TOL),
                                     ("--pixel-level", args.pixel_level, PIXEL_LEVEL)):
            if value != default:
                raise UsageError(f"{flag}: a tolerance of --against GOLDEN_DIR; give --against too")
        return
    if not args.against.is_dir():
        raise UsageError(f"--against {args.against}: expected the folder of an earlier batch run")
    if args.against.resolve() == args.out_dir.resolve():
        raise UsageError(f"--against {args.against}: the same folder as --out; name the earlier run's")
    check_tolerances(args)


def _compare(out: Path, args: argparse.Namespace) -> list:
    """This run against ``--against``'s: the summary printed, the report in ``out/report``; the changed jobs."""
    bar = Progress("batch --against", unit="jobs")

    with bar:
        report = compare_runs(out, args.against, weight_tol=args.weight_tol, pixel_tol=args.pixel_tol,
                              pixel_level=args.pixel_level, progress=bar.step)
    print_summary(report)
    write_report(report, out / REPORT)
    print(f"batch: the report against {args.against} in {out / REPORT / REPORT_MD}")
    return report.changed


def _discard(out: Path, job_id: str) -> None:
    """Remove a failed job's folder: it holds the result of other inputs (a job whose result matched was
    skipped), which a comparison against goldens would take for this run's."""
    folder = out / job_id
    if folder.is_dir():
        aside = out / PARTIAL / f"{job_id}.failed"
        aside.parent.mkdir(exist_ok=True)
        shutil.rmtree(aside, ignore_errors=True)
        os.replace(folder, aside)
        shutil.rmtree(aside, ignore_errors=True)


def check_groups(path: Path, jobs: list[Job]) -> None:
    """Refuse, before anything runs, a group whose options ``replay`` refuses (naming the jobs file and group)."""
    parser = replay_parser()
    seen = set()
    for job in jobs:
        if job.group in seen:
            continue
        seen.add(job.group)
        try:
            video = Path(job.id + VIDEO) if job.outputs.video else None  # (its plan checks PyAV and the codec)
            ReplayPlan.from_args(parser.parse_args(replay_argv(job, video)))
        except FacepuppetError as exc:
            raise JobsFileError(f"{path}: groups.{job.group}: {exc}") from None


def run_on_cluster(jobs: list[Job], out: Path, scheduler: str | None = None, workers: int | None = None
                   ) -> list[dict]:
    """Run ``jobs`` into ``out`` on a cluster, with a progress line; each job's report, in the order they ended."""
    try:
        with cluster.open_client(scheduler, workers) as client:
            failed = 0
            with Progress("batch", total=len(jobs), unit="jobs", piped_every_s=PIPED_EVERY_S) as bar:
                def done(report: dict) -> None:
                    nonlocal failed
                    failed += report["status"] != "ok"
                    bar.advance(1, note=f"{failed} failed" if failed else "")

                return cluster.run_jobs(client, jobs, out, done)
    finally:
        shutil.rmtree(out / PARTIAL, ignore_errors=True)


def _write_summary(out: Path, jobs: list[Job], reports: list[dict], wall_s: float) -> None:
    ran = {r["job"]: r for r in reports}
    entries = {}
    for job in jobs:
        r = ran.get(job.id)
        entries[job.id] = ({"status": "skipped"} if r is None else
                           {"status": r["status"], "message": r["message"], "ticks": r["ticks"],
                            "wall_s": round(r["wall_s"], 4)})
    counts = {s: sum(e["status"] == s for e in entries.values()) for s in ("ok", "skipped", "failed")}
    text = dumps_strict({"jobs": entries, "counts": counts, "wall_s": round(wall_s, 3)}, indent=1)
    write_atomic(out / SUMMARY, lambda temp: temp.write_text(text + "\n", encoding="utf-8"))
