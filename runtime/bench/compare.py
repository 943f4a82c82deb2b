"""A benchmark run against a baseline: the ratio of each figure to the baseline's, and the figures that got worse.

A baseline is the JSON a previous ``facepuppet bench NAME --json`` run wrote on the same machine. A change to
the renderer or the frame loop that costs time shows here before it lands, instead of months later in a
latency nobody measured (``--against BASELINE.json``; ``make bench-check`` compares with the previous
commit's build the same way).

What is compared, found by name anywhere under the report's ``results``:

* times, lower is better: a number whose key ends in ``_ms`` or ``_us`` (``cpu_before_draw_p99_ms``,
  ``p50_us``), a statistic (``median``, ``mean``, ``p50``, ``p99``, ...) inside an object whose key ends so
  (``end_to_end_ms.p99``, ``passes_ms.opaque.median``), and each entry of an object named for one
  statistic of times (``cpu_stage_p99_ms.draw_submit``);
* rates, higher is better: a number whose key has ``_per_s`` (``frames_per_s``, ``new_frames_drawn_per_s``).

Not compared: counters (``n``, frames sent, datagrams), memory, a budget (``budget_ms``: a goal, not a
measure), and a maximum (``max``, ``max_ms``: the worst single sample, which one stall of the machine
decides). Configuration (size, samples, path, character, the GL renderer, the machine) is not a figure either,
but where it differs the runs measured different things, and that is said first. A figure is "worse by" the
fraction of the baseline it lost: a time 1.3 x the baseline's is 30 % worse, a rate 0.7 x the baseline's
is 30 % worse too.
"""

from __future__ import annotations

import argparse
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.files.input_files import regular_file

#: a figure more than this fraction worse than the baseline's is flagged
THRESHOLD = 0.20
#: a baseline larger than this is not a benchmark's JSON (ours are tens of KiB)
MAX_BASELINE_BYTES = 16 * 2**20

_TIME_SUFFIXES = ("_ms", "_us")
_STATISTICS = frozenset({"median", "mean", "min", "p50", "p90", "p95", "p99"})
_NOT_FIGURES = re.compile(r"^(n|max|budget)(_ms|_us)?$")
_STATISTIC_OF_TIMES = re.compile(r"(^|_)(p\d+|median|mean)_(ms|us)$")
_RATE = re.compile(r"_per_s(_|$)")
_NAMES_SHOWN = 6  # figures named in the printed list of those only one run has

#: keys whose values say what was measured (where they differ, the runs are not alike)
CONFIGURATION = frozenset({
    "character", "size", "width", "height", "msaa", "path", "render_path", "auto_choice", "gl_renderer",
    "input", "draw", "fps", "rate_hz", "seconds", "frames", "receiver", "head_pose", "n_active", "n_vertices",
    "n_triangles", "n_shapes",
})


def direction(keys: tuple[str, ...]) -> str | None:
    """``"lower"`` (a time), ``"higher"`` (a rate) or None (not compared) for the number at ``keys``
    (its path of object keys under ``results``)."""
    leaf = keys[-1]
    if _NOT_FIGURES.match(leaf):
        return None
    if _RATE.search(leaf):
        return "higher"
    if leaf.endswith(_TIME_SUFFIXES):
        return "lower"
    if leaf in _STATISTICS and any(k.endswith(_TIME_SUFFIXES) for k in keys[:-1]):
        return "lower"
    if len(keys) > 1 and _STATISTIC_OF_TIMES.search(keys[-2]):
        return "lower"
    return None


def _leaves(tree: Any, keys: tuple[str, ...] = ()):
    """(keys, value) of every leaf of nested objects (lists are series, not figures: left out)."""
    if isinstance(tree, dict):
        for k, v in tree.items():
            yield from _leaves(v, (*keys, str(k)))
    elif not isinstance(tree, list):
        yield keys, tree


def figures(results: dict) -> dict[str, tuple[float, str]]:
    """Dotted name -> (value, ``"lower"`` or ``"higher"``) of every figure of a report's ``results``."""
    found = {}
    for keys, value in _leaves(results):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            continue
        better = direction(keys)
        if better is not None:
            found[".".join(keys)] = (float(value), better)
    return found


def configuration(report: dict) -> dict[str, Any]:
    """Dotted name -> value of what a report says it measured: the machine, and each :data:`CONFIGURATION`
    key under ``results`` (a character by its file name: two builds may each import their own copy)."""
    found = {f"machine.{k}": v for k, v in (report.get("machine") or {}).items()}
    for keys, value in _leaves(report.get("results") or {}):
        if keys[-1] in CONFIGURATION:
            found[".".join(keys)] = Path(value).name if keys[-1] == "character" and isinstance(value, str) \
                else value
    return found


@dataclass(frozen=True)
class Figure:
    """One figure in both runs.

    Attributes
    ----------
    name : str, dotted keys under ``results``
    baseline, this_run : float
    better : "lower" or "higher"
    """

    name: str
    baseline: float
    this_run: float
    better: str

    @property
    def ratio(self) -> float | None:
        """this run / baseline; None where the baseline is not positive (no ratio to speak of)."""
        return self.this_run / self.baseline if self.baseline > 0 else None

    @property
    def worse_by(self) -> float | None:
        """The fraction of the baseline lost (0.3: 30 % worse; negative: better); None without a ratio."""
        ratio = self.ratio
        if ratio is None:
            return None
        return ratio - 1.0 if self.better == "lower" else 1.0 - ratio


@dataclass(frozen=True)
class Comparison:
    """A run against a baseline: what differs in configuration, and every figure both have.

    Attributes
    ----------
    baseline_path : str
    threshold : float, fraction; a figure worse by more is flagged
    differs : list of (name, baseline value, this run's value), configuration that differs
    figures : list of Figure, in the report's order
    only_baseline, only_this_run : list of str, figures one run has and the other lacks
    """

    baseline_path: str
    threshold: float
    differs: list[tuple[str, Any, Any]]
    figures: list[Figure]
    only_baseline: list[str]
    only_this_run: list[str]

    def is_flagged(self, figure: Figure) -> bool:
        worse = figure.worse_by
        return worse is not None and worse > self.threshold + 1e-12  # 1.2 x in floating point is not "more"

    @property
    def flagged(self) -> list[Figure]:
        """The figures more than :attr:`threshold` worse than the baseline's."""
        return [f for f in self.figures if self.is_flagged(f)]

    def to_json(self) -> dict:
        """What a script reads: ``flagged`` (names), and each figure with its ratio and flag."""
        return {
            "baseline": self.baseline_path,
            "threshold": self.threshold,
            "configuration_differs": [{"name": n, "baseline": b, "this_run": t} for n, b, t in self.differs],
            "figures": [{"name": f.name, "baseline": f.baseline, "this_run": f.this_run, "better": f.better,
                         "ratio": f.ratio, "worse_by": f.worse_by, "flagged": self.is_flagged(f)}
                        for f in self.figures],
            "flagged": [f.name for f in self.flagged],
            "only_in_baseline": self.only_baseline,
            "only_in_this_run": self.only_this_run,
        }

    def lines(self) -> list[str]:
        """The printed comparison: configuration that differs, the table, then the flagged figures."""
        out = [f"against {self.baseline_path}:"]
        for name, base, this in self.differs:
            out.append(f"  NOT ALIKE: {name} is {this!r} here, {base!r} in the baseline")
        width = max([len("figure")] + [len(f.name) for f in self.figures])
        if self.figures:
            out.append(f"  {'figure':<{width}} {'baseline':>10} {'this run':>10} {'ratio':>7}  change")
        else:
            out.append("  no figure in common with the baseline (another size, path or character?)")
        for f in self.figures:
            ratio, worse = f.ratio, f.worse_by
            change = "n/a" if worse is None else "same" if abs(worse) < 0.0005 else \
                f"{abs(worse) * 100:.1f} % {'worse' if worse > 0 else 'better'}"
            mark = "  << FLAGGED" if self.is_flagged(f) else ""
            out.append(f"  {f.name:<{width}} {f.baseline:>10.4g} {f.this_run:>10.4g} "
                       f"{'n/a' if ratio is None else f'{ratio:.3f}':>7}  {change}{mark}")
        for label, names in (("only in the baseline", self.only_baseline), ("only in this run", self.only_this_run)):
            if names:
                more = len(names) - _NAMES_SHOWN
                shown = ", ".join(names[:_NAMES_SHOWN]) + (f" and {more} more (the JSON lists them)" if more > 0
                                                           else "")
                out.append(f"  {label}, not compared: {len(names)} figures: {shown}")
        flagged = self.flagged
        limit = f"{self.threshold * 100:g} %"
        if flagged:
            out.append(f"  {len(flagged)} of {len(self.figures)} figures more than {limit} worse: "
                       + ", ".join(f"{f.name} ({f.worse_by * 100:+.0f} %)" for f in flagged))
        else:
            out.append(f"  none of {len(self.figures)} figures more than {limit} worse")
        return out


def compare(baseline: dict, report: dict, threshold: float = THRESHOLD, baseline_path: str = "") -> Comparison:
    """``report`` (this run, as the registry writes it) against ``baseline`` (an earlier one, read back)."""
    base, this = figures(baseline.get("results") or {}), figures(report.get("results") or {})
    base_config, this_config = configuration(baseline), configuration(report)
    differs = [(name, base_config.get(name), value) for name, value in this_config.items()
               if name in base_config and base_config[name] != value]
    return Comparison(
        baseline_path=baseline_path,
        threshold=float(threshold),
        differs=differs,
        figures=[Figure(name, base[name][0], value, better) for name, (value, better) in this.items() if name in base],
        only_baseline=[name for name in base if name not in this],
        only_this_run=[name for name in this if name not in base],
    )


def load_baseline(path: str | Path, bench: str) -> dict:
    """The report a ``bench BENCH --json`` run wrote at ``path``, checked to be one.

    Raises
    ------
    FileNotFoundError
        nothing at ``path`` (the message names it)
    InputFileError
        not a regular file, too large, not JSON, not a report of ``bench``: the message names the file and field
    """
    path = regular_file(path, "baseline (a bench --json file)")
    size = path.stat().st_size
    if size > MAX_BASELINE_BYTES:
        raise InputFileError(f"{path}: a baseline of {size} bytes; a bench's JSON is far smaller "
                             f"(at most {MAX_BASELINE_BYTES} bytes read)")
    try:
        report = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputFileError(f"{path}: not a bench's JSON ({exc})") from None
    if not isinstance(report, dict):
        raise InputFileError(f"{path}: expected a JSON object (a bench --json report), found {type(report).__name__}")
    if report.get("bench") != bench:
        raise InputFileError(f"{path}: bench: expected {bench!r} (a baseline of the same benchmark), "
                             f"found {report.get('bench')!r}")
    if not isinstance(report.get("results"), dict):
        raise InputFileError(f"{path}: results: expected an object of figures, found "
                             f"{type(report.get('results')).__name__}")
    return report


def threshold_percent(text: str) -> float:
    """``--threshold PCT`` as a fraction (argparse ``type=``): a percentage above 0."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"expected a percentage above 0, got {text!r}")
    return value / 100.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``--against``, ``--threshold`` and ``--fail-worse`` of a benchmark whose figures compare."""
    parser.add_argument("--against", metavar="BASELINE.json",
                        help="compare with a run of this benchmark that --json wrote earlier on this machine: the "
                             "ratio per figure, and those more than --threshold worse flagged (also in the JSON)")
    parser.add_argument("--threshold", metavar="PCT", type=threshold_percent, default=THRESHOLD,
                        help=f"with --against: flag a figure worse than the baseline's by more than this "
                             f"({THRESHOLD * 100:g} %%)")
    parser.add_argument("--fail-worse", action="store_true",
                        help="with --against: exit 1 when a figure is flagged (default: exit 0 either way; "
                             "benchmarks inform)")
