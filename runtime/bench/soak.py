"""``facepuppet bench soak``: a simulated show, and whether the run's memory stays flat.

A sender *process* plays a tracker for the whole duration, repeating one show
cycle (``--cycle``, 60 s by default) of VMC frames at ``--rate`` Hz (120) to a
headless ``run`` in this process, with ``--record`` on (a temporary file,
deleted afterwards; its size is reported)::

    0    - 50 %   the face moves (every ARKit channel, sine waves); a
                  ``/facepuppet/calibrate`` message at 10 %
    50   - 67 %   idle: frames keep coming, the face holds still
    67   - 83 %   tracking loss: nothing is sent (the run eases to neutral)
    83   - 100 %  the face moves again; another calibration at 90 %

The run's resident memory (RSS, ``/proc/self/statm``) is sampled every
``--sample-s`` seconds (10) from a tick hook, and the slope after the warm-up
(``--warmup-s``, 60 s, at most a third of the run) is a least-squares fit in
MB per hour; the goal is a slope under 1 MB/hour (``goal_mb_per_hour``,
``passed`` in the JSON). With ``--tracemalloc`` the memory held by Python
objects (``tracemalloc.get_traced_memory``) is sampled too: it is what the
program retains, free of the allocator's and the GL driver's noise, at the
cost of a slower run.

With ``--panel`` the run draws the operator's panel into every frame (``run --headless --panel``) and, as
an operator would, presses its Record at 25 % of each cycle and Stop at 40 % (a new file each time, started
mid-run, in the temporary folder; each is deleted once the next starts, its size counted): the panel's
retained windows, its rings and the recorder's switching meet the whole show.

Length: 10 minutes by default; ``--hours``, ``--minutes`` or ``--seconds``
(summed when several are given) for another length.

Run the sender alone with ``python -m facepuppet.runtime.bench.soak --send HOST PORT RATE SECONDS CYCLE``.
"""

from __future__ import annotations

import argparse
import math
import socket
import subprocess
import sys
import tempfile
import threading
import time
import tracemalloc
from pathlib import Path

import numpy as np

from facepuppet.runtime.bench.latency import rss_mb
from facepuppet.runtime.bench.registry import load_average, register_bench, session_log
from facepuppet.runtime.bench.senders import paced
from facepuppet.runtime.commands.run import plan_from_argv, run_live
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.live.vmc_out import VmcSender
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.model.geometry import euler_to_quat

GOAL_MB_PER_HOUR = 1.0
MOVE_END, IDLE_END, LOSS_END = 0.5, 2 / 3, 5 / 6  # phase boundaries, fractions of a cycle
CALIBRATE_AT = (0.1, 0.9)


def phase(t: float, cycle_s: float) -> str:
    """The show's phase at ``t`` seconds: ``"move"``, ``"idle"`` or ``"loss"``."""
    f = (t % cycle_s) / cycle_s
    if f < MOVE_END or f >= LOSS_END:
        return "move"
    return "idle" if f < IDLE_END else "loss"


def send(host: str, port: int, rate: float, seconds: float, cycle_s: float) -> dict:
    """Play the show cycle to ``host:port`` for ``seconds``; returns what was sent."""

    sender = VmcSender(host, port, ARKIT_NAMES)
    calibrate = b"/facepuppet/calibrate\x00\x00\x00,\x00\x00\x00"  # OSC message, no arguments
    cal_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    n = len(ARKIT_NAMES)
    phases = np.arange(n) * 0.37
    held = 0.5 + 0.5 * np.sin(phases)
    sent = {"frames": 0, "calibrations": 0, "datagrams": 0}
    next_calibration = 0
    try:
        for t in paced(rate, seconds):
            cycle, f = divmod(t / cycle_s, 1.0)
            due = int(cycle) * len(CALIBRATE_AT) + sum(f >= c for c in CALIBRATE_AT)
            if due > next_calibration:
                next_calibration = due
                cal_sock.sendto(calibrate, (host, port))
                sent["calibrations"] += 1
            what = phase(t, cycle_s)
            if what == "loss":
                continue
            weights = held if what == "idle" else 0.5 + 0.5 * np.sin(2 * np.pi * 0.7 * t + phases)
            yaw = 0.0 if what == "idle" else 0.2 * math.sin(t)
            sender.send(weights, euler_to_quat(yaw, 0.0, 0.0), (0.0, 0.0, 0.0))
            sent["frames"] += 1
    finally:
        sent["datagrams"] = sender.counters["bundles_sent"] + sent["calibrations"]
        sender.close()
        cal_sock.close()
    return sent


def rss_parts_mb() -> dict[str, float]:
    """RSS split as the kernel counts it (``/proc/self/status``): anonymous (heap, driver buffers), file-backed
    (mapped libraries) and shared memory, in MiB; empty where the file is absent."""
    parts = {}
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                key, _, value = line.partition(":")
                if key in ("RssAnon", "RssFile", "RssShmem"):
                    parts[key[3:].lower()] = round(int(value.split()[0]) / 1024, 3)
    except OSError:
        pass
    return parts


def slope_per_hour(series: list[tuple[float, float]], after_s: float) -> float:
    """Least-squares slope of ``(t seconds, MB)`` samples at ``t >= after_s``, in MB per hour (NaN if < 3)."""
    pts = np.array([p for p in series if p[0] >= after_s], dtype=np.float64).reshape(-1, 2)
    if len(pts) < 3:
        return math.nan
    t, m = pts[:, 0], pts[:, 1]
    return float(np.polyfit(t, m, 1)[0] * 3600.0)


def duration_s(args: argparse.Namespace) -> float:
    """The run's length from ``--hours``, ``--minutes`` and ``--seconds`` (10 minutes when none is given)."""
    parts = [(args.hours, 3600.0), (args.minutes, 60.0), (args.seconds, 1.0)]
    given = [(v, unit) for v, unit in parts if v is not None]
    if not given:
        return 600.0
    total = 0.0
    for value, unit in given:
        if not (math.isfinite(value) and value >= 0):
            raise UsageError(f"bench soak: a length must be a finite number >= 0, got {value!r}")
        total += value * unit
    if total <= 0:
        raise UsageError("bench soak: the length (--hours + --minutes + --seconds) must be more than 0")
    return total


def bench_soak(args: argparse.Namespace) -> dict:
    seconds = duration_s(args)
    cycle_s = float(args.cycle)
    if not (math.isfinite(cycle_s) and cycle_s > 0):
        raise UsageError(f"bench soak --cycle: expected seconds > 0, got {args.cycle!r}")
    sample_s = float(args.sample_s)
    warmup_s = min(float(args.warmup_s), seconds / 3)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    workdir = Path(tempfile.mkdtemp(prefix="facepuppet-soak-"))
    record = workdir / "soak.fps"
    plan = plan_from_argv(["-c", str(args.character), "--input", "vmc", "--listen", f"127.0.0.1:{port}",
                           "--record", str(record), "--headless", "--size", args.size, "--fps", repr(float(args.fps)),
                           "--duration", repr(seconds + 120), "--path", args.path, "--receiver", args.receiver,
                           "--draw", "arrival", *(["--panel"] if args.panel else [])])
    stop = threading.Event()
    procs: list[subprocess.Popen] = []
    sender_out: list[str] = []
    rss: list[tuple[float, float]] = []
    parts: list[dict[str, float]] = []
    traced: list[tuple[float, float]] = []
    t0 = [0.0]
    next_sample = [0.0]
    panels: list = []  # the run's DeskPanel (--panel)
    presses = {"cycle": -1, "started": 0, "stopped": 0, "bytes": 0}
    done_files: list[Path] = []
    if args.tracemalloc:
        tracemalloc.start()

    def on_ready(address):
        t0[0] = time.monotonic()
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "facepuppet.runtime.bench.soak", "--send", "127.0.0.1", str(address[1]),
             repr(float(args.rate)), repr(seconds), repr(cycle_s)], stdout=subprocess.PIPE, text=True))

        def wait_for_sender():
            sender_out.append(procs[0].communicate()[0])
            stop.set()

        threading.Thread(target=wait_for_sender, daemon=True).start()

    def operate(now: float) -> None:
        """--panel: Record at 25 % of each cycle, Stop at 40 %, through the panel's own action; no Record once
        the show's time is up (the run only waits for the sender process to end, however long it took to
        start). A tick that comes late (a loaded machine, the first frames' shader builds) presses late rather
        than skipping the cycle: the Record at the first tick past 25 %, its Stop at the next past 40 %."""
        panel = panels[0]
        rec = panel.recorder
        f = (now % cycle_s) / cycle_s
        cycle = int(now // cycle_s)
        if f >= 0.25 and presses["cycle"] != cycle and not (rec.recording and rec.path != record) \
                and cycle < seconds / cycle_s:
            presses["cycle"] = cycle
            rec.wait_closed()  # the recording stopped last cycle is complete: count it and make room
            for path in done_files:
                presses["bytes"] += path.stat().st_size
                path.unlink()
            done_files.clear()
            panel.record_action("start")
            presses["started"] += 1
        elif f >= 0.4 and rec.recording and rec.path != record:
            done_files.append(rec.path)
            panel.record_action("stop")
            presses["stopped"] += 1

    def sample(info):
        now = time.monotonic() - t0[0]
        if panels:
            operate(now)
        if now < next_sample[0]:
            return
        next_sample[0] += sample_s
        rss.append((round(now, 2), round(rss_mb(), 3)))
        parts.append(rss_parts_mb())
        if args.tracemalloc:
            traced.append((round(now, 2), round(tracemalloc.get_traced_memory()[0] / 2**20, 4)))
        if not args.quiet:
            print(f"soak: {now:7.0f} s  RSS {rss[-1][1]:8.1f} MiB" + (f"  python {traced[-1][1]:8.2f} MiB" if traced
                                                                        else ""), flush=True)

    try:
        with session_log(args.verbose):
            result = run_live(plan, stop_event=stop, on_ready=on_ready, hooks=[sample],
                              on_panel=panels.append if args.panel else None)
    finally:
        for proc in procs:
            proc.kill()
            proc.wait()
        if args.tracemalloc:
            tracemalloc.stop()
        record_bytes = sum(p.stat().st_size for p in workdir.iterdir()) + presses["bytes"]
        for p in workdir.iterdir():
            p.unlink()
        workdir.rmdir()
    sent_lines = sender_out[0].strip().splitlines() if sender_out and sender_out[0].strip() else []
    sent = dict(zip(("frames", "calibrations", "datagrams"), map(int, sent_lines[-1].split()))) if sent_lines else {}
    slope = slope_per_hour(rss, warmup_s)
    out = {
        "seconds": seconds,
        "rate_hz": float(args.rate),
        "cycle_s": cycle_s,
        "sample_s": sample_s,
        "warmup_s": warmup_s,
        "receiver": args.receiver,
        "render_path": result.path,
        "ticks": result.loop.n_ticks,
        "sent": sent,
        "counters": result.counters,
        "record_bytes": record_bytes,
        "panel": None if not args.panel else {
            "records_started": presses["started"], "records_stopped": presses["stopped"],
            "desk_builds": result.panel.desk_builds if result.panel is not None else None,
            "settings_builds": result.panel.settings_builds if result.panel is not None else None},
        "rss_mb": [{"t_s": t, "mb": m, **p} for (t, m), p in zip(rss, parts)],
        "rss_slope_mb_per_hour": slope,
        "goal_mb_per_hour": GOAL_MB_PER_HOUR,
        "passed": bool(math.isfinite(slope) and slope < GOAL_MB_PER_HOUR),
        "loadavg": load_average(),
    }
    if args.tracemalloc:
        out["python_mb"] = [{"t_s": t, "mb": m} for t, m in traced]
        out["python_slope_mb_per_hour"] = slope_per_hour(traced, warmup_s)
    verdict = "PASS" if out["passed"] else ("n/a (too few samples)" if not math.isfinite(slope) else "FAIL")
    print(f"soak: {seconds:g} s, {out['ticks']} ticks, {sent.get('frames', -1)} frames sent; RSS slope after "
          f"{warmup_s:g} s: {slope:.3f} MB/hour (goal < {GOAL_MB_PER_HOUR:g}): {verdict}"
          + (f"; python objects {out['python_slope_mb_per_hour']:.3f} MB/hour" if args.tracemalloc else "")
          + (f"; panel shown, Record pressed {presses['started']} times, Stop {presses['stopped']}" if args.panel
             else ""))
    return out


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-c", "--character", required=True, help="character .npz (the ICT head for a real show)")
    parser.add_argument("--hours", type=float, default=None, help="length in hours (default: 10 minutes in all)")
    parser.add_argument("--minutes", type=float, default=None, help="length in minutes (added to --hours)")
    parser.add_argument("--seconds", type=float, default=None, help="length in seconds (added; a short test)")
    parser.add_argument("--rate", type=float, default=120.0, help="tracker frames per second (120)")
    parser.add_argument("--cycle", type=float, default=60.0, help="seconds of one show cycle (60)")
    parser.add_argument("--sample-s", type=float, default=10.0, help="seconds between RSS samples (10)")
    parser.add_argument("--warmup-s", type=float, default=60.0,
                        help="seconds left out of the slope (60; at most a third of the run)")
    parser.add_argument("--size", default="320x240", help="render size (320x240)")
    parser.add_argument("--fps", type=float, default=60.0, help="idle redraw rate of the run (60)")
    parser.add_argument("--path", choices=("auto", "gpu", "cpu"), default="auto", help="deformation path")
    parser.add_argument("--receiver", choices=("process", "thread"), default="process", help="the run's receiver")
    parser.add_argument("--tracemalloc", action="store_true", help="also sample the memory Python objects hold")
    parser.add_argument("--panel", action="store_true",
                        help="draw the operator's panel into every frame and press its Record / Stop each cycle "
                             "(needs imgui-bundle)")
    parser.add_argument("--quiet", action="store_true", help="no line per sample")
    parser.add_argument("--verbose", action="store_true", help="show the run's own log")


register_bench(
    "soak",
    bench_soak,
    "a simulated show (tracker, idle, tracking loss, calibrations, recording): RSS every 10 s and its slope",
    _add_arguments,
)


if __name__ == "__main__":
    if len(sys.argv) == 7 and sys.argv[1] == "--send":
        done = send(sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5]), float(sys.argv[6]))
        print(done["frames"], done["calibrations"], done["datagrams"], flush=True)
    else:
        print("usage: python -m facepuppet.runtime.bench.soak --send HOST PORT RATE SECONDS CYCLE", file=sys.stderr)
        raise SystemExit(2)
