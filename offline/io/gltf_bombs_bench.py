"""``facepuppet bench gltf-bombs --json OUT.json``: each forged hostile glTF through ``import-rig`` and ``check-gltf``.

Every forger of :mod:`.gltf_bombs` writes its file into a fresh folder; each
command then runs on it in a process of its own (``python -m facepuppet``),
started by a small watcher process, so the peak resident memory reported is
that command's on that file alone (its ``ru_maxrss`` from ``wait4``),
start-up included, as a user would meet it. A case is ``ok`` when both commands refuse the file (exit
2, the file named, the JSON path the attack is in named, no traceback) within the budget: :data:`BUDGET_MB` of peak
memory and :data:`BUDGET_S` seconds. A child that is still running at
``--timeout`` (a hang) or grows past ``--kill-mb`` (a memory bomb) is killed
and reported so, which keeps the benchmark itself bounded on a machine where
the readers are not.

The baseline is both commands on a small sound file (one triangle), which
``import-rig`` reads and ``check-gltf`` passes: the part of each measure that
is the command's own start-up.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

from facepuppet.runtime.errors import UsageError

from facepuppet.offline.io import gltf_bombs

#: What each refusal may cost at most (the issue's goal on this machine): peak RSS, MB, and seconds.
BUDGET_MB = 256.0
BUDGET_S = 2.0
MAX_LINES = 20  # lines of what a command said kept in the results


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cases", nargs="+", metavar="NAME", choices=sorted(gltf_bombs.FORGERIES),
                        help="the forged cases to run (default: all): " + ", ".join(gltf_bombs.FORGERIES))
    parser.add_argument("--timeout", type=float, default=20.0,
                        help="seconds after which a command still running is killed as a hang (default 20)")
    parser.add_argument("--kill-mb", type=float, default=2048.0,
                        help="resident MB past which a command is killed as a memory bomb (default 2048)")


#: The watcher of one command, run as ``python -S -c`` (no site, no NumPy: about 10 MB). The command is its
#: child, not the benchmark's: Linux folds the memory of the process a child was forked from into that child's
#: ``ru_maxrss`` (the image it had before ``exec``), so a child forked from the benchmark itself would report
#: at least the benchmark's own peak.
_WATCH = r"""
import json, os, signal, subprocess, sys, time
timeout_s, kill_mb, out_path, err_path, argv = float(sys.argv[1]), float(sys.argv[2]), sys.argv[3], sys.argv[4], \
    sys.argv[5:]

def rss_mb(pid):
    try:
        with open(f"/proc/{pid}/status", encoding="ascii", errors="replace") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        pass
    return 0.0

with open(out_path, "wb") as out, open(err_path, "wb") as err:
    start = time.perf_counter()
    child = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=out, stderr=err)
    killed = None
    while True:
        pid, status, usage = os.wait4(child.pid, os.WNOHANG)
        if pid:
            break
        if time.perf_counter() - start > timeout_s:
            killed = "hang"
        elif kill_mb and rss_mb(child.pid) > kill_mb:
            killed = "memory"
        if killed:
            os.kill(child.pid, signal.SIGKILL)
            _, status, usage = os.wait4(child.pid, 0)
            break
        time.sleep(0.01)
    seconds = time.perf_counter() - start
    child.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait for it again
print(json.dumps({"exit": None if killed else child.returncode, "killed": killed, "seconds": seconds,
                  "peak_rss_mb": usage.ru_maxrss / 1024.0}))
"""


def facepuppet(*args: str) -> list[str]:
    """The command line of ``facepuppet *args`` in this Python."""
    return [sys.executable, "-m", "facepuppet", *args]


def run_command(argv: list[str], timeout_s: float, kill_mb: float) -> dict:
    """Run ``argv`` under a watcher; its exit code, seconds, peak RSS (MB) and what it said.

    ``killed`` is "hang" or "memory" when the command was stopped at ``timeout_s`` or past ``kill_mb``
    (0: never for memory); ``exit`` is then None.
    """
    env = {k: v for k, v in os.environ.items() if k != "FACEPUPPET_DEBUG"}  # refusals in one line, as users see
    with tempfile.TemporaryDirectory(prefix="bench-gltf-bombs-out-") as tmp:
        out, err = Path(tmp) / "stdout", Path(tmp) / "stderr"
        watch = subprocess.run([sys.executable, "-S", "-c", _WATCH, str(timeout_s), str(kill_mb), str(out),
                                str(err), *argv],
                               capture_output=True, text=True, env=env, check=False)
        if watch.returncode != 0:
            raise RuntimeError(f"the watcher of {argv} failed: {watch.stderr[-400:]}")
        result = json.loads(watch.stdout)
        stdout = out.read_bytes().decode("utf-8", "replace")
        stderr = err.read_bytes().decode("utf-8", "replace")
    lines = [line for line in stderr.splitlines() if line.strip()] or \
        [line for line in stdout.splitlines() if line.strip()]
    return {**result, "message": lines[0][:400] if lines else "",
            "said": [line[:400] for line in (stdout + stderr).splitlines() if line.strip()][:MAX_LINES],
            "traceback": "Traceback (most recent call last)" in stderr}


def judge(result: dict, path: Path, names: str) -> dict:
    """``result`` with ``flags`` (what is wrong) and ``ok``: refused with exit 2, naming ``path`` and (in the
    message or in check-gltf's list) a JSON path matching ``names``, no traceback, within the budget."""
    flags = []
    if result["killed"]:
        flags.append(f"killed ({result['killed']})")
    elif result["exit"] != 2:
        flags.append(f"exit {result['exit']}, not 2")
    if result["traceback"]:
        flags.append("traceback")
    if result["exit"] == 2 and str(path) not in result["message"]:
        flags.append("the message does not name the file")
    if result["exit"] == 2 and not any(re.search(names, line) for line in result["said"]):
        flags.append(f"no line names the JSON path {names!r}")
    if result["peak_rss_mb"] > BUDGET_MB:
        flags.append(f"peak RSS {result['peak_rss_mb']:.0f} MB > {BUDGET_MB:g} MB")
    if result["seconds"] > BUDGET_S:
        flags.append(f"{result['seconds']:.2f} s > {BUDGET_S:g} s")
    return {**result, "flags": flags, "ok": not flags}


def run_case(forge: Callable[[Path], Path], names: str, folder: Path, timeout_s: float, kill_mb: float) -> dict:
    """One forged file through both commands, each judged (``names``: the JSON path its refusal names)."""
    path = forge(folder)
    out = folder / "character.npz"
    size = path.stat().st_size
    result: dict = {"file": path.name, "file_bytes": size}
    for key, argv in (("import_rig", facepuppet("import-rig", str(path), "-o", str(out))),
                      ("check_gltf", facepuppet("check-gltf", str(path)))):
        result[key] = judge(run_command(argv, timeout_s, kill_mb), path, names)
    result["ok"] = result["import_rig"]["ok"] and result["check_gltf"]["ok"]
    return result


def _baseline(folder: Path, timeout_s: float, kill_mb: float) -> dict:
    """Both commands on one sound triangle: their start-up and the least they cost."""
    path = gltf_bombs.sound_triangle(folder)
    return {"import_rig": run_command(facepuppet("import-rig", str(path), "-o", str(folder / "c.npz")), timeout_s,
                                      kill_mb),
            "check_gltf": run_command(facepuppet("check-gltf", str(path)), timeout_s, kill_mb)}


def _line(name: str, command: str, r: dict) -> str:
    said = r["message"].replace("\n", " ")
    state = "ok  " if r.get("ok", True) else "FAIL"
    exit_code = r["killed"] or r["exit"]
    return (f"{name:26s} {command:10s} {state} exit {exit_code!s:6s} {r['seconds']:6.2f} s {r['peak_rss_mb']:7.1f} MB  "
            f"{said[:90]}")


def run_bench(args: argparse.Namespace) -> dict:
    if args.timeout <= 0 or args.kill_mb < 0:
        raise UsageError(f"--timeout {args.timeout:g} must be > 0 and --kill-mb {args.kill_mb:g} >= 0")
    names = args.cases or list(gltf_bombs.FORGERIES)
    results: dict = {"budget": {"peak_rss_mb": BUDGET_MB, "seconds": BUDGET_S}, "timeout_s": args.timeout,
                     "kill_mb": args.kill_mb, "cases": {}}
    with tempfile.TemporaryDirectory(prefix="bench-gltf-bombs-") as tmp:
        results["baseline"] = _baseline(Path(tmp) / "baseline", args.timeout, args.kill_mb)
        for command, r in results["baseline"].items():
            print(_line("baseline (a triangle)", command.replace("_", "-"), r))
        for name in names:
            case = run_case(gltf_bombs.FORGERIES[name], gltf_bombs.REFUSAL_NAMES[name], Path(tmp) / name,
                            args.timeout, args.kill_mb)
            results["cases"][name] = case
            for command in ("import_rig", "check_gltf"):
                line = _line(name, command.replace("_", "-"), case[command])
                flags = case[command]["flags"]
                print(line + (f"\n{'':26s} {'':10s} ^ {'; '.join(flags)}" if flags else ""))
    failing = [name for name, case in results["cases"].items() if not case["ok"]]
    results["failing"] = failing
    results["ok"] = not failing
    print(f"bench gltf-bombs: {len(names) - len(failing)} of {len(names)} cases refused by both commands within "
          f"{BUDGET_MB:g} MB and {BUDGET_S:g} s" + (f"; failing: {', '.join(failing)}" if failing else ""))
    return results


def register_benches(register_bench: Callable[..., None]) -> None:
    """Entry of ``offline/commands.py``: add ``bench gltf-bombs``."""
    register_bench("gltf-bombs", run_bench, "forged hostile glTF files through import-rig and check-gltf: exit "
                   "code, seconds and peak RSS of each refusal against 256 MB and 2 s", _add_arguments)
