"""``facepuppet bench video``: what ``--video`` costs per frame, and the frames/s ``replay --video`` reaches.

1. **Encode cost per frame** at ``--size`` (default 1280x720) for each codec of
   :mod:`facepuppet.runtime.live.video_out` (H.264 by default; with ``--alpha``
   also VP9 yuva420p and ProRes 4444 on RGBA frames): the time of one
   :meth:`VideoSink.write` (RGB -> YUV conversion and the encoder call), p50/p99,
   and the end-to-end rate including the final flush. The frames are the demo
   head rendered headless (EGL) over a deterministic performance, so the
   encoder sees real pictures, not noise or flat colour.
2. **replay --video**: a synthetic Live Link Face take (``--seconds`` at 60 rows
   a second, the jaw, blinks and brows moving) replayed headless on the demo
   head at ``--size``, once without and once with ``--video``; ticks / wall
   seconds of each, and the difference per tick.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from facepuppet.runtime.bench.registry import load_average, peak_rss_mb, register_bench
from facepuppet.runtime.bench.render import synthetic_performance
from facepuppet.runtime.cli import main
from facepuppet.runtime.commands.options import parse_size
from facepuppet.runtime.demo.head import build_demo_character
from facepuppet.runtime.live.video_out import VideoSink, plan_video
from facepuppet.runtime.mapping.channels import ARKIT_NAMES, pascal
from facepuppet.runtime.model.geometry import euler_to_quat


def _stats(ms: list[float]) -> dict:
    a = np.asarray(ms)
    return {"p50": float(np.median(a)), "p99": float(np.percentile(a, 99)), "mean": float(a.mean()), "n": len(a)}


def _frames(width: int, height: int, n: int, info: dict) -> list[np.ndarray]:
    """``n`` frames of the demo head, rendered headless at ``width`` x ``height``, (h, w, 3) uint8; the GL
    renderer's name goes into ``info``."""
    from facepuppet.runtime.render.gl_context import create_context
    from facepuppet.runtime.render.renderer import FaceRenderer

    character = build_demo_character()
    weights = synthetic_performance(n, character.n_shapes, n_active=12, fps=30.0)
    target = create_context(headless=True, width=width, height=height)
    info["gl_renderer"] = target.ctx.info.get("GL_RENDERER")
    try:
        renderer = FaceRenderer(target.ctx, character, width, height, path="cpu")
        try:
            out = []
            for k, w in enumerate(weights):
                renderer.draw(w, euler_to_quat(0.3 * np.sin(k / 9), 0.1 * np.sin(k / 7), 0.0))
                renderer.finish()
                out.append(renderer.read_pixels())
            return out
        finally:
            renderer.close()
    finally:
        target.close()


def _encode(frames: list[np.ndarray], n: int, suffix: str, alpha: bool, folder: Path) -> dict:

    h, w = frames[0].shape[:2]
    if alpha:
        ramp = np.linspace(0, 255, w, dtype=np.uint8)[None, :, None].repeat(h, 0)
        frames = [np.concatenate([f, ramp], axis=2) for f in frames]
    plan = plan_video(folder / f"bench{suffix}", w, h, alpha=alpha)
    sink = VideoSink(plan, 30.0)
    times = []
    start = time.perf_counter()
    for k in range(n):
        t0 = time.perf_counter()
        sink.write(k, frames[k % len(frames)])
        times.append((time.perf_counter() - t0) * 1e3)
    t_flush = time.perf_counter()
    sink.close()
    end = time.perf_counter()
    size = (folder / f"bench{suffix}").stat().st_size
    codec = plan.alpha_codec if alpha else plan.codec
    fmt = plan.alpha_pix_fmt if alpha else plan.pix_fmt
    return {"codec": codec, "pix_fmt": fmt, "container": suffix, "frames": n, "write_ms": _stats(times),
            "flush_ms": (end - t_flush) * 1e3, "frames_per_s": n / (end - start),
            "bytes_per_frame": size / n}


def _take(path: Path, seconds: float) -> int:

    idx = {n: i for i, n in enumerate(ARKIT_NAMES)}
    rows = ["Timecode,BlendShapeCount," + ",".join(pascal(n) for n in ARKIT_NAMES)]
    n = int(seconds * 60)
    for i in range(n):
        v = np.zeros(52)
        t = i / 60
        v[idx["jawOpen"]] = 0.5 - 0.5 * np.cos(2 * np.pi * t / 1.3)
        v[idx["eyeBlinkLeft"]] = v[idx["eyeBlinkRight"]] = max(0.0, np.sin(2 * np.pi * t / 2.1)) ** 8
        v[idx["browInnerUp"]] = 0.5 + 0.5 * np.sin(2 * np.pi * t / 1.7)
        v[idx["mouthSmileLeft"]] = 0.5 + 0.5 * np.sin(2 * np.pi * t / 2.9)
        rows.append(f"00:{i // 3600:02d}:{i // 60 % 60:02d}:{i % 60:02d}.000,52," + ",".join(f"{x:.4f}" for x in v))
    path.write_text("\n".join(rows) + "\n")
    return n


def _replay_fps(folder: Path, seconds: float, size: str, codec_suffix: str) -> dict:

    character = folder / "demo_head.npz"
    build_demo_character().save(character)
    take = folder / "take.csv"
    _take(take, seconds)
    out = {}
    for label, extra in (("without_video", []), ("with_video", ["--video", str(folder / f"replay{codec_suffix}")])):
        weights = folder / f"{label}.npy"
        argv = ["replay", str(take), "-c", str(character), "--headless", "--size", size, "--fps", "60",
                "--path", "cpu", "--dump-weights", str(weights), *extra]
        start = time.perf_counter()
        code = main(argv)
        wall = time.perf_counter() - start
        if code != 0:
            raise RuntimeError(f"bench video: replay exited {code}")
        ticks = len(np.load(weights))
        out[label] = {"ticks": ticks, "seconds": wall, "ticks_per_s": ticks / wall}
    out["video_ms_per_tick"] = (out["with_video"]["seconds"] - out["without_video"]["seconds"]) * 1e3 / \
        out["with_video"]["ticks"]
    return out


def bench_video(args: argparse.Namespace) -> dict:
    from facepuppet.runtime.render.blas_threads import BlasThreads

    width, height = parse_size(args.size)
    results: dict = {"size": f"{width}x{height}", "load_average_before": load_average()}
    with tempfile.TemporaryDirectory(prefix="facepuppet-bench-video-") as d, BlasThreads(1):
        folder = Path(d)
        frames = _frames(width, height, min(args.frames, 60), results)
        encodes = [_encode(frames, args.frames, ".mp4", False, folder)]
        if args.alpha:
            encodes.append(_encode(frames, max(args.frames // 4, 10), ".webm", True, folder))
            encodes.append(_encode(frames, max(args.frames // 4, 10), ".mov", True, folder))
        results["encode"] = encodes
        for e in encodes:
            print(f"encode {e['codec']} {e['pix_fmt']} {width}x{height}: write p50 {e['write_ms']['p50']:.1f} ms, "
                  f"p99 {e['write_ms']['p99']:.1f} ms, {e['frames_per_s']:.1f} frames/s with the flush, "
                  f"{e['bytes_per_frame'] / 1024:.1f} KiB/frame")
        if args.seconds > 0:
            replay = _replay_fps(folder, args.seconds, f"{width}x{height}", ".mp4")
            results["replay"] = replay
            print(f"replay {width}x{height}, {replay['with_video']['ticks']} ticks: "
                  f"{replay['without_video']['ticks_per_s']:.1f} ticks/s without --video, "
                  f"{replay['with_video']['ticks_per_s']:.1f} with (+{replay['video_ms_per_tick']:.1f} ms a tick)")
    results["load_average_after"] = load_average()
    results["peak_rss_mb"] = peak_rss_mb()
    return results


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--size", default="1280x720", help="frame size WIDTHxHEIGHT (default 1280x720)")
    parser.add_argument("--frames", type=int, default=120, help="frames encoded per codec (default 120)")
    parser.add_argument("--alpha", action="store_true", help="also time VP9 yuva420p and ProRes 4444 on RGBA frames")
    parser.add_argument("--seconds", type=float, default=3.0,
                        help="seconds of the replayed take (60 ticks a second; 0 skips the replay; default 3)")


register_bench("video", bench_video, "encode cost per frame (--video) and the frames/s of replay --video",
               _add_arguments)
