"""``facepuppet bench NAME --json OUT.json [options]``: a registry of benchmarks.

A benchmark is a function ``func(args) -> dict`` (JSON-serialisable results)
registered with :func:`register_bench`, optionally with ``add_arguments(parser)``
for its own options. Runtime benchmarks live in the modules listed in
``_BENCH_MODULES``; other packages register through the ``facepuppet.benches``
entry-point group (each entry point is called with :func:`register_bench`).
Benchmarks are code, not timed tests: they print medians and write JSON. A benchmark registered
``comparable`` (its figures are times and rates, :mod:`~facepuppet.runtime.bench.compare`) takes
``--against BASELINE.json`` too: this run's figures against an earlier run's, in the table printed and in the
JSON (``against``).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import os
import platform
import resource
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path

from facepuppet.runtime.bench import compare
from facepuppet.runtime.files.json_limits import dumps_strict
from facepuppet.runtime.files.outputs import check_path, write_atomic

# Runtime modules that register benchmarks when imported; each must exist and import.
_BENCH_MODULES = ("facepuppet.runtime.bench.render", "facepuppet.runtime.bench.latency",
                  "facepuppet.runtime.bench.soak", "facepuppet.runtime.bench.tables_bombs",
                  "facepuppet.runtime.bench.video")


@dataclass(frozen=True)
class Bench:
    name: str
    func: Callable[[argparse.Namespace], dict]
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None] | None = None
    comparable: bool = False


_REGISTRY: dict[str, Bench] = {}
_LOADED = False


@contextlib.contextmanager
def session_log(shown: bool) -> Iterator[None]:
    """Within the block, the log of the session a benchmark runs (facepuppet's INFO lines: what it loaded,
    where it listens) is shown only when ``shown`` (``--verbose``); warnings always are."""
    ours = logging.getLogger("facepuppet.runtime")
    level = ours.level
    if not shown:
        ours.setLevel(logging.WARNING)
    try:
        yield
    finally:
        ours.setLevel(level)


def register_bench(name: str, func: Callable[[argparse.Namespace], dict], help: str,
                   add_arguments: Callable[[argparse.ArgumentParser], None] | None = None,
                   comparable: bool = False) -> None:
    """Add a benchmark; ``func(args)`` returns a dict written as JSON. ``comparable``: its results are times and
    rates named as :mod:`~facepuppet.runtime.bench.compare` reads them, so it takes ``--against``."""
    if name in _REGISTRY and _REGISTRY[name].func is not func:
        raise ValueError(f"benchmark {name!r} is registered twice")
    _REGISTRY[name] = Bench(name, func, help, add_arguments, comparable)


def benches() -> dict[str, Bench]:
    """Every registered benchmark by name (in name order, whichever module was imported first), loading the
    known modules and entry points once."""
    global _LOADED
    if not _LOADED:
        _LOADED = True
        for module in _BENCH_MODULES:
            importlib.import_module(module)
        for ep in entry_points(group="facepuppet.benches"):
            ep.load()(register_bench)
    return dict(sorted(_REGISTRY.items()))


def machine_info() -> dict:
    """CPU count, platform and Python version of this machine."""
    return {
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "python": sys.version.split()[0],
    }


def load_average() -> str:
    """The 1, 5 and 15-minute load averages, e.g. ``"0.52 0.61 0.70"``; ``"n/a"`` where the OS keeps none."""
    try:
        return " ".join(f"{v:.2f}" for v in os.getloadavg())
    except (AttributeError, OSError):
        return "n/a"


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far, MiB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def bench_parser(bench: Bench) -> argparse.ArgumentParser:
    """The options of one benchmark: ``--json``, ``--force`` and its own; the commands reference lists the same."""
    parser = argparse.ArgumentParser(prog=f"facepuppet bench {bench.name}", description=bench.help)
    parser.add_argument("--json", metavar="OUT.json", help="write the results as JSON here")
    parser.add_argument("--force", action="store_true", help="overwrite an existing --json file")
    if bench.add_arguments:
        bench.add_arguments(parser)
    if bench.comparable:
        compare.add_arguments(parser)
    return parser


def run(args: argparse.Namespace) -> int:
    """Run the named benchmark (or list them). Exit code 0, also when ``--against`` flags figures; 1 only with
    ``--fail-worse`` and a flagged figure; a baseline that cannot be read is refused (exit 2) before the run."""
    registry = benches()
    if not args.name or args.name not in registry:
        lines = [f"  {b.name:<12} {b.help}" for b in registry.values()]
        if args.name:
            print(f"facepuppet bench: no benchmark named {args.name!r}; known:", file=sys.stderr)
            print("\n".join(lines), file=sys.stderr)
            return 2
        print("benchmarks:\n" + "\n".join(lines))
        return 0
    bench = registry[args.name]
    options = bench_parser(bench).parse_args(args.options)
    if options.json:

        check_path("--json", "file", Path(options.json), options.force)   # before the benchmark runs
    against = getattr(options, "against", None)
    baseline = compare.load_baseline(against, bench.name) if against else None  # before the benchmark runs
    started = time.time()
    results = bench.func(options)
    report = {
        "bench": bench.name,
        "started_unix": started,
        "seconds": time.time() - started,
        "machine": machine_info(),
        "results": results,
    }
    comparison = None
    if baseline is not None:
        comparison = compare.compare(baseline, report, options.threshold, baseline_path=str(against))
        report["against"] = comparison.to_json()
        print("\n".join(comparison.lines()))
    if options.json:  # strict JSON: a figure that could not be measured (NaN) is written null
        text = dumps_strict(report, indent=2, sort_keys=True) + "\n"
        write_atomic(options.json, lambda temp: temp.write_text(text))
        print(f"wrote {options.json}")
    if comparison is not None and options.fail_worse and comparison.flagged:
        return 1
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "bench", help="run a benchmark (render, ...) and write its numbers as JSON", add_help=True
    )
    parser.add_argument("name", nargs="?", help="benchmark name; leave out to list them")
    parser.add_argument("options", nargs=argparse.REMAINDER, help="the benchmark's own options (--json OUT.json ...)")
    parser.set_defaults(func=run)
