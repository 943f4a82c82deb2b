"""``facepuppet bench kpls``: cyclic retarget accuracy of every method, fit/predict times, runtime per frame.

A Live Link Face take drives the ICT head (source); it is retargeted to the
stylised ICT head and the procedural demo head, each once as a linear
blendshape correspondence (the control) and once non-linear
(:mod:`facepuppet.offline.kpls.targets`), and back (:mod:`.cyclic_eval`). The exported runtime stage
(:mod:`facepuppet.runtime.kpls.stage`) is timed per frame on the same take.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.demo.head import build_demo_character
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.kpls.stage import KplsRetarget
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.recording.livelinkface_csv import read_llf_csv

from facepuppet.offline.bench_data import add_data_argument, data_dir
from facepuppet.offline.io.rig_import import import_rig
from facepuppet.offline.kpls.commands import fit_kpls, to_runtime
from facepuppet.offline.kpls.cyclic_eval import (
    bar_plot,
    default_methods,
    evaluate,
    format_table,
    improvements,
    motion_weights,
)
from facepuppet.offline.kpls.pairs import match_matrix
from facepuppet.offline.kpls.targets import ExaggeratedRigTarget, LinearRigTarget, WarpedSourceTarget, stylise


def _add_arguments(parser) -> None:
    add_data_argument(parser)
    parser.add_argument("--take", default="livelinkface_myslate_3.csv", help="tracker CSV under DATA/tracker")
    parser.add_argument("--frames", type=int, default=0, help="use only the first N frames (0: all)")
    parser.add_argument("--mixes", type=int, default=300, help="random mixed pairs per direction")
    parser.add_argument("--plot", type=Path, default=Path("kpls_cyclic.png"), help="bar plot PNG to write")


def real_take_channels(source: Character, targets: dict, frames: list, log: Callable[[str], None]) -> dict:
    """The "real take, source vs retargeted channels" table: ``fit-retarget``'s default fit per target.

    For each target, the take's source channels mapped by name onto the target (what the retarget
    should reproduce) against the exported stage's output, per channel that both characters have
    and that the take moves (source peak >= 0.05): peak ratio and correlation r. Goals: identity
    within 0.02 on the identical character; elsewhere peak within 15 % and r >= 0.95.
    """
    W = motion_weights(frames, source)
    frames = [f for f in frames if f.weights is not None]
    out = {}
    for tname, target in targets.items():
        model, pairs = fit_kpls(source, target, label=f"bench kpls: {tname}")
        stage = to_runtime(model, pairs, source, target)
        M = match_matrix(source.shape_names, target.shape_names)
        want = W @ M.T
        got = np.stack([stage.apply(f) for f in frames]).astype(np.float64)
        channels = {}
        for j in np.flatnonzero(M.any(axis=1) & (want.max(axis=0) >= 0.05)):
            r = float(np.corrcoef(want[:, j], got[:, j])[0, 1]) if got[:, j].std() > 0 else float("nan")
            channels[target.shape_names[j]] = {"source_peak": float(want[:, j].max()),
                                               "peak_ratio": float(got[:, j].max() / want[:, j].max()), "r": r}
        ratios = [c["peak_ratio"] for c in channels.values()]
        rs = [c["r"] for c in channels.values()]
        out[tname] = {"kernel": model.kernel_, "n_components": int(model.n_components_), "n_pairs": len(pairs.X),
                      "max_abs_vs_source": float(np.abs(got - want)[:, M.any(axis=1)].max()),
                      "worst_peak_ratio": max(ratios, key=lambda v: abs(v - 1)), "min_r": min(rs), "channels": channels}
    names = list(dict.fromkeys(n for t in out.values() for n in t["channels"]))
    width = max(16, *(len(t) + 2 for t in out))
    lines = ["real take, source vs retargeted channels (fit-retarget defaults): peak ratio / r per channel",
             f"{'channel':<20}" + "".join(f"{t:>{width}}" for t in out)]
    for n in names:
        cells = [f"{c['peak_ratio']:.3f} / {c['r']:.3f}" if (c := out[t]["channels"].get(n)) else "-" for t in out]
        lines.append(f"{n:<20}" + "".join(f"{c:>{width}}" for c in cells))
    for key, label in (("max_abs_vs_source", "max |retarget - source|"), ("worst_peak_ratio", "worst peak ratio"),
                       ("min_r", "min r")):
        lines.append(f"{label:<20}" + "".join(f"{out[t][key]:>{width}.4f}" for t in out))
    lines.append(f"{'kernel, components':<20}" + "".join(
        f"{out[t]['kernel'] + ', ' + str(out[t]['n_components']):>{width}}" for t in out))
    table = "\n".join(lines)
    log(table)
    return {"targets": out, "table": table}


def _runtime_timing(source, target, frames, log) -> dict:
    model, pairs = fit_kpls(source, target, label="bench kpls: runtime stage")  # fit-retarget's defaults
    stage = to_runtime(model, pairs, source, target)
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        stage = KplsRetarget.load(stage.save(Path(tmp) / "retarget.npz"))
    frames = [f for f in frames if f.weights is not None]
    stage.apply(frames[0])  # builds the channel map once
    times = []
    for _ in range(3):
        for f in frames:
            t0 = time.perf_counter()
            stage.apply(f)
            times.append(time.perf_counter() - t0)
    us = 1e6 * np.asarray(times)
    result = {"kernel": model.kernel_, "n_train": int(len(pairs.X)),
              "n_features": int(pairs.X.shape[1]), "n_target": target.n_shapes,
              "n_components": int(model.n_components_), "per_frame_us_median": float(np.median(us)),
              "per_frame_us_p99": float(np.percentile(us, 99)), "n_calls": len(us)}
    log(f"runtime stage (ICT -> {target.name}, {model.kernel_}, {result['n_train']} training pairs, "
        f"{result['n_features']} features): per frame median {result['per_frame_us_median']:.1f} us, "
        f"p99 {result['per_frame_us_p99']:.1f} us")
    return result


def run_bench(args: argparse.Namespace, log: Callable[[str], None] = print) -> dict:
    data = data_dir(args.data)
    ict_dir = data / "ict-facekit"
    take = data / "tracker" / args.take
    for path in (ict_dir, take):
        if not path.exists():
            raise UsageError(f"bench kpls: {path} not found; pass --data DIR holding ict-facekit/ and tracker/")
    t0 = time.perf_counter()
    ict = import_rig(ict_dir / "generic_neutral_mesh.obj", ict_dir)
    demo = build_demo_character()
    targets = {  # linear controls, then genuinely non-linear correspondences (module retarget_targets)
        "ICT stylised rig (lin)": LinearRigTarget(ict, stylise(ict)),
        "ICT warp+exagg (nonlin)": WarpedSourceTarget(ict),
        "demo head (lin)": LinearRigTarget(ict, demo),
        "demo head exagg (nonlin)": ExaggeratedRigTarget(ict, demo),
    }
    frames = read_llf_csv(take)
    motion = motion_weights(frames, ict)
    if args.frames > 0:
        motion = motion[: args.frames]
    log(f"bench kpls: {take.name}, {len(motion)} frames driving the ICT head; targets: {', '.join(targets)} "
        f"(setup {time.perf_counter() - t0:.1f} s)")
    from threadpoolctl import threadpool_limits

    # one row per (target, method) fit, the spatial Dutreve method included; the rows' lines are results
    with Progress("bench kpls: cyclic error", len(targets) * (len(default_methods()) + 1), unit="fits") as bar:
        def row_done(line: str) -> None:
            if bar.enabled:
                bar.write(line)
            else:
                log(line)
            bar.advance()

        with threadpool_limits(limits=1, user_api="blas"):  # small matrices: threaded BLAS only contends
            rows = evaluate(ict, targets, motion, n_mixes=args.mixes, log=row_done)
    table = format_table(rows, ict.units)
    log(table)
    target_table = format_table(rows, ict.units, key="e_target")
    log(target_table)
    plot = bar_plot(rows, args.plot, ict.units)
    log(f"bar plot: {plot}")
    real_take = real_take_channels(ict, {
        "ICT itself": ict,
        "ICT stylised": stylise(ict, name="ICT stylised"),
        "ICT long jaw": stylise(ict, eye_scale=1.5, jaw_stretch=0.5, taper=-0.15, name="ICT long jaw"),
        "ICT big eyes": stylise(ict, eye_scale=1.8, jaw_stretch=0.1, taper=0.25, name="ICT big eyes"),
        "demo head": demo}, frames, log)
    runtime = _runtime_timing(ict, demo, frames, log)
    return {"real_take_channels": real_take,
            "take": take.name, "n_frames": int(len(motion)), "units": ict.units, "rows": rows,
            "improvement_percent_of_kpls_rbf": improvements(rows),
            "improvement_percent_of_kpls_rbf_e_target": improvements([dict(r, e_d=r["e_target"]) for r in rows]),
            "table": table, "target_table": target_table, "plot": str(plot),
            "runtime_stage": runtime}


def register_benches(register_bench: Callable[..., None]) -> None:
    register_bench("kpls", run_bench, "kernel-PLS retargeting: cyclic error per method, fit/predict "
                   "times, real-take channels of fit-retarget's default fit, runtime stage per frame", _add_arguments)
