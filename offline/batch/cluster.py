"""Batch jobs on Dask distributed: a LocalCluster of this machine's cores, or an existing cluster.

Dask distributed is the optional extra ``batch`` (``pip install 'facepuppet[batch]'``), imported only when a
batch runs. A LocalCluster has one worker process per core (``threads_per_worker=1``: a worker draws in one
headless EGL context, and a replay is one thread of Python and drawing), bound to 127.0.0.1. Each job is one
task running :func:`~facepuppet.offline.batch.job_run.run_job`; a job's own failure comes back as its report,
so the scheduler's resubmission is left for what it is for: a worker that died (killed, out of memory, a lost
machine) has its job run again on another, up to ``distributed.scheduler.allowed-failures`` times (3 by
default) before the job is reported failed with the scheduler's word on it.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import os
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from facepuppet.runtime.errors import UsageError

from facepuppet.offline.batch.job_run import run_job
from facepuppet.offline.batch.jobs import Job

if TYPE_CHECKING:
    from distributed import Client

logger = logging.getLogger(__name__)

INSTALL_HINT = "pip install 'facepuppet[batch]' (Dask distributed)"
DASHBOARD = ":8787"


def _distributed():
    try:
        import distributed  # the optional extra `batch`
    except ImportError:
        raise UsageError(f"batch: needs Dask distributed, which is not installed: {INSTALL_HINT}") from None
    return distributed


@contextlib.contextmanager
def open_client(scheduler: str | None = None, workers: int | None = None, log: Callable[[str], None] = print
                ) -> Iterator:
    """A Dask client: on the cluster at ``scheduler`` (``tcp://HOST:PORT``), else on a LocalCluster of
    ``workers`` processes (default: one per core). Says where it runs and the dashboard's address when there is
    one; the LocalCluster is closed with the block."""
    distributed = _distributed()
    if scheduler is not None:
        try:
            client = distributed.Client(scheduler, timeout="20s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise UsageError(f"--scheduler {scheduler}: cannot reach a Dask scheduler there: {exc}") from None
        with client:
            n = len(client.scheduler_info().get("workers", {}))
            log(f"batch: on the cluster at {scheduler}, {n} worker{'s' if n != 1 else ''}")
            _say_dashboard(client, log)
            yield client
        return
    n = workers or os.cpu_count() or 1
    # Without bokeh Dask has no dashboard (and would warn that it cannot start one): ask for it only then.
    dashboard = DASHBOARD if importlib.util.find_spec("bokeh") is not None else None
    with distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=dashboard) as cluster, distributed.Client(cluster) as client:
        log(f"batch: on a local cluster of {n} worker process{'es' if n != 1 else ''} at {cluster.scheduler_address}")
        _say_dashboard(client, log)
        yield client


def _say_dashboard(client: Client, log: Callable[[str], None]) -> None:
    link = None
    with contextlib.suppress(Exception):  # a cluster without a dashboard answers in more than one way
        if client.scheduler_info().get("services", {}).get("dashboard"):
            link = client.dashboard_link
    if link:
        log(f"batch: Dask's dashboard: {link}")


def run_jobs(client: Client, jobs: Iterable[Job], out: Path, on_done: Callable[[dict], None]) -> list[dict]:
    """Submit every job, call ``on_done(report)`` as each ends (in the order they end); the reports."""
    distributed = _distributed()
    futures = {}
    for job in jobs:
        future = client.submit(run_job, job, str(out), key=f"facepuppet-batch-{job.id}-{os.urandom(4).hex()}",
                               pure=False)
        futures[future] = job
    reports = []
    for future in distributed.as_completed(futures):
        job = futures[future]
        try:
            report = future.result()
        except Exception as exc:  # the scheduler gave the job up (its workers kept dying) or lost it
            report = {"job": job.id, "status": "failed", "message": f"{type(exc).__name__}: {exc}", "ticks": 0,
                      "wall_s": 0.0, "pid": None}
        reports.append(report)
        on_done(report)
    return reports
