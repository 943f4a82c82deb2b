"""``facepuppet fit-voice`` (speech + mouth curves -> voice table) and ``voice-curves`` (table + WAV -> CSV).

``fit-voice SPEECH.wav CURVES.csv [SPEECH2.wav CURVES2.csv ...] --map MAP.csv -o voice.npz`` cross-validates
the level baseline, ridge, kernel PLS and blend (ridge with boosted trees; :mod:`facepuppet.offline.voice.fit`),
prints the held-out r of
every channel, and writes the best as a ``voice`` tables file. ``voice-curves voice.npz SPEECH.wav -o
curves.csv`` writes what the table predicts at 30 frames/s (header ``time_s`` + the ARKit names), evaluated
by the runtime's own code, so the curves are what a run would draw.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.files.outputs import write_atomic
from facepuppet.runtime.voice.features import FeatureSpec, features_of
from facepuppet.runtime.voice.table import VoiceTable

from facepuppet.offline.gestures.speech_intensity import read_speech
from facepuppet.offline.voice.calibrate import add_parser as add_calibrate_voice
from facepuppet.offline.voice.fit import CURVE_FPS, MODEL_NAMES, fit_voice, report_lines

DEFAULT_MAP = "facegood_to_arkit.csv"


def speech_pairs(paths: list[Path], mapping: Path | None) -> list[tuple[Path, Path, Path]]:
    """(WAV, curves, map) triples of fit-voice's positional arguments (WAV CSV pairs)."""
    if len(paths) < 2 or len(paths) % 2:
        raise UsageError(f"fit-voice: expected SPEECH.wav CURVES.csv pairs, got {len(paths)} paths")
    out = []
    for wav, curves in zip(paths[::2], paths[1::2]):
        m = mapping if mapping is not None else curves.parent / DEFAULT_MAP
        if not m.is_file():
            raise UsageError(f"fit-voice: no --map given and no {DEFAULT_MAP} beside {curves}")
        out.append((wav, curves, m))
    return out


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "fit-voice",
        help="learn ARKit mouth channels from speech with paired mouth curves -> voice table",
        description="Cross-validate (contiguous folds) the voice-level baseline, ridge regression, kernel "
                    "PLS and blend (the mean of ridge and gradient-boosted trees) from causal log-mel features "
                    "with their history to the mouth channels, print the held-out r per channel and keep the best "
                    "as a voice tables file (run --voice).",
    )
    p.add_argument("paths", type=Path, nargs="+", metavar="SPEECH.wav CURVES.csv",
                   help="speech WAV and its mouth curves CSV (time_s + controls at 30 fps); several pairs allowed")
    p.add_argument("--map", type=Path, help=f"curves -> ARKit sheet (default: {DEFAULT_MAP} beside the curves)")
    p.add_argument("-o", "--output", type=Path, required=True, help="voice table to write (.npz)")
    p.add_argument("--lookahead", type=float, default=0.0, metavar="MS",
                   help="let the features hear MS milliseconds past each mouth frame (default 0: causal); the "
                        "voice's mouth is then that much late at run time")
    p.add_argument("--models", default=",".join(MODEL_NAMES),
                   help=f"models to compare, comma-separated (default {','.join(MODEL_NAMES)})")
    p.add_argument("--folds", type=int, default=5, help="contiguous cross-validation folds (default 5)")
    p.set_defaults(func=fit_voice_command)

    q = subparsers.add_parser(
        "voice-curves",
        help="the ARKit mouth channels a voice table predicts for a WAV, as a 30 fps CSV",
        description="Evaluate a voice table on a WAV with the runtime's code and write the predicted channels "
                    "at 30 frames/s: header time_s and the ARKit names.",
    )
    q.add_argument("table", type=Path, help="voice table (.npz, fit-voice)")
    q.add_argument("wav", type=Path, help="speech WAV")
    q.add_argument("-o", "--output", type=Path, required=True, help="CSV to write")
    q.set_defaults(func=voice_curves_command)
    add_calibrate_voice(subparsers)


def fit_voice_command(args: argparse.Namespace, log: Callable[[str], None] = print) -> int:
    start = time.perf_counter()
    models = tuple(m.strip() for m in args.models.split(",") if m.strip())
    bad = [m for m in models if m not in MODEL_NAMES]
    if bad or not models:
        raise UsageError(f"--models: expected some of {','.join(MODEL_NAMES)}, got {args.models!r}")
    if not 2 <= args.folds <= 20:
        raise UsageError(f"--folds: expected 2..20, got {args.folds}")
    pairs = speech_pairs(list(args.paths), args.map)
    with Progress("fit-voice: cross-validation", len(models) * args.folds, unit="folds") as bar:
        table, report = fit_voice(pairs, lookahead_s=args.lookahead / 1000.0, folds=args.folds, models=models,
                                  progress=lambda note: bar.advance(1, note))
    for line in report_lines(report):
        log(line)
    out = table.save(args.output)
    log(f"{out}: {table.model} model, {len(table.outputs)} channels, {table.spec.n_features} features "
        f"({'causal' if table.lookahead_s == 0 else f'{table.lookahead_s * 1000:g} ms look-ahead'}), "
        f"{out.stat().st_size / 1024:.0f} KiB; {time.perf_counter() - start:.1f} s")
    return 0


def predict_curves(table: VoiceTable, samples: np.ndarray, fps: float = CURVE_FPS) -> tuple[np.ndarray, np.ndarray]:
    """(times (k,), channels (k, n_outputs)) the table gives for samples at its rate, ``fps`` frames a second."""
    spec: FeatureSpec = table.spec
    n = int(len(samples) / spec.sample_rate * fps) + 1
    times = np.arange(n) / fps
    return times, table.predict(features_of(samples, spec, times))


def voice_curves_command(args: argparse.Namespace, log: Callable[[str], None] = print) -> int:
    table = VoiceTable.load(args.table)
    samples = read_speech(args.wav, rate=int(table.spec.sample_rate), stereo="mix")
    times, Y = predict_curves(table, samples)
    lines = ["time_s," + ",".join(table.outputs)]
    lines += [f"{t:.6f}," + ",".join(f"{v:.5f}" for v in row) for t, row in zip(times, Y)]
    write_atomic(args.output, lambda temp: temp.write_text("\n".join(lines) + "\n"))
    log(f"{args.output}: {len(times)} frames at {CURVE_FPS:g} fps, {len(table.outputs)} channels")
    return 0
