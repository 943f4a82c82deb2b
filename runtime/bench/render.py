"""``facepuppet bench render``: frames/s and CPU cost per frame of both deformation paths.

Per path (gpu, cpu) and per frame:

* prepare: the CPU work before the draw call (active weight list and uniform
  upload, joint matrices of the head pose, or NumPy deformation, skinning and
  vertex upload),
* submit: issuing the draw calls (CPU; one per material group with parts),
* draw: issuing the draw calls and waiting for them (``ctx.finish()``),
* readback: reading the frame back (what ``--headless --out`` pays; with MSAA
  it includes the resolve).

The weights are a deterministic synthetic performance: sinusoids of
different periods on ~10 channels, the rest at zero; the head turns
(a slow sinusoidal yaw and pitch), so a character with a skeleton is skinned
every frame (``--no-pose`` keeps it still). MSAA as the commands draw
as a live ``run`` draws by default (``--quality auto``: no MSAA on a software rasteriser, 4x on a GPU;
:mod:`~facepuppet.runtime.render.quality`); ``--quality full`` or ``--msaa N`` for another picture.
"""

from __future__ import annotations

import argparse
import os
import time
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.bench.registry import peak_rss_mb, register_bench
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.geometry import euler_to_quat
from facepuppet.runtime.render.quality import QUALITIES, choose_quality

if TYPE_CHECKING:
    from facepuppet.runtime.render.renderer import FaceRenderer


def synthetic_performance(n_frames: int, n_shapes: int, n_active: int = 10, fps: float = 60.0) -> np.ndarray:
    """Weights of shape (n_frames, n_shapes), float32, in [0, 1]: sinusoids on ``n_active`` channels."""
    t = np.arange(n_frames)[:, None] / fps
    channels = np.unique(np.linspace(0, n_shapes - 1, min(n_active, n_shapes)).astype(int))
    periods = 0.7 + 0.37 * np.arange(len(channels))  # seconds, all different
    phases = 0.9 * np.arange(len(channels))
    w = np.zeros((n_frames, n_shapes), dtype=np.float32)
    w[:, channels] = 0.5 + 0.5 * np.sin(2 * np.pi * t / periods + phases)
    return w


def _stats(ms: list[float]) -> dict:
    a = np.asarray(ms)
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99)), "mean": float(a.mean())}


def head_poses(n_frames: int, fps: float = 60.0, degrees: float = 20.0) -> np.ndarray:
    """Quaternions (n_frames, 4) (x, y, z, w): a slow yaw (period 3 s) and pitch (period 4.1 s)."""

    t = np.arange(n_frames) / fps
    yaw = np.radians(degrees) * np.sin(2 * np.pi * t / 3.0)
    pitch = np.radians(degrees / 2) * np.sin(2 * np.pi * t / 4.1)
    return np.array([euler_to_quat(y, p, 0.0) for y, p in zip(yaw, pitch)], np.float64)


def measure_path(renderer: FaceRenderer, weights: np.ndarray, warmup: int = 5,
                 poses: np.ndarray | None = None) -> dict:
    """Time ``renderer`` over the weight sequence (and head poses); per-stage ms statistics and frames/s."""
    prepare, submit, draw, readback, springs = [], [], [], [], []
    pose = (lambda i: None) if poses is None else (lambda i: poses[i % len(poses)])  # noqa: E731
    for i, w in enumerate(weights[:warmup]):
        renderer.draw(w, head_rotation=pose(i))
        renderer.finish()
    start = time.perf_counter()
    for i, w in enumerate(weights):
        t0 = time.perf_counter()
        renderer.prepare(w, head_rotation=pose(i))
        t1 = time.perf_counter()
        renderer.submit()
        ts = time.perf_counter()
        renderer.finish()
        t2 = time.perf_counter()
        renderer.read_pixels()
        t3 = time.perf_counter()
        prepare.append((t1 - t0) * 1e3)
        if getattr(renderer, "spring_ms", None) is not None:  # the spring step's part of prepare
            springs.append(renderer.spring_ms)
        submit.append((ts - t1) * 1e3)
        draw.append((t2 - t1) * 1e3)
        readback.append((t3 - t2) * 1e3)
    total = time.perf_counter() - start
    render_s = (sum(prepare) + sum(draw)) / 1e3
    passes = time_passes(renderer, weights[:max(len(weights) // 2, 1)], poses)
    spring = {"spring_ms": _stats(springs)} if springs else {}
    return {
        "frames": len(weights),
        "frames_per_s": len(weights) / render_s,
        "frames_per_s_with_readback": len(weights) / total,
        "cpu_prepare_ms": _stats(prepare),
        "cpu_submit_ms": _stats(submit),
        "draw_finish_ms": _stats(draw),
        "readback_ms": _stats(readback),
        "passes_ms": passes,
        "peak_rss_mb": peak_rss_mb(),
        **spring,
    }


def time_passes(renderer: FaceRenderer, weights: np.ndarray, poses: np.ndarray | None = None,
                mode: str = "finish") -> dict:
    """Median and p99 ms of each draw pass over the frames (a :class:`PassClock`; "finish" mode stalls
    after every pass, so these frames are timed apart from the unprofiled ones)."""
    from facepuppet.runtime.render.pass_clock import PassClock

    clock = PassClock(renderer.ctx, mode)
    for i, w in enumerate(weights):
        renderer.prepare(w, head_rotation=None if poses is None else poses[i % len(poses)])
        clock.start()
        renderer.submit(clock)
        renderer.resolve(clock)
        clock.stop()
    names = list(dict.fromkeys(n for frame in clock.frames for n in frame))
    out = {name: _stats([frame.get(name, 0.0) for frame in clock.frames]) for name in names}
    out["total"] = _stats([sum(frame.values()) for frame in clock.frames])
    return out


def pass_costs(character_path: str | os.PathLike, width: int, height: int, path: str, msaa: int,
               frames: int = 60, subtle_layers: bool = True) -> dict:
    """ms per draw pass (:func:`time_passes`) of a character at a size, deformation path and samples, every
    shape moving and the head turning: what a live run's picture costs pass by pass, timed apart from the
    run (waiting after each pass would change the run)."""
    from facepuppet.runtime.render.gl_context import create_context
    from facepuppet.runtime.render.renderer import FaceRenderer

    character = Character.load(character_path)
    target = create_context(headless=True)
    try:
        renderer = FaceRenderer(target.ctx, character, width, height, path=path, msaa=msaa, log=lambda _: None,
                                subtle_layers=subtle_layers)
        try:
            weights = synthetic_performance(frames, character.n_shapes, n_active=character.n_shapes)
            return {"path": path, "msaa": renderer.samples, "subtle_layers": renderer.subtle_layers,
                    **time_passes(renderer, weights, head_poses(frames))}
        finally:
            renderer.close()
    finally:
        target.close()


def bench_render(args: argparse.Namespace) -> dict:
    from facepuppet.runtime.render.gl_context import create_context
    from facepuppet.runtime.render.renderer import FaceRenderer

    character = Character.load(args.character)
    weights = synthetic_performance(args.frames, character.n_shapes, n_active=args.active)
    poses = None if getattr(args, "no_pose", False) else head_poses(args.frames)
    asked = getattr(args, "msaa", None)
    target = create_context(headless=True)
    ctx = target.ctx
    quality = choose_quality(asked, getattr(args, "quality", "auto"), ctx.info.get("GL_RENDERER"), live=True)
    msaa, layers = quality.msaa, quality.subtle_layers
    results = {
        "quality": getattr(args, "quality", "auto"),
        "quality_note": quality.note,
        "subtle_layers": layers,
        "character": str(args.character),
        "n_vertices": character.n_vertices,
        "n_triangles": int(len(character.triangles)),
        "n_shapes": character.n_shapes,
        "n_active": min(args.active, character.n_shapes),
        "width": args.width,
        "height": args.height,
        "parts": [p for p in ("skeleton", "look", "expressions") if getattr(character, p) is not None],
        "n_textures": len(character.look.texture_names) if character.look is not None else 0,
        "head_pose": poses is not None,
        "gl_renderer": ctx.info.get("GL_RENDERER"),
        "gl_version": ctx.info.get("GL_VERSION"),
        "paths": {},
    }
    try:
        for path in ("gpu", "cpu"):
            renderer = FaceRenderer(ctx, character, args.width, args.height, path=path, msaa=msaa,
                                    subtle_layers=layers)
            results["msaa"] = renderer.samples
            results["paths"][path] = measure_path(renderer, weights, poses=poses)
            renderer.close()
        reports = []
        renderer = FaceRenderer(ctx, character, args.width, args.height, path="auto", log=reports.append, msaa=msaa,
                                subtle_layers=layers)
        results["auto_choice"] = renderer.path
        results["auto_report"] = renderer.path_report
        renderer.close()
        results["gl_error"] = ctx.error
    finally:
        target.close()
    _print_table(results)
    return results


def _print_table(r: dict) -> None:
    print(
        f"render bench: {r['character']} ({r['n_vertices']} vertices, {r['n_triangles']} triangles, "
        f"{r['n_shapes']} shapes; parts: {', '.join(r['parts']) or 'none'}) at {r['width']}x{r['height']}, "
        f"MSAA {r['msaa']}x, head {'turning' if r['head_pose'] else 'still'}, on {r['gl_renderer']}"
    )
    print(f"{'path':<5} {'fps':>7} {'fps+read':>9} {'cpu med':>8} {'cpu p99':>8} {'sub med':>8} {'draw med':>9} "
          f"{'draw p99':>9} {'read med':>9} {'rss MB':>7}")
    for path, p in r["paths"].items():
        print(
            f"{path:<5} {p['frames_per_s']:7.1f} {p['frames_per_s_with_readback']:9.1f} "
            f"{p['cpu_prepare_ms']['median']:8.3f} {p['cpu_prepare_ms']['p99']:8.3f} "
            f"{p['cpu_submit_ms']['median']:8.3f} "
            f"{p['draw_finish_ms']['median']:9.2f} {p['draw_finish_ms']['p99']:9.2f} "
            f"{p['readback_ms']['median']:9.2f} {p['peak_rss_mb']:7.0f}"
        )
    print(r["auto_report"])


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-c", "--character", required=True, help="character tables file (.npz), e.g. the ICT head")
    parser.add_argument("--frames", type=int, default=120, help="frames per path (120)")
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=720)
    parser.add_argument("--active", type=int, default=10,
                        help="shapes animated at once (10; a live ARKit tracker drives nearly all of them)")
    parser.add_argument("--quality", choices=QUALITIES, default="auto",
                        help="picture quality as run's --quality (auto: what a live run draws on this machine)")
    parser.add_argument("--msaa", type=int, default=None,
                        help="multisamples (default: as --quality decides; 0 = off)")
    parser.add_argument("--no-pose", action="store_true",
                        help="keep the head still (default: it turns, so a skeleton is skinned every frame)")


register_bench(
    "render",
    bench_render,
    "frames/s and CPU ms per frame of the gpu and cpu deformation paths (headless)",
    _add_arguments,
    comparable=True,
)
