"""``facepuppet bench batch --json OUT.json``: what the cluster costs per job, how it scales, and a paper
estimate of a studio's library.

A library is generated in a temporary folder: ``--takes`` session takes of the demo's synthetic performance
(``--seconds`` each at 30 frames/s, one seed per take) on the demo head (about 13k vertices, ARKit's shapes),
replayed on the CPU path at ``--size``, each job keeping its weights (what a plain ``replay --dump-weights``
writes, so the two are the same work). Measured:

* ``plain``: every job as a plain ``facepuppet replay --dump-weights`` in this process (its own context per
  replay, as the command makes), one after another: ``per_job_s``, the cost of the work itself;
* ``workers_1``, ``workers_2``: the same jobs through ``facepuppet batch``'s code on a LocalCluster of 1 and 2
  worker processes: ``start_s`` (the cluster started and its workers warmed: imports, one EGL context each),
  then ``jobs_per_s`` and ``per_job_s`` over the jobs alone (submission to the last result; the median of
  ``--rounds`` passes, each pass of 1 worker right after a pass of plain replays, so that both meet the
  machine's load of the same moment), and
  ``scheduling_overhead``: the time between jobs, ``(per_job_s * workers - job_wall_mean_s) / job_wall_mean_s``,
  where ``job_wall_mean_s`` is a job's own time inside its worker;
* ``overhead``: 1 worker's per-job time against the plain replay's, ``(cluster - plain) / plain`` (the goal
  is under 10 %); ``scaling_efficiency``: ``jobs_per_s(2) / (2 * jobs_per_s(1))``;
* ``subprocess_per_job_s``: a few jobs as a shell loop would run them, one ``facepuppet replay`` process each
  (start-up and imports included), for scale;
* ``estimate``: 10,000 jobs (``--estimate-jobs``) on 1, 10 and 100 machines of this machine's cores, from
  1 worker's per-job cost, every worker at the measured scaling efficiency, plus one cluster start: a paper
  figure, which assumes the jobs are like these and the shared filesystem keeps up.

The figures move with the machine's load (``load_average`` is kept with them).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from facepuppet.runtime.bench.registry import load_average
from facepuppet.runtime.cli import main
from facepuppet.runtime.demo.head import build_demo_character
from facepuppet.runtime.demo.performance import demo_frames
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.recording.session import SessionWriter

from facepuppet.offline.batch import cluster
from facepuppet.offline.batch.job_run import replay_argv, replay_parser, worker_context
from facepuppet.offline.batch.jobs import Job, load_jobs

MACHINES = (1, 10, 100)
SUBPROCESS_JOBS = 3


def _add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--takes", type=int, default=8, help="takes in the generated library (default 8), one job each")
    p.add_argument("--seconds", type=float, default=2.0, help="seconds per take (default 2)")
    p.add_argument("--size", default="320x240", help="picture size of the jobs (default 320x240)")
    p.add_argument("--rounds", type=int, default=3, help="passes over the jobs per measure, the median kept "
                                                         "(default 3; a worker's first pass is its slowest)")
    p.add_argument("--estimate-jobs", type=int, default=10_000,
                   help="jobs in the paper estimate (default 10000)")


def register_benches(register_bench: Callable[..., None]) -> None:
    """Entry of ``offline/commands.py``: add ``bench batch``."""
    register_bench("batch", run_bench, "facepuppet batch on a LocalCluster of 1 and 2 workers: jobs/s, scaling "
                   "efficiency, per-job overhead against a plain replay, a paper estimate of 10,000 jobs on N "
                   "machines", _add_arguments)


def _library(root: Path, takes: int, seconds: float, size: str) -> Path:
    build_demo_character().save(root / "head.npz")
    for seed in range(takes):
        with SessionWriter(root / f"take{seed:02d}.fps") as w:
            for frame in demo_frames(duration=seconds, rate=30.0, seed=seed):
                w.write_frame(frame)
    jobs = root / "jobs.toml"
    jobs.write_text(f'[groups.bench]\ntakes = ["take*.fps"]\ncharacters = ["head.npz"]\npath = "cpu"\n'
                    f'size = "{size}"\n[groups.bench.outputs]\nweights = true\n')
    return jobs


def _plain(jobs: list[Job], folder: Path) -> list[float]:
    """Wall time of each job as a plain in-process ``facepuppet replay`` with the same outputs."""
    walls = []
    for job in jobs:
        out = folder / job.id
        out.mkdir(parents=True)
        argv = [*replay_argv(job), "--dump-weights", str(out / "w.npy")]
        start = time.perf_counter()
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            code = main(argv)
        walls.append(time.perf_counter() - start)
        if code != 0:
            raise UsageError(f"bench batch: the plain replay of {job.id} failed (exit {code})")
    return walls


def _subprocess(jobs: list[Job], folder: Path) -> list[float]:
    walls = []
    for job in jobs[:SUBPROCESS_JOBS]:
        out = folder / f"sub-{job.id}"
        out.mkdir(parents=True)
        argv = [*replay_argv(job), "--dump-weights", str(out / "w.npy")]
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "facepuppet", *argv], check=True, capture_output=True, timeout=600)
        walls.append(time.perf_counter() - start)
    return walls


def _warm() -> str:
    """On a worker: the imports and the EGL context its first job would make."""
    replay_parser()
    return worker_context().ctx.info.get("GL_RENDERER", "")


def _on_cluster(jobs: list[Job], out: Path, workers: int, rounds: int, plain: list[float] | None = None) -> dict:
    """``rounds`` passes of every job on a LocalCluster of ``workers``; with ``plain``, each pass follows one of
    plain replays in this process (appended to ``plain``), so both see the machine's load of the same moment."""
    start = time.perf_counter()
    walls, inside = [], []
    with cluster.open_client(workers=workers, log=lambda line: None) as client:
        client.run(_warm)
        started = time.perf_counter() - start
        for k in range(rounds):
            if plain is not None:
                plain += _plain(jobs, out / f"plain{k}")
            t = time.perf_counter()
            reports = cluster.run_jobs(client, jobs, out / f"round{k}", lambda report: None)
            walls.append(time.perf_counter() - t)
            failed = [r for r in reports if r["status"] != "ok"]
            if failed:
                raise UsageError(f"bench batch: {failed[0]['job']} failed: {failed[0]['message']}")
            inside.append(statistics.fmean(r["wall_s"] for r in reports))
    wall = statistics.median(walls)
    job_wall = statistics.median(inside)
    return {"workers": workers, "start_s": started, "rounds_s": walls, "jobs_per_s": len(jobs) / wall,
            "per_job_s": wall / len(jobs), "job_wall_mean_s": job_wall,
            "scheduling_overhead": (wall / len(jobs) * workers - job_wall) / job_wall}


def _estimate(per_job_s: float, efficiency: float, start_s: float, n_jobs: int, cores: int) -> list[dict]:
    """Hours for ``n_jobs`` on each count of machines: every worker at the measured efficiency."""
    rows = []
    for machines in MACHINES:
        workers = machines * cores
        rate = workers * min(efficiency, 1.0) / per_job_s
        rows.append({"machines": machines, "workers": workers, "hours": (start_s + n_jobs / rate) / 3600})
    return rows


def run_bench(args: argparse.Namespace) -> dict:
    if not 1 <= args.takes <= 1000:
        raise UsageError(f"bench batch --takes: expected 1 to 1000, got {args.takes}")
    if not 0 < args.seconds <= 600:
        raise UsageError(f"bench batch --seconds: expected a positive number up to 600, got {args.seconds!r}")
    if not 1 <= args.rounds <= 20:
        raise UsageError(f"bench batch --rounds: expected 1 to 20, got {args.rounds}")
    if args.estimate_jobs < 1:
        raise UsageError(f"bench batch --estimate-jobs: expected a positive count, got {args.estimate_jobs}")
    with tempfile.TemporaryDirectory(prefix="facepuppet-bench-batch-") as tmp:
        root = Path(tmp)
        lib = root / "lib"
        lib.mkdir()
        jobs = load_jobs(_library(lib, args.takes, args.seconds, args.size))
        plain: list[float] = []
        one = _on_cluster(jobs, root / "w1", 1, args.rounds, plain)
        two = _on_cluster(jobs, root / "w2", 2, args.rounds)
        sub = _subprocess(jobs, root / "sub")
    plain_per_job = statistics.median(sum(plain[k:k + len(jobs)]) for k in range(0, len(plain), len(jobs))) / len(jobs)
    efficiency = two["jobs_per_s"] / (2 * one["jobs_per_s"])
    cores = os.cpu_count() or 1
    return {
        "jobs": len(jobs), "take_seconds": args.seconds, "size": args.size, "path": "cpu",
        "plain": {"per_job_s": plain_per_job, "median_s": statistics.median(plain), "total_s": sum(plain)},
        "workers_1": one, "workers_2": two,
        "overhead": (one["per_job_s"] - plain_per_job) / plain_per_job, "overhead_goal": 0.10,
        "scaling_efficiency": efficiency,
        "subprocess_per_job_s": statistics.median(sub),
        "estimate": {"jobs": args.estimate_jobs, "cores_per_machine": cores, "per_job_s": one["per_job_s"],
                     "scaling_efficiency": efficiency,
                     "rows": _estimate(one["per_job_s"], efficiency, two["start_s"], args.estimate_jobs, cores)},
        "load_average": load_average(),
    }
