"""``facepuppet demo``: the embedded demo, needing no data files.

A procedurally generated head (:mod:`facepuppet.runtime.demo.head`) plays a deterministic
synthetic performance (:mod:`facepuppet.runtime.demo.performance`) through the same frame loop
a live session or a replay uses. With a display it opens a window paced to
real time; headless (no display, or ``--headless``) it renders through EGL as
fast as it can, writes the frames and a contact sheet, and in both cases
prints the per-stage timing summary at the end. ``--video FILE`` also encodes every
tick (:mod:`~facepuppet.runtime.live.video_out`), with ``--audio-file WAV`` as its sound.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.commands.options import parse_size
from facepuppet.runtime.live.loop import FrameLoop, RecordedClock, WallClock
from facepuppet.runtime.live.sinks import PngSink
from facepuppet.runtime.live.video_out import VideoSink, add_video_arguments, plan_video_from_args
from facepuppet.runtime.recording.replay_source import ReplaySource
from facepuppet.runtime.render.options import add_render_arguments, render_options

if TYPE_CHECKING:
    import argparse

    from facepuppet.runtime.frames import Frame
    from facepuppet.runtime.protocols import Renderer

SHEET_CELLS = 12


class SheetSink:
    """Keep ``n`` evenly spaced frames of a run of ``n_ticks`` for a contact sheet."""

    def __init__(self, n_ticks: int, n: int = SHEET_CELLS, fps: float = 30.0) -> None:
        self.picks = set(np.linspace(0, max(n_ticks - 1, 0), n).round().astype(int).tolist())
        self.fps = fps
        self.cells: list[tuple[str, np.ndarray]] = []

    def consume(self, tick_index: int, t: float, weights: np.ndarray, frame: Frame | None,
                renderer: Renderer) -> None:
        if tick_index in self.picks:
            self.cells.append((f"t = {t:5.2f} s", renderer.read_pixels().copy()))


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo",
        help="play the embedded demo (procedural head, synthetic performance); needs no data",
        description="Play the embedded demo: a procedurally generated head performing a deterministic "
                    "synthetic take through the frame loop. Headless it writes PNG frames and a contact sheet.",
    )
    p.add_argument("--headless", action="store_true", help="render offscreen through EGL even if a display exists")
    p.add_argument("--out", type=Path, default=None,
                   help="write frames and contact_sheet.png here (default when headless: demo-out)")
    p.add_argument("--size", default="960x540", help="image size WIDTHxHEIGHT (default 960x540)")
    p.add_argument("--fps", type=float, default=30.0, help="ticks per second (default 30)")
    p.add_argument("--duration", type=float, default=12.0, help="seconds of performance (default 12)")
    p.add_argument("--seed", type=int, default=0, help="seed of the synthetic performance (default 0)")
    p.add_argument("--path", choices=("auto", "gpu", "cpu"), default="auto", help="deformation path")
    p.add_argument("--no-frames", action="store_true", help="write only the contact sheet, not every frame")
    add_video_arguments(p, audio_help="with --video, the sound track")
    add_render_arguments(p)
    p.set_defaults(func=run_demo)


def run_demo(args: argparse.Namespace, log: Callable[[str], None] = print) -> int:
    """Run the ``demo`` command from parsed ``args``; returns the exit code."""
    from facepuppet.runtime.demo.head import build_demo_character
    from facepuppet.runtime.demo.performance import demo_frames
    from facepuppet.runtime.render.gl_context import create_context
    from facepuppet.runtime.render.images import contact_sheet, save_png
    from facepuppet.runtime.render.renderer import FaceRenderer

    width, height = parse_size(args.size)
    picture = render_options(args)
    if not (args.fps > 0) or not (args.duration > 0):
        raise ValueError(f"--fps and --duration must be positive, got {args.fps} and {args.duration}")
    if getattr(args, "audio_file", None) is not None and getattr(args, "video", None) is None:
        raise ValueError("--audio-file: in the demo it is the sound track of --video FILE; give --video too")
    video_plan = plan_video_from_args(args, width, height, alpha=picture.transparent)
    started = time.perf_counter()
    character = build_demo_character()
    frames = demo_frames(duration=args.duration, rate=60.0, seed=args.seed)
    log(f"demo: procedural head, {character.n_vertices} vertices, {len(character.triangles)} triangles, "
        f"{character.n_shapes} shapes; performance {args.duration:g} s, {len(frames)} frames "
        f"(seed {args.seed}); built in {time.perf_counter() - started:.2f} s")
    if character.credits:
        log(f"credits: {character.credits}")
    target = create_context(headless=True if args.headless else None, width=width, height=height,
                            title="facepuppet demo", log=log, samples=picture.msaa, transparent=picture.transparent)
    out = args.out if args.out is not None else (Path("demo-out") if target.headless else None)
    if args.out is None and out is not None:   # the default folder follows the output policy too
        from facepuppet.runtime.outputs import check_path

        try:
            check_path("--out (default)", "dir", out, bool(getattr(args, "force", False)))
        except Exception:
            target.close()
            raise
    log(f"demo: {'headless (EGL)' if target.headless else 'window'}, {target.ctx.info['GL_RENDERER']}, "
        f"{width}x{height} at {args.fps:g} fps" + (f", writing to {out}" if out else ""))
    renderer = video = None
    try:
        screen = None if target.headless else target.ctx.screen
        renderer = FaceRenderer(target.ctx, character, width, height, path=args.path, target_fbo=screen, log=log,
                                **picture.renderer_kwargs(), credits=character.credits if picture.credits else None)
        n_ticks = int(np.ceil(args.duration * args.fps - 1e-6)) + 1
        sheet = SheetSink(n_ticks, fps=args.fps)
        sinks = [sheet]
        if out is not None and not args.no_frames:
            sinks.append(PngSink(out))
        progress = None
        if video_plan is not None:
            from facepuppet.runtime.progress import Progress

            progress = Progress(f"demo --video {video_plan.path.name}", total=n_ticks, unit="frames")
            video = VideoSink(video_plan, args.fps, progress=progress)
            log(video_plan.describe(args.fps))
            sinks.append(video)
        clock = RecordedClock() if target.headless else WallClock()
        loop = FrameLoop(character.shape_names, renderer, clock, sinks=sinks, fps=args.fps, log=log, target=target)
        log("stages: demo performance→map→draw")
        result = loop.run(ReplaySource(frames), duration=args.duration)
        if progress is not None:
            progress.close()
        if video is not None:
            video.close()
    except BaseException:
        if video is not None:
            video.abort()
        raise
    finally:
        if renderer is not None:
            renderer.close()
        target.close()
    if out is not None and sheet.cells:
        out.mkdir(parents=True, exist_ok=True)
        cell_w = 320
        cells = [(label, _shrink(rgb, cell_w)) for label, rgb in sheet.cells]
        path = save_png(out / "contact_sheet.png", contact_sheet(cells, columns=4))
        log(f"demo: contact sheet of {len(cells)} moments: {path}")
    c = result.counters
    log(f"demo: {result.n_ticks} ticks, {renderer.path} deformation path; frames received "
        f"{c['frames_received']}, stale dropped {c['stale_dropped']}"
        + (f"; {result.n_ticks} PNG frames in {out}" if out is not None and not args.no_frames else ""))
    if video is not None:
        log(f"demo: {video.frames} video frames ({video.duration:.2f} s) in {video_plan.path}")
    log("per-stage timing (ms):")
    log(result.timer.table())
    log(f"demo: done in {time.perf_counter() - started:.1f} s")
    return 0


def _shrink(rgb: np.ndarray, width: int) -> np.ndarray:
    """Downscale an (h, w, 3) or RGBA (h, w, 4) uint8 image to ``width`` pixels wide (Pillow, high quality)."""
    from PIL import Image

    h, w = rgb.shape[:2]
    if w <= width:
        return rgb
    img = Image.fromarray(rgb).resize((width, round(h * width / w)), Image.LANCZOS)
    return np.asarray(img)
