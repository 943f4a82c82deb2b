"""``facepuppet bench gpu --json OUT.json``: what the draw of a frame costs a real GPU, from its own timer queries.

The design's budget for the draw is under 1 ms on a GPU; on the software rasteriser of the development machines
it is tens of milliseconds, so nothing measured there says whether the budget holds. This bench is the one
command to run when a machine with a GPU is at hand (NVIDIA and EGL: headless, no display needed).

Each case is a character of the data kit (``--data`` or ``$FACEPUPPET_DATA``: the ICT head and Godette, imported
with the project's importers into ``--cache DIR`` or a temporary folder), a size (1280x720 and 3840x2160) and a
deformation path (gpu, cpu), drawn with ``--msaa`` samples (4, as a live run on a GPU draws) over a synthetic
performance, the head turning. Per case:

* ``gpu_frame_ms``: the GPU's time per frame, the sum of its passes' ``GL_TIME_ELAPSED`` queries, and
  ``gpu_passes_ms`` per pass (:class:`~facepuppet.runtime.render.pass_clock.PassClock`, "query" mode: the GPU
  idle at each frame's start, nothing stalled between passes);
* ``draw_finish_ms``: the wall time from issuing the draw to the GPU done (submit, MSAA resolve, ``finish``),
  frames drawn without timer queries, and ``cpu_prepare_ms``, the CPU work before the draw;
* ``picture_matches_unclocked``: one frame drawn with the timer queries around its passes and again without
  them reads back the same pixels (the measured picture is the picture a run shows).

``gl_renderer`` says what drew. On a software rasteriser (llvmpipe, SwiftShader) timer queries do not time the
draw (its work runs on CPU threads when the frame is flushed, not between the queries), so the GPU figures
there are not times: the bench warns, and such a run checks only that the bench works. With several EGL
devices (a GPU beside Mesa's software one), ``--device auto`` takes the first that is not a software
rasteriser.
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.bench.render import head_poses, synthetic_performance
from facepuppet.runtime.commands.options import parse_size
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.render.quality import is_software

from facepuppet.offline.bench_data import add_data_argument, data_dir
from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.rig_import import import_rig

if TYPE_CHECKING:
    import moderngl

    from facepuppet.runtime.render.renderer import FaceRenderer

logger = logging.getLogger(__name__)

#: the design's budget for the GPU time of one frame's draw, ms
BUDGET_MS = 1.0
SIZES = "1280x720,3840x2160"
PATHS = ("gpu", "cpu")
#: EGL devices tried by ``--device auto``
MAX_DEVICES = 8

SOFTWARE_WARNING = ("{renderer} is a software rasteriser: timer queries there do not time the draw (its work "
                    "runs on CPU threads when the frame is flushed, not between the queries), so gpu_frame_ms and "
                    "gpu_passes_ms are not GPU times; this run checks the bench only: run it on a machine with a GPU")


def _import_ict(data: Path) -> Character:
    folder = data / "ict-facekit"
    return import_rig(folder / "generic_neutral_mesh.obj", folder)


def _import_godette(data: Path) -> Character:
    return read_gltf(data / "gltf" / "Godette_vrm_v4.vrm")


#: name -> (the file in the data kit it is imported from, its importer)
CHARACTERS: dict[str, tuple[str, Callable[[Path], Character]]] = {
    "ict": ("ict-facekit/generic_neutral_mesh.obj", _import_ict),
    "godette": ("gltf/Godette_vrm_v4.vrm", _import_godette),
}


def character_file(name: str, data: Path, cache: Path) -> tuple[Path, float | None]:
    """The tables file of character ``name`` in ``cache``: imported from the data kit now (and the seconds it
    took), or None for the seconds where ``cache`` holds it already."""
    out = cache / f"{name}.npz"
    if out.is_file():
        return out, None
    source, importer = CHARACTERS[name]
    if not (data / source).is_file():
        raise UsageError(f"--data {data}: {source} not found (the data kit's {name} character)")
    start = time.perf_counter()
    importer(data).save(out)
    return out, time.perf_counter() - start


def _stats(ms: list[float]) -> dict:
    a = np.asarray(ms, dtype=np.float64)
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99)), "mean": float(a.mean()),
            "min": float(a.min())}


def measure_case(renderer: FaceRenderer, weights: np.ndarray, poses: np.ndarray, warmup: int) -> dict:
    """GPU time per frame and per pass (timer queries), the wall draw + finish (no queries), the CPU prepare,
    and whether the timed picture is the untimed one, of ``renderer`` over ``weights`` and ``poses``."""
    from facepuppet.runtime.render.pass_clock import PassClock

    ctx = renderer.ctx
    n = len(weights)
    for i in range(warmup):
        renderer.prepare(weights[i % n], head_rotation=poses[i % n])
        renderer.submit()
        renderer.resolve()
        renderer.finish()
    prepare, draw = [], []
    for i in range(n):
        t0 = time.perf_counter()
        renderer.prepare(weights[i], head_rotation=poses[i])
        t1 = time.perf_counter()
        renderer.submit()
        renderer.resolve()
        renderer.finish()
        t2 = time.perf_counter()
        prepare.append((t1 - t0) * 1e3)
        draw.append((t2 - t1) * 1e3)
    clock = PassClock(ctx, "query")
    for i in range(n):
        renderer.prepare(weights[i], head_rotation=poses[i])
        clock.start()
        renderer.submit(clock)
        renderer.resolve(clock)
        clock.stop()
    names = list(dict.fromkeys(name for frame in clock.frames for name in frame))
    k = n // 2  # one frame drawn with the queries, then again without: the same pixels
    renderer.advance(0.0)  # both at one time, so spring bones stand where they stood (unadvanced, each frame steps)
    renderer.prepare(weights[k], head_rotation=poses[k])
    clock.start()
    renderer.submit(clock)
    renderer.resolve(clock)
    clock.stop()
    timed = renderer.read_pixels()
    clock.frames.pop()
    renderer.advance(0.0)
    renderer.prepare(weights[k], head_rotation=poses[k])
    renderer.submit()
    untimed = renderer.read_pixels()
    return {
        "frames": n,
        "gpu_frame_ms": _stats([sum(frame.values()) for frame in clock.frames]),
        "gpu_passes_ms": {name: _stats([frame.get(name, 0.0) for frame in clock.frames]) for name in names},
        "draw_finish_ms": _stats(draw),
        "cpu_prepare_ms": _stats(prepare),
        "frames_per_s": n / ((sum(prepare) + sum(draw)) / 1e3),
        "picture_matches_unclocked": bool(np.array_equal(timed, untimed)),
        "gl_error": ctx.error,
    }


def open_context(device: str) -> tuple[moderngl.Context, int]:
    """An EGL context: on ``device`` (an index), or with ``"auto"`` on the first EGL device that is not a
    software rasteriser (the first device when all are). Returns (context, device index)."""
    import moderngl

    from facepuppet.runtime.render.gl_context import EGL_HELP, GLUnavailable

    indices = range(MAX_DEVICES) if device == "auto" else [int(device)]
    first = None
    for index in indices:
        try:
            ctx = moderngl.create_standalone_context(backend="egl", require=330, device_index=index)
        except Exception as exc:
            if first is not None:  # no device past the last one
                break
            raise GLUnavailable(f"no headless EGL OpenGL 3.3 context on EGL device {index} ({exc}); "
                                f"{EGL_HELP}") from None
        if not is_software(ctx.info.get("GL_RENDERER")) or device != "auto":
            if first is not None:
                first[0].release()
            return ctx, index
        if first is None:
            first = (ctx, index)
        else:
            ctx.release()
    return first


def _device(text: str) -> str:
    if text != "auto" and not (text.isdigit() and int(text) < MAX_DEVICES):
        raise argparse.ArgumentTypeError(f"expected auto or an EGL device index 0-{MAX_DEVICES - 1}, got {text!r}")
    return text


def _sizes(text: str) -> list[tuple[int, int]]:
    try:
        sizes = [parse_size(item) for item in text.split(",")]
    except UsageError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT[,WIDTHxHEIGHT...], got {text!r}") from None
    if any(w * h > 8192 * 8192 for w, h in sizes):
        raise argparse.ArgumentTypeError(f"at most 8192x8192 pixels per size, got {text!r}")
    return sizes


def _names(allowed: tuple[str, ...]) -> Callable[[str], list[str]]:
    def parse(text: str) -> list[str]:
        names = [item.strip() for item in text.split(",") if item.strip()]
        wrong = [n for n in names if n not in allowed]
        if not names or wrong:
            raise argparse.ArgumentTypeError(f"expected a comma-separated list of {', '.join(allowed)}, got {text!r}")
        return list(dict.fromkeys(names))
    return parse


def run_bench(args: argparse.Namespace) -> dict:
    from facepuppet.runtime.render.renderer import FaceRenderer

    if args.frames < 2 or args.warmup < 0:
        raise UsageError(f"--frames {args.frames} / --warmup {args.warmup}: at least 2 frames, warmup 0 or more")
    data = data_dir(args.data)
    with tempfile.TemporaryDirectory(prefix="bench-gpu-") as tmp:
        cache = Path(args.cache) if args.cache is not None else Path(tmp)
        if not cache.is_dir():
            raise UsageError(f"--cache {cache}: not a folder")
        characters = {}
        for name in args.characters:
            path, seconds = character_file(name, data, cache)
            characters[name] = (path, Character.load(path), seconds)
        ctx, device = open_context(args.device)
        try:
            renderer_name = ctx.info.get("GL_RENDERER")
            software = is_software(renderer_name)
            results = {
                "gl_renderer": renderer_name, "gl_vendor": ctx.info.get("GL_VENDOR"),
                "gl_version": ctx.info.get("GL_VERSION"), "egl_device": device, "software_rasteriser": software,
                "warning": SOFTWARE_WARNING.format(renderer=renderer_name) if software else None,
                "budget_ms": BUDGET_MS, "msaa_asked": args.msaa, "warmup": args.warmup,
                "characters": {name: {"file": str(path), "n_vertices": c.n_vertices,
                                      "n_triangles": int(len(c.triangles)), "n_shapes": c.n_shapes,
                                      "import_s": seconds}
                               for name, (path, c, seconds) in characters.items()},
                "cases": {},
            }
            print(f"bench gpu: on {renderer_name} (EGL device {device}); the budget is {BUDGET_MS:g} ms of GPU time "
                  "per frame")
            if software:
                logger.warning("bench gpu: WARNING: %s", results["warning"])
            for name, (_, character, _) in characters.items():
                weights = synthetic_performance(args.frames, character.n_shapes, n_active=character.n_shapes)
                poses = head_poses(args.frames)
                for width, height in args.sizes:
                    for path in args.paths:
                        renderer = FaceRenderer(ctx, character, width, height, path=path, msaa=args.msaa,
                                                log=lambda _: None)
                        try:
                            case = {"msaa": renderer.samples, **measure_case(renderer, weights, poses, args.warmup)}
                        finally:
                            renderer.close()
                        median = case["gpu_frame_ms"]["median"]
                        case["within_budget"] = None if software else bool(median < BUDGET_MS)
                        results["cases"].setdefault(name, {}).setdefault(f"{width}x{height}", {})[path] = case
                        _print_case(name, width, height, path, case)
        finally:
            ctx.release()
    return results


def _print_case(name: str, width: int, height: int, path: str, case: dict) -> None:
    g, d = case["gpu_frame_ms"], case["draw_finish_ms"]
    passes = ", ".join(f"{n} {v['median']:.3f}" for n, v in case["gpu_passes_ms"].items())
    print(f"  {name:<8} {width}x{height:<5} {path:<4} MSAA {case['msaa']}x: GPU ms/frame median {g['median']:.3f} "
          f"p99 {g['p99']:.3f} ({passes}); draw+finish median {d['median']:.2f} ms; "
          f"picture {'same' if case['picture_matches_unclocked'] else 'DIFFERS'} with the timer queries")


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    add_data_argument(parser)
    parser.add_argument("--cache", type=Path, default=None,
                        help="folder for the imported characters (ict.npz, godette.npz), reused when there; delete "
                             "them after changing an importer (default: a temporary folder, imported afresh)")
    parser.add_argument("--characters", type=_names(tuple(CHARACTERS)), default=list(CHARACTERS),
                        help="which characters (ict,godette)")
    parser.add_argument("--sizes", type=_sizes, default=_sizes(SIZES), help=f"render sizes ({SIZES})")
    parser.add_argument("--paths", type=_names(PATHS), default=list(PATHS), help="deformation paths (gpu,cpu)")
    parser.add_argument("--frames", type=int, default=240, help="frames timed per case, each way (240)")
    parser.add_argument("--warmup", type=int, default=20, help="frames drawn first per case, not timed (20)")
    parser.add_argument("--msaa", type=int, default=4, help="multisamples (4, as a live run on a GPU draws; 0 = off)")
    parser.add_argument("--device", type=_device, default="auto",
                        help="EGL device index, or auto: the first that is not a software rasteriser (auto)")


def register_benches(register_bench: Callable[..., None]) -> None:
    """Entry of ``offline/commands.py``: add ``bench gpu``."""
    register_bench("gpu", run_bench, "GPU time per frame (timer queries) and wall draw time of the ICT head and "
                   "Godette at 1280x720 and 4K, both deformation paths, on an EGL GPU", _add_arguments,
                   comparable=True)
