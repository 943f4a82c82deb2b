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

from facepuppet.offline.bench_data import add_data_argument, data_dir


def _add_arguments(parser) -> None:
    add_data_argument(parser)
    parser.add_argument("--take", default="livelinkface_myslate_3.csv", help="tracker CSV under DATA/tracker")
    parser.add_argument("--frames", type=int, default=0, help="use only the first N frames (0: all)")
    parser.add_argument("--mixes", type=int, default=300, help="random mixed pairs per direction")
    parser.add_argument("--plot", type=Path, default=Path("kpls_cyclic.png"), help="bar plot PNG to write")


def _runtime_timing(source, target, frames, log) -> dict:
    from facepuppet.runtime.kpls.stage import KplsRetarget

    from facepuppet.offline.kpls.commands import to_runtime
    from facepuppet.offline.kpls.model import KernelPLS
    from facepuppet.offline.kpls.pairs import expression_pairs

    pairs = expression_pairs(source, target)
    model = KernelPLS(kernel="rbf").fit(pairs.X, pairs.Y)
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
    result = {"n_train": int(len(pairs.X)), "n_features": int(pairs.X.shape[1]), "n_target": target.n_shapes,
              "n_components": int(model.n_components_), "per_frame_us_median": float(np.median(us)),
              "per_frame_us_p99": float(np.percentile(us, 99)), "n_calls": len(us)}
    log(f"runtime stage (ICT -> {target.name}, rbf, {result['n_train']} training pairs, "
        f"{result['n_features']} features): per frame median {result['per_frame_us_median']:.1f} us, "
        f"p99 {result['per_frame_us_p99']:.1f} us")
    return result


def run_bench(args: argparse.Namespace, log: Callable[[str], None] = print) -> dict:
    from facepuppet.runtime.demo.head import build_demo_character
    from facepuppet.runtime.recording.livelinkface_csv import read_llf_csv

    from facepuppet.offline.io.rig_import import import_rig
    from facepuppet.offline.kpls.cyclic_eval import bar_plot, evaluate, format_table, improvements, motion_weights
    from facepuppet.offline.kpls.targets import ExaggeratedRigTarget, LinearRigTarget, WarpedSourceTarget, stylise

    data = data_dir(args.data)
    ict_dir = data / "ict-facekit"
    take = data / "tracker" / args.take
    for path in (ict_dir, take):
        if not path.exists():
            raise ValueError(f"bench kpls: {path} not found; pass --data DIR holding ict-facekit/ and tracker/")
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

    with threadpool_limits(limits=1, user_api="blas"):  # small matrices: threaded BLAS only contends
        rows = evaluate(ict, targets, motion, n_mixes=args.mixes, log=log)
    table = format_table(rows, ict.units)
    log(table)
    target_table = format_table(rows, ict.units, key="e_target")
    log(target_table)
    plot = bar_plot(rows, args.plot, ict.units)
    log(f"bar plot: {plot}")
    runtime = _runtime_timing(ict, demo, frames, log)
    return {"take": take.name, "n_frames": int(len(motion)), "units": ict.units, "rows": rows,
            "improvement_percent_of_kpls_rbf": improvements(rows),
            "improvement_percent_of_kpls_rbf_e_target": improvements([dict(r, e_d=r["e_target"]) for r in rows]),
            "table": table, "target_table": target_table, "plot": str(plot),
            "runtime_stage": runtime}


def register_benches(register_bench: Callable[..., None]) -> None:
    register_bench("kpls", run_bench, "kernel-PLS retargeting: cyclic error per method, fit/predict "
                   "times, runtime stage per frame", _add_arguments)
