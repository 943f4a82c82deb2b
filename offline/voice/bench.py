"""``facepuppet bench voice``: held-out r of the voice models on the kit's speech, and the voice stage's cost.

Two evaluations of the FACEGOOD speech pair (5 contiguous folds):

* ``cross_validated``: every fold held out in turn, each model's settings chosen on the other folds;
* ``held_out_take``: settings chosen on folds 1-3 only, scored on folds 4-5, which nothing looked at
  before (the nearest this kit has to "other speech of the same speaker").

Goals (issue): jawOpen r >= 0.75, mouthFunnel r >= 0.6, every channel above the level baseline; the
JSON says per goal whether it is met. Cost: the runtime evaluator per hop (features + model, what the
audio thread does per block of ``hop_s``) and per tick (one copy of the channels), timed on this machine.
Latency (a sound onset in ``--audio-file`` to the weight): by construction of the WAV source the first hop
that holds the onset is evaluated at the first tick after it, so it is at most one hop plus one tick; the
bench measures it on a synthetic onset through :class:`~facepuppet.runtime.voice.source.WavVoice`.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.voice.features import FeatureSpec, VoiceFeatures

from facepuppet.offline.bench_data import add_data_argument, data_dir
from facepuppet.offline.voice.fit import MODEL_NAMES, cross_validate, fit_voice, read_pair, report_lines

GOALS = {"jawOpen": 0.75, "mouthFunnel": 0.6}


def _add_arguments(parser) -> None:
    add_data_argument(parser)
    parser.add_argument("--lookahead", type=float, default=0.0, metavar="MS", help="feature look-ahead (default 0)")


def _goals(r: dict) -> dict:
    base = r["level"]
    out = {f"{c}>={g}": {name: bool(r[name].get(c, -1) >= g) for name in r} for c, g in GOALS.items()}
    out["every_channel_above_level"] = {name: all(r[name][c] > base[c] for c in base) for name in r
                                        if name != "level"}
    return out


def _timing(table, log) -> dict:
    from facepuppet.runtime.voice.source import WavVoice, onset_latency

    spec = table.spec
    rng = np.random.default_rng(0)
    ev = table.evaluator()
    feats = VoiceFeatures(spec)
    block = (0.1 * rng.standard_normal(feats.hop_n)).astype(np.float64)
    for _ in range(50):
        feats.push(block)
    n = 2000
    t0 = time.perf_counter()
    for _ in range(n):
        feats.push(block)
        ev(feats.vector())
    per_hop = (time.perf_counter() - t0) / n * 1000.0
    out = np.zeros(len(table.outputs), np.float32)
    src = ev(feats.vector())
    t0 = time.perf_counter()
    for _ in range(n):
        np.copyto(out, src)
    per_tick = (time.perf_counter() - t0) / n * 1000.0
    lat = onset_latency(table, fps=60.0)
    log(f"voice stage: {per_hop:.3f} ms per hop of {spec.hop_s * 1000:g} ms (features + {table.model}), "
        f"{per_tick:.4f} ms per tick; onset -> weight {lat['latency_ms']:.1f} ms at 60 fps")
    del WavVoice
    return {"per_hop_ms": per_hop, "per_tick_ms": per_tick, "hop_ms": spec.hop_s * 1000.0, "latency": lat,
            "goals": {"per_tick<0.3ms": per_tick < 0.3, "latency<=40ms": lat["latency_ms"] <= 40.0}}


def run_bench(args: argparse.Namespace, log: Callable[[str], None] = print) -> dict:
    data = data_dir(args.data)
    speech = data / "speech"
    pair = (speech / "facegood_1114_3_15.wav", speech / "facegood_1114_3_15_blendshapes.csv",
            speech / "facegood_to_arkit.csv")
    for p in pair:
        if not p.is_file():
            raise UsageError(f"bench voice: {p} not found; pass --data DIR holding speech/")
    t0 = time.perf_counter()
    table, report = fit_voice([pair], lookahead_s=args.lookahead / 1000.0)
    for line in report_lines(report):
        log(line)
    fit_s = time.perf_counter() - t0
    sp = read_pair(*pair, FeatureSpec(), args.lookahead / 1000.0)
    Y = sp.Y[:, [sp.channels.index(c) for c in report["channels"]]]
    held = cross_validate(sp.X, Y, 5, MODEL_NAMES, test_folds=(3, 4))
    held_r = {name: {c: float(r) for c, r in zip(report["channels"], v["r"])} for name, v in held.items()}
    log("held-out take (settings chosen on folds 1-3, scored on folds 4-5):")
    for line in report_lines({**report, "held_out_r": held_r, "mean_r": {n: float(np.nanmean(list(v.values())))
                                                                         for n, v in held_r.items()}})[1:]:
        log(line)
    timing = _timing(table, log)
    return {"channels": report["channels"], "frames": report["frames"], "kept": report["best"],
            "lookahead_ms": args.lookahead, "fit_s": fit_s,
            "cross_validated": {"r": report["held_out_r"], "mean_r": report["mean_r"],
                                "goals": _goals(report["held_out_r"])},
            "held_out_take": {"r": held_r, "goals": _goals(held_r)},
            "cost": timing}


def register_benches(register_bench: Callable[..., None]) -> None:
    register_bench("voice", run_bench, "voice -> mouth: held-out r of the level baseline, ridge and kernel PLS on "
                   "the kit's speech; the voice stage's cost per hop and tick, onset latency", _add_arguments)
