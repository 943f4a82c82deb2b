"""The virtual card's latency in fresh processes: ``card_latency`` run several times, each in a new Python.

``bench voice`` measures the card once, late in a long process whose imports, fits and caches are all warm.
A user's ``run --audio`` is a fresh process: its start-up (imports, the chain, the GL context) and a busy
machine are what can keep the capture callback from running, so this runs
:func:`~facepuppet.offline.voice.card_latency.card_latency` in ``runs`` new interpreters, one after the
other, and reports each run's onset latencies, how far the capture fell behind the wall clock and the
microphone's counters (blocks read, dropped as stale), then the median of the runs' medians and the worst
p99::

    python -m facepuppet.offline.voice.card_runs voice.npz --runs 4 --onsets 8 --json out.json
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

CHILD = """
import json, sys
from pathlib import Path
from facepuppet.offline.voice.card_latency import card_latency
print(json.dumps(card_latency(Path(sys.argv[1]), Path(sys.argv[2]), onsets=int(sys.argv[3]), log=lambda s: None)))
"""

KEYS = ("played_to_drawn", "played_to_arrived", "arrived_to_drawn")


def one_run(table: Path, onsets: int, timeout_s: float = 300.0) -> dict:
    """``card_latency`` in a new interpreter; its result, or ``{"available": False, "reason": ...}``."""
    with tempfile.TemporaryDirectory() as d:
        try:
            proc = subprocess.run([sys.executable, "-c", CHILD, str(table), d, str(onsets)], capture_output=True,
                                  text=True, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return {"available": False, "reason": f"the run did not end within {timeout_s:g} s"}
    lines = proc.stdout.strip().splitlines()
    try:
        return json.loads(lines[-1])
    except (IndexError, json.JSONDecodeError):
        return {"available": False, "reason": proc.stderr[-500:] or f"exit status {proc.returncode}"}


def summarise(results: list[dict]) -> dict:
    """Each key's median of the runs' medians and worst p99 (ms), the onsets drawn, the blocks dropped."""
    ok = [r for r in results if r.get("available")]
    out: dict = {"runs": len(results), "measured": len(ok)}
    for key in KEYS:
        med = [r[key]["median_ms"] for r in ok if r[key]["n"]]
        p99 = [r[key]["p99_ms"] for r in ok if r[key]["n"]]
        out[key] = {"median_of_medians_ms": float(np.median(med)) if med else math.nan,
                    "worst_p99_ms": float(max(p99)) if p99 else math.nan}
    out["onsets_drawn"] = [f"{r['detected']['drawn']}/{r['onsets']}" for r in ok]
    out["capture_backlog_max_ms"] = [round(r["capture"]["capture_backlog_ms"]["max"]) for r in ok]
    out["microphone"] = [r.get("microphone") for r in ok]
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m facepuppet.offline.voice.card_runs", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("table", type=Path, help="a voice table (fit-voice)")
    parser.add_argument("--runs", type=int, default=4)
    parser.add_argument("--onsets", type=int, default=8)
    parser.add_argument("--json", type=Path, default=None, metavar="OUT.json")
    args = parser.parse_args(argv)
    if not 1 <= args.runs <= 100 or not 1 <= args.onsets <= 100:
        parser.error("--runs and --onsets: expected 1..100")
    results = []
    for k in range(args.runs):
        r = one_run(args.table, args.onsets)
        results.append(r)
        if r.get("available"):
            pd, mic = r["played_to_drawn"], r.get("microphone") or {}
            print(f"run {k + 1}: played -> drawn median {pd['median_ms']:.1f} ms, p99 {pd['p99_ms']:.1f} ms "
                  f"({r['detected']['drawn']}/{r['onsets']} drawn); capture backlog max "
                  f"{r['capture']['capture_backlog_ms']['max']:.0f} ms; {mic.get('stale_dropped')} of "
                  f"{mic.get('blocks')} blocks dropped as stale", flush=True)
        else:
            print(f"run {k + 1}: not measured ({r.get('reason')})", flush=True)
    report = {"summary": summarise(results), "runs": results}
    print(json.dumps(report["summary"]))
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
