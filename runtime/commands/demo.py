"""``facepuppet demo``: the embedded demo, needing no data files.

A procedurally generated head (:mod:`facepuppet.runtime.demo.head`) plays a deterministic synthetic
performance (:mod:`facepuppet.runtime.demo.performance`) through the same session a live run or a replay
assembles (:func:`~facepuppet.runtime.session.assemble.open_session`). With a display it opens a window
paced to real time; headless (no display, or ``--headless``) it renders through EGL as fast as it can,
writes the frames and a contact sheet, and in both cases prints the per-stage timing summary at the end.
``--video FILE`` also encodes every tick, with ``--audio-file WAV`` as its sound.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image

from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.demo.head import build_demo_character
from facepuppet.runtime.demo.performance import demo_frames
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.files.outputs import check_path
from facepuppet.runtime.live.video_out import add_video_arguments
from facepuppet.runtime.render.gl_context import display_available
from facepuppet.runtime.render.images import contact_sheet, point_box, save_png
from facepuppet.runtime.session.assemble import open_session
from facepuppet.runtime.session.feeds import FramesFeed
from facepuppet.runtime.session.options import OutputOptions, PacingOptions, PictureOptions

if TYPE_CHECKING:
    from facepuppet.runtime.live.loop import TickInfo

SHEET_CELLS = 12
SHEET_ASPECT = 0.6  # width / height of a contact-sheet cell: a head with its neck is taller than wide
DEMO_OUT = Path("demo-out")


class SheetSink:
    """Keep ``n`` evenly spaced frames of a run of ``n_ticks`` for a contact sheet (a tick observer), each
    cropped to the head: the frame is wide and the head tall, so a whole frame as a cell shows the head in
    a quarter of it. The crop is the head's box in the first kept frame (grown by ``margin`` for the head's
    turns and the jaw), the same for every cell so that they compare."""

    def __init__(self, n_ticks: int, n: int = SHEET_CELLS, aspect: float = SHEET_ASPECT,
                 margin: float = 0.1) -> None:
        self.picks = set(np.linspace(0, max(n_ticks - 1, 0), n).round().astype(int).tolist())
        self.cells: list[tuple[str, np.ndarray]] = []
        self.aspect, self.margin = aspect, margin
        self.box: tuple[int, int, int, int] | None = None

    def __call__(self, info: TickInfo) -> None:
        if info.k in self.picks:
            r = info.renderer
            if self.box is None:
                self.box = point_box(r.project(r.character.vertices), r.width, r.height, self.aspect, self.margin)
            left, top, right, bottom = self.box
            self.cells.append((f"t = {info.t:5.2f} s", r.read_pixels()[top:bottom, left:right].copy()))


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo",
        help="play the embedded demo (procedural head, synthetic performance); needs no data",
        description="Play the embedded demo: a procedurally generated head performing a deterministic "
                    "synthetic take through the frame loop. Headless it writes PNG frames and a contact sheet.",
    )
    PictureOptions.add_arguments(p, size="960x540",
                                 headless_help="render offscreen through EGL even if a display exists")
    PacingOptions.add_arguments(p, fps=30.0, fps_help="ticks per second (default 30)", duration=12.0,
                                duration_help="seconds of performance (default 12)")
    p.add_argument("--out", type=Path, default=None,
                   help="write frames and contact_sheet.png here (default when headless: demo-out)")
    p.add_argument("--no-frames", action="store_true", help="write only the contact sheet, not every frame")
    p.add_argument("--seed", type=int, default=0, help="seed of the synthetic performance (default 0)")
    add_video_arguments(p, audio_help="with --video, the sound track")
    p.set_defaults(func=run_demo)


def run_demo(args: argparse.Namespace) -> int:
    """Run the ``demo`` command from parsed ``args``; returns the exit code."""
    picture = PictureOptions.from_args(args)
    pacing = PacingOptions.from_args(args, fps=30.0)
    if pacing.duration is None:
        raise UsageError("--duration: expected a positive number of seconds, got None")
    if args.audio_file is not None and args.video is None:
        raise UsageError("--audio-file: in the demo it is the sound track of --video FILE; give --video too")
    video = OutputOptions.from_args(args, picture).video
    started = time.perf_counter()
    character = build_demo_character()
    frames = demo_frames(duration=pacing.duration, rate=60.0, seed=args.seed)
    print(f"demo: procedural head, {character.n_vertices} vertices, {len(character.triangles)} triangles, "
          f"{character.n_shapes} shapes; performance {pacing.duration:g} s, {len(frames)} frames "
          f"(seed {args.seed}); built in {time.perf_counter() - started:.2f} s")
    out = args.out
    if out is None and (picture.headless or not display_available()):
        out = DEMO_OUT   # the default folder follows the output policy too
        check_path("--out (default)", "dir", out, bool(getattr(args, "force", False)))
    n_ticks = int(np.ceil(pacing.duration * pacing.fps - 1e-6)) + 1
    sheet = SheetSink(n_ticks)
    outputs = OutputOptions(out=None if args.no_frames else out, video=video)
    progress = Progress(f"demo --video {video.path.name}", total=n_ticks, unit="frames") if video else None
    feed = FramesFeed(frames, pacing, label="demo performance", title="facepuppet demo", observers=[sheet])
    with open_session(character, feed, outputs=outputs, picture=picture, progress=progress) as session:
        target = session.target
        print(f"demo: {'headless (EGL)' if target.headless else 'window'}, {target.ctx.info['GL_RENDERER']}, "
              f"{picture.width}x{picture.height} at {pacing.fps:g} fps" + (f", writing to {out}" if out else ""))
        result = session.run()
    if progress is not None:
        progress.close()
    if out is not None and sheet.cells:
        out.mkdir(parents=True, exist_ok=True)
        cell_w = 320
        cells = [(label, _to_width(rgb, cell_w)) for label, rgb in sheet.cells]
        path = save_png(out / "contact_sheet.png", contact_sheet(cells, columns=4))
        print(f"demo: contact sheet of {len(cells)} moments: {path}")
    loop, c = result.loop, result.loop.counters
    print(f"demo: {loop.n_ticks} ticks, {result.path} deformation path; frames received "
          f"{c['frames_received']}, stale dropped {c['stale_dropped']}"
          + (f"; {loop.n_ticks} PNG frames in {out}" if out is not None and not args.no_frames else ""))
    if result.outputs.video is not None:
        sink = result.outputs.video
        print(f"demo: {sink.frames} video frames ({sink.duration:.2f} s) in {video.path}")
    print("per-stage timing (ms):")
    print(loop.timer.table())
    print(f"demo: done in {time.perf_counter() - started:.1f} s")
    return 0


def _to_width(rgb: np.ndarray, width: int) -> np.ndarray:
    """An (h, w, 3) or RGBA (h, w, 4) uint8 image scaled to ``width`` pixels wide (Pillow, high quality): every
    cell of the sheet as wide, whatever the window's size and the head's crop."""
    h, w = rgb.shape[:2]
    if w == width:
        return rgb
    img = Image.fromarray(rgb).resize((width, max(1, round(h * width / w))), Image.LANCZOS)
    return np.asarray(img)
