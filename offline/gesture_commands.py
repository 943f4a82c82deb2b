"""``facepuppet build-gestures`` and ``facepuppet synthesize-gestures`` (Ju & Lee 2008 gesture layer).

``build-gestures`` assembles the reference database (:mod:`.gesture_db`);
``synthesize-gestures`` runs :class:`~facepuppet.runtime.gestures.GestureSynth`
on a WAV frame by frame (the runtime step, with the speaker normalised over the
whole file) and writes a session file that ``facepuppet replay`` plays;
``--pictures DIR`` also draws the intensity with the synthesised tracks under it.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "build-gestures", help="speech + tracker + marker takes -> gesture reference database (.npz)",
        description="Build the Ju & Lee gesture database: lips from a speech take with mouth curves, mood and "
                    "regional gestures from Live Link Face CSVs, head motion from marker takes (C3D).")
    p.add_argument("--speech", nargs=3, type=Path, required=True, metavar=("WAV", "CURVES_CSV", "MAP_CSV"),
                   help="speech WAV, its 30 fps FACEGOOD curves CSV and the FACEGOOD->ARKit mapping CSV")
    p.add_argument("--llf", nargs="*", type=Path, default=[], help="Live Link Face CSV takes")
    p.add_argument("--markers", nargs="*", type=Path, default=[], help="marker takes (C3D)")
    p.add_argument("-o", "--output", type=Path, required=True, help="gesture tables to write (.npz)")
    p.add_argument("--basis", type=int, default=6, help="whole-face expressions in the blend basis (default 6)")
    p.add_argument("--epsilon", type=float, default=0.1, help="bound slack ε: -ε <= c <= 1+ε (default 0.1)")
    p.add_argument("--window", type=int, default=41, help="temporal window of the blend weights, frames (41)")
    p.add_argument("--blend-method", choices=("lsq", "knn"), default="lsq", help="blend weight solver (lsq)")
    p.set_defaults(func=_build)

    s = subparsers.add_parser(
        "synthesize-gestures", help="gesture database + speech WAV -> session file of synthesised gestures",
        description="Synthesise lips, mood, brows, eyes and head motion for a voice (Ju & Lee §5.1) and write "
                    "them as a session file for `facepuppet replay`.")
    s.add_argument("database", type=Path, help="gesture tables (.npz) from build-gestures")
    s.add_argument("speech", type=Path, help="speech WAV (mono; another rate is resampled)")
    s.add_argument("-o", "--output", type=Path, required=True, help="session file to write (.fps)")
    s.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    s.add_argument("--style", default="", help="palette: GROUP=TAKE pairs, e.g. brows=take1,head=take2")
    s.add_argument("--sigma", type=float, default=0.01, help="σ of the candidate draw (default 0.01)")
    s.add_argument("--candidates", type=int, default=3, help="candidates drawn from (default 3)")
    s.add_argument("--history", type=int, default=10, help="history h in frames (default 10)")
    s.add_argument("--stereo", choices=("refuse", "mix"), default="refuse", help="stereo WAV: refuse or mix")
    s.add_argument("--pictures", type=Path, default=None, help="also draw intensity + tracks as PNG here")
    s.add_argument("--overwrite", action="store_true", help="replace an existing session file")
    s.set_defaults(func=_synthesize)


def parse_style(text: str) -> dict[str, str]:
    """{group: take} of ``"brows=take1,head=take2"``; ValueError on a malformed pair."""
    style = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        group, sep, take = part.partition("=")
        if not sep or not group or not take:
            raise ValueError(f"--style: expected GROUP=TAKE pairs separated by commas, got {part!r}")
        style[group.strip()] = take.strip()
    return style


def synthesize(database, speech, seed: int = 0, style=None, sigma: float = 0.01, n_candidates: int = 3,
               history: int = 10, stereo: str = "refuse"):
    """Synthesised tracks for a WAV; returns (synth, level_db (n,), tracks (n, n_out) float32, seconds)."""
    from facepuppet.runtime.gestures import GestureSynth, SpeakerNormaliser, load_gesture_db

    from .speech_intensity import speech_intensity

    db = load_gesture_db(database)
    fps = float(db.settings.get("fps", 30.0))
    level, _, (mean_db, std_db, gate_db) = speech_intensity(speech, fps=fps, stereo=stereo)
    synth = GestureSynth(db, seed=seed, style=style, sigma=sigma, n_candidates=n_candidates, history=history,
                         normaliser=SpeakerNormaliser(mean_db, std_db, gate_db, rate=0.0))
    tracks = np.zeros((len(level), len(synth.out_names)), np.float32)
    start = time.perf_counter()
    for i, v in enumerate(level):
        tracks[i] = synth.step(float(v))
    return synth, level, tracks, time.perf_counter() - start


def _build(args: argparse.Namespace) -> int:
    from .gesture_db import build_gesture_db

    start = time.perf_counter()
    path, takes = build_gesture_db(args.output, tuple(args.speech), args.llf, args.markers, n_basis=args.basis,
                                   epsilon=args.epsilon, window=args.window, method=args.blend_method)
    for t in takes:
        print(f"  take {t.name}: {t.n_frames} frames, groups {', '.join(t.groups)}")
    print(f"{path}: {sum(t.n_frames for t in takes)} frames, {path.stat().st_size / 1e3:.0f} kB, "
          f"{time.perf_counter() - start:.1f} s")
    return 0


def _synthesize(args: argparse.Namespace) -> int:
    from facepuppet.runtime.frames import Frame
    from facepuppet.runtime.gestures import GestureLayer
    from facepuppet.runtime.session import SessionWriter

    synth, level, tracks, seconds = synthesize(args.database, args.speech, args.seed, parse_style(args.style),
                                               args.sigma, args.candidates, args.history, args.stereo)
    fps = float(synth_fps(args.database))
    layer = GestureLayer(synth, fps=fps, mode="voice")
    with SessionWriter(args.output, info={"generator": "synthesize-gestures", "speech": str(args.speech),
                                          "seed": args.seed, "style": args.style}, overwrite=args.overwrite) as w:
        for i, row in enumerate(tracks):
            synth.additions[:] = row
            synth.mood_part[:] = 0.0
            f = layer.compose(None, i / fps)
            w.write_frame(Frame(i / fps, source="gestures", channels=f.channels, weights=f.weights,
                                head_rotation=f.head_rotation, head_translation=f.head_translation,
                                audio_level=float(level[i]), number=i))
    duration = len(level) / fps
    print(f"{args.output}: {len(level)} frames ({duration:.2f} s at {fps:g} fps), synthesis {seconds * 1e3:.1f} ms "
          f"= {duration / max(seconds, 1e-9):.0f}x real time")
    if args.pictures is not None:
        out = plot_tracks(args.pictures / "gestures.png", level, tracks, synth.out_names, fps)
        print(f"wrote {out}")
    return 0


def synth_fps(database) -> float:
    from facepuppet.runtime.gestures import load_gesture_db

    return float(load_gesture_db(database).settings.get("fps", 30.0))


_PLOT_CHANNELS = ("jawOpen", "mouthFunnel", "eyeBlinkLeft", "browInnerUp", "browDownLeft", "headYaw", "headPitch")


def plot_tracks(path, level_db, tracks, names, fps: float, channels=_PLOT_CHANNELS, width: int = 1200):
    """Draw the speech level (dBFS) with the synthesised tracks under it, one lane each, as a PNG (Pillow)."""
    from PIL import Image, ImageDraw

    chans = [c for c in channels if c in names]
    lane, top, left = 70, 20, 110
    img = Image.new("RGB", (width, top + lane * (len(chans) + 1) + 30), "white")
    d = ImageDraw.Draw(img)
    n = len(level_db)
    xs = left + np.arange(n) * (width - left - 10) / max(n - 1, 1)

    def lane_plot(k, y, label, lo, hi, colour):
        y0 = top + k * lane
        d.rectangle([left, y0, width - 10, y0 + lane - 8], outline=(200, 200, 200))
        d.text((5, y0 + lane / 2 - 12), label, fill="black")
        d.text((5, y0 + lane / 2), f"{lo:.2g}..{hi:.2g}", fill=(110, 110, 110))
        v = (np.asarray(y, np.float64) - lo) / max(hi - lo, 1e-9)
        ys = y0 + (lane - 10) * (1.0 - np.clip(v, 0, 1)) + 1
        d.line(list(zip(xs.tolist(), ys.tolist())), fill=colour, width=2)

    lane_plot(0, level_db, "speech dBFS", float(np.min(level_db)), float(np.max(level_db)), (30, 30, 30))
    for k, c in enumerate(chans, 1):
        y = tracks[:, list(names).index(c)]
        lo, hi = float(y.min()), float(y.max())
        lane_plot(k, y, c, lo, hi if hi > lo else lo + 1.0, (40, 90, 200) if not c.startswith("head") else (200, 80, 40))
    y_axis = top + lane * (len(chans) + 1)
    for s in range(0, int(n / fps) + 1):
        x = left + s * fps * (width - left - 10) / max(n - 1, 1)
        d.line([(x, y_axis - 5), (x, y_axis)], fill="black")
        d.text((x - 3, y_axis + 2), f"{s}s", fill="black")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    img.save(path)
    return path
