"""``facepuppet build-gestures`` and ``facepuppet synthesize-gestures`` (Ju & Lee 2008 gesture layer).

``build-gestures`` assembles the reference database (:mod:`facepuppet.offline.gestures.database`);
``synthesize-gestures`` runs :class:`~facepuppet.runtime.gestures.synth.GestureSynth`
on a WAV frame by frame (the runtime step, with the speaker normalised over the
whole file) and writes a session file that ``facepuppet replay`` plays;
``--pictures DIR`` also draws the intensity with the synthesised tracks under it.
``transfer-detail`` carries the §5.2 detail features of marker takes onto a
character as extra shapes ``detail_<region>_<k>`` (:mod:`.detail_transfer`),
optionally writes a copy of a gesture database with the detail weights per
reference frame (which ``run --gestures`` then drives) and a contact sheet.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.errors import InputFileError, UsageError
from facepuppet.runtime.files.outputs import OutputSet, atomic_path, check_path
from facepuppet.runtime.files.tables import save_tables
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.gestures.layer import GestureLayer
from facepuppet.runtime.gestures.speaker_normaliser import SpeakerNormaliser
from facepuppet.runtime.gestures.synth import GestureSynth
from facepuppet.runtime.gestures.tables import load_gesture_db
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.recording.session import SessionWriter
from facepuppet.runtime.render.images import contact_sheet, save_png

from facepuppet.offline.io.capture import read_capture

if TYPE_CHECKING:  # the command functions import them when they run (scipy.signal, scipy.ndimage)
    from facepuppet.offline.gestures.detail_transfer import DetailTransfer, MarkerDetail


def register(subparsers: argparse._SubParsersAction) -> None:
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
    s.add_argument("--force", "--overwrite", dest="force", action="store_true",
                   help="replace an existing session file / picture (default: refuse, before any work)")
    s.set_defaults(func=_synthesize)

    t = subparsers.add_parser(
        "transfer-detail", help="marker takes + character -> character with §5.2 detail shapes (.npz)",
        description="Ju & Lee §5.2: the residual detail of marker takes (after the blend weights, per region) "
                    "carried onto a character by a compact-support RBF, stored as extra shapes detail_<region>_<k>.")
    t.add_argument("character", type=Path, help="character tables (.npz) that receive the detail shapes")
    t.add_argument("--markers", nargs="+", type=Path, required=True,
                   help="marker takes (C3D or TRC with the AnimFace marker names)")
    t.add_argument("--landmarks", type=Path, required=True,
                   help="JSON with the character's 68 Multi-PIE landmark vertices: a list, or a dict with "
                        "idx_to_landmark_verts (ICT vertex_indices.json)")
    t.add_argument("-o", "--output", type=Path, required=True, help="character to write (.npz)")
    t.add_argument("--per-region", type=int, default=2, help="detail features per region (default 2)")
    t.add_argument("--basis", type=int, default=6, help="whole-face expressions of the blend fit (default 6)")
    t.add_argument("--window", type=int, default=41, help="temporal window of the blend weights, frames (41)")
    t.add_argument("--step", type=int, default=2, help="fit basis and features on every STEP-th frame (2)")
    t.add_argument("--radius", type=float, default=None,
                   help="RBF support radius in character units (default: per region, from the marker spacing)")
    t.add_argument("--gestures", type=Path, default=None,
                   help="gesture tables built with these marker takes: also write a copy holding the detail "
                        "weights per reference frame (--gestures-out), for run --gestures")
    t.add_argument("--gestures-out", type=Path, default=None, help="where the gesture tables copy goes")
    t.add_argument("--pictures", type=Path, default=None, help="also render a contact sheet of the shapes here")
    t.add_argument("--picture-weight", type=float, default=3.0,
                   help="weight of each detail shape in the pictures (a shape is 1 std of its feature; default 3)")
    t.add_argument("--force", "--overwrite", dest="force", action="store_true",
                   help="replace existing output files (default: refuse, before any work)")
    t.set_defaults(func=_transfer_detail)


def parse_style(text: str) -> dict[str, str]:
    """{group: take} of ``"brows=take1,head=take2"``; ValueError on a malformed pair."""
    style = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        group, sep, take = part.partition("=")
        if not sep or not group or not take:
            raise UsageError(f"--style: expected GROUP=TAKE pairs separated by commas, got {part!r}")
        style[group.strip()] = take.strip()
    return style


def synthesize(database: str | os.PathLike, speech: str | os.PathLike, seed: int = 0,
               style: dict[str, str] | None = None, sigma: float = 0.01, n_candidates: int = 3, history: int = 10,
               stereo: str = "refuse") -> tuple[GestureSynth, np.ndarray, np.ndarray, float]:
    """Synthesised tracks for a WAV; returns (synth, level_db (n,), tracks (n, n_out) float32, seconds)."""
    # imported here, not at the top: it loads scipy.signal, which every `facepuppet` start would pay
    from facepuppet.offline.gestures.speech_intensity import speech_intensity

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
    # imported here, not at the top: it loads scipy.signal and .ndimage, which every `facepuppet` start would pay
    from facepuppet.offline.gestures.database import build_gesture_db

    start = time.perf_counter()
    path, takes = build_gesture_db(args.output, tuple(args.speech), args.llf, args.markers, n_basis=args.basis,
                                   epsilon=args.epsilon, window=args.window, method=args.blend_method)
    for t in takes:
        print(f"  take {t.name}: {t.n_frames} frames, groups {', '.join(t.groups)}")
    print(f"{path}: {sum(t.n_frames for t in takes)} frames, {path.stat().st_size / 1e3:.0f} kB, "
          f"{time.perf_counter() - start:.1f} s")
    return 0


def _synthesize(args: argparse.Namespace) -> int:
    synth, level, tracks, seconds = synthesize(args.database, args.speech, args.seed, parse_style(args.style),
                                               args.sigma, args.candidates, args.history, args.stereo)
    fps = float(synth_fps(args.database))
    layer = GestureLayer(synth, fps=fps, mode="voice")
    with atomic_path(args.output) as temp, SessionWriter(
            temp, info={"generator": "synthesize-gestures", "speech": str(args.speech), "seed": args.seed,
                        "style": args.style}, overwrite=True) as w:   # the whole session, or none
        for i, row in enumerate(tracks):
            synth.additions[:] = row
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


def synth_fps(database: str | os.PathLike) -> float:
    return float(load_gesture_db(database).settings.get("fps", 30.0))


_PLOT_CHANNELS = ("jawOpen", "mouthFunnel", "eyeBlinkLeft", "browInnerUp", "browDownLeft", "headYaw", "headPitch")


def plot_tracks(path: str | os.PathLike, level_db: np.ndarray, tracks: np.ndarray, names: Sequence[str], fps: float,
                channels: Sequence[str] = _PLOT_CHANNELS, width: int = 1200) -> Path:
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
        colour = (200, 80, 40) if c.startswith("head") else (40, 90, 200)
        lane_plot(k, y, c, lo, hi if hi > lo else lo + 1.0, colour)
    y_axis = top + lane * (len(chans) + 1)
    for s in range(0, int(n / fps) + 1):
        x = left + s * fps * (width - left - 10) / max(n - 1, 1)
        d.line([(x, y_axis - 5), (x, y_axis)], fill="black")
        d.text((x - 3, y_axis + 2), f"{s}s", fill="black")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as temp:
        img.save(temp, format="PNG")
    return path


def load_landmarks(path: str | os.PathLike) -> np.ndarray:
    """68 landmark vertex indices from JSON: a list, or a dict with ``idx_to_landmark_verts``; (68,) int64."""
    import json

    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise InputFileError(f"{path}: expected a JSON file of 68 landmark vertex indices ({exc})") from None
    if isinstance(data, dict):
        data = data.get("idx_to_landmark_verts")
    if (not isinstance(data, list) or len(data) != 68 or not all(isinstance(v, int) for v in data)
            or not all(-2 ** 63 <= v < 2 ** 63 for v in data)):
        raise InputFileError(f"{path}: expected 68 integer vertex indices (a list, or idx_to_landmark_verts), "
                             f"got {type(data).__name__}{'' if not isinstance(data, list) else f' of {len(data)}'}")
    return np.array(data, np.int64)


def transfer_detail(
    character: Character,
    marker_paths: Sequence[str | os.PathLike],
    landmarks: np.ndarray,
    per_region: int = 2,
    n_basis: int = 6,
    window: int = 41,
    step: int = 2,
    radius: float | dict[str, float] | None = None,
    log: Callable[[str], None] = print,
) -> tuple[Character, MarkerDetail, DetailTransfer, float]:
    """The §5.2 pipeline of :mod:`.detail_transfer` with progress; returns (character, detail, transfer, rate).

    Parameters
    ----------
    character : Character; marker_paths : marker takes (same markers in each); landmarks : (68,) int
    """
    # imported here, not at the top: it loads scipy.ndimage, which every `facepuppet` start would pay
    from facepuppet.offline.gestures.detail_transfer import (
        DetailTransfer,
        detail_character,
        marker_detail,
        place_markers,
    )

    start = time.perf_counter()
    caps = [read_capture(p) for p in marker_paths]
    names = caps[0].names
    for c, p in zip(caps[1:], marker_paths[1:]):
        if c.names != names or abs(c.rate - caps[0].rate) > 1e-9:
            raise InputFileError(f"{p}: expected the markers and rate of {marker_paths[0]} ({len(names)} markers, "
                                 f"{caps[0].rate:g} Hz), got {len(c.names)} markers at {c.rate:g} Hz")
    log(f"[1/4] read {len(caps)} take(s): {sum(len(c.markers) for c in caps)} frames x {len(names)} markers "
        f"at {caps[0].rate:g} Hz ({time.perf_counter() - start:.1f} s)")
    det = marker_detail([c.markers for c in caps], names, per_region=per_region, n_basis=n_basis, window=window,
                        step=step)
    log(f"[2/4] detail features {', '.join(det.feature_names)}; blend fit RMS {det.blend_rms:.3f} "
        f"{caps[0].units} ({time.perf_counter() - start:.1f} s)")
    placement = place_markers(det.neutral, names, character, landmarks)
    tr = DetailTransfer(placement, character, radius=radius)
    log(f"[3/4] markers placed: scale {placement.scale:.3f}, landmark RMS {placement.rms:.3f} (character units); "
        f"radius per region {', '.join(f'{r} {v:.2f}' for r, v in tr.radius.items())} "
        f"({time.perf_counter() - start:.1f} s)")
    out = detail_character(character, tr, det)
    log(f"[4/4] {len(det.feature_names)} detail shapes added ({time.perf_counter() - start:.1f} s)")
    return out, det, tr, caps[0].rate


def render_detail_sheet(character: Character, names: Sequence[str], weight: float = 3.0,
                        cell: tuple[int, int] = (320, 320), columns: int = 0, path: str = "cpu",
                        log: Callable[[str], None] | None = None) -> np.ndarray:
    """Neutral, then each named shape at ``weight``, the skin tinted red by the displacement (common scale).

    The detail is millimetres on a face of centimetres, so the tint shows where each shape acts; the
    label gives its largest displacement at ``weight``. ``path``: the renderer's deformation path.

    Returns
    -------
    sheet : ndarray of shape (h, w, 3), uint8
    """
    import dataclasses
    import math

    from facepuppet.runtime.render.gl_context import create_context  # GL: these import moderngl
    from facepuppet.runtime.render.renderer import FaceRenderer

    dense = character.dense_deltas()
    idx = [list(character.shape_names).index(n) for n in names]
    mags = [np.linalg.norm(dense[i], axis=1) * abs(weight) for i in idx]
    top = max(float(max(m.max() for m in mags)), 1e-9)
    red = np.array([0.85, 0.1, 0.1], np.float32)
    target = create_context(headless=True)
    frames = []
    try:
        for label, shape, mag in [("neutral", None, None)] + list(zip(names, idx, mags)):
            colour = character.vertex_color if mag is None else (
                character.vertex_color + np.clip(mag / top, 0, 1)[:, None] * (red - character.vertex_color))
            r = FaceRenderer(target.ctx, dataclasses.replace(character, vertex_color=colour.astype(np.float32)),
                             cell[0], cell[1], path=path, log=log or (lambda *_: None), framing="face")
            try:
                w = np.zeros(character.n_shapes, np.float32)
                if shape is not None:
                    w[shape] = weight
                r.draw(w)
                text = label if mag is None else f"{label} x{weight:g}: max {mag.max():.2f} {character.units}"
                frames.append((text, r.read_pixels()))
            finally:
                r.close()
    finally:
        target.close()
    columns = columns or max(1, math.ceil(math.sqrt(len(frames))))
    return contact_sheet(frames, columns)


def _transfer_detail(args: argparse.Namespace) -> int:
    # imported here, not at the top: it loads scipy.ndimage, which every `facepuppet` start would pay
    from facepuppet.offline.gestures.detail_transfer import detail_table

    if (args.gestures is None) != (args.gestures_out is None):
        raise UsageError("--gestures and --gestures-out go together (read one database, write its copy)")
    for flag, path in (("--output", args.output), ("--gestures-out", args.gestures_out)):
        if path is not None:       # (cli.main checked already; again for direct callers)
            check_path(flag, "file", Path(path), args.force)
    if args.per_region < 1 or args.step < 1:
        raise UsageError(f"--per-region and --step: expected >= 1, got {args.per_region}, {args.step}")
    if not (args.picture_weight > 0):
        raise UsageError(f"--picture-weight: expected a positive number, got {args.picture_weight}")
    if args.radius is not None and not (args.radius > 0):
        raise UsageError(f"--radius: expected a positive number, got {args.radius}")
    # every input read and checked before the work, and every output written at the end, together
    character = Character.load(args.character)
    landmarks = load_landmarks(args.landmarks)
    db = load_gesture_db(args.gestures) if args.gestures is not None else None
    out, det, tr, rate = transfer_detail(character, args.markers, landmarks, args.per_region,
                                         args.basis, args.window, args.step, args.radius)
    table = detail_table(db, det, [Path(p).stem for p in args.markers], rate=rate) if db is not None else None
    sheet = render_detail_sheet(out, det.feature_names, args.picture_weight) if args.pictures is not None else None
    with OutputSet() as outputs:
        out.save(outputs.path(args.output))
        if db is not None:
            channels = {**db.channels, "detail": list(det.feature_names)}
            save_tables(outputs.path(args.gestures_out), "gesture_db", {**db.arrays, "detail_weights": table},
                        units=db.units, channels=channels, metadata=db.metadata)
    path = Path(args.output)
    dense = out.dense_deltas()[character.n_shapes:]
    print(f"{path}: {out.n_vertices} vertices, {out.n_shapes} shapes ({len(det.feature_names)} detail), "
          f"{path.stat().st_size / 1e6:.1f} MB")
    for name, d in zip(det.feature_names, dense):
        m = np.linalg.norm(d, axis=1)
        print(f"  {name}: {np.count_nonzero(m > 1e-5)} vertices moved, max {m.max():.4f} {out.units} "
              f"at weight 1 (1 std of the feature)")
    if db is not None:
        g = Path(args.gestures_out)
        rows = int(np.count_nonzero(np.abs(table).sum(1) > 0))
        print(f"{g}: gesture tables with detail weights ({rows} of {len(table)} reference frames from the "
              f"marker takes); run --gestures {g} --character {path} drives the detail shapes")
    if args.pictures is not None:
        args.pictures.mkdir(parents=True, exist_ok=True)
        print(f"wrote {save_png(args.pictures / 'detail_shapes.png', sheet)}")
    return 0
