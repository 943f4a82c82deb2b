"""``facepuppet bench shin``: Shin & Lee training time, per-frame solve time, linear vs cubic accuracy.

Training: a synthetic take the paper's size (68 markers, 3,500 frames, K = 13)
and the real AnimFace takes. Solve: every frame of a take, warm-started, with
all markers, 5 markers and 1 marker given; median and p99 in ms. Accuracy:
held-out RMS marker error of the linear ICA model and the cubic one.
"""

from __future__ import annotations

import argparse
import time
import warnings
from collections.abc import Callable

import numpy as np

from facepuppet.runtime.actuation.solver import MarkerSolver

from facepuppet.offline.actuation.synthetic_capture import synthetic_capture
from facepuppet.offline.bench_data import add_data_argument, data_dir
from facepuppet.offline.io.capture import read_capture

TAKES = ("animface_jaw.trc", "animface_cheeks.trc")


def _solve_times(actor, markers: np.ndarray, n_given: int | None, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    solver = MarkerSolver(actor)
    movable = np.setdiff1d(np.arange(actor.n_markers), actor.head_markers)
    given = None if n_given is None else rng.choice(movable, size=min(n_given, len(movable)), replace=False)
    obs = markers.astype(np.float64)
    if given is not None:
        keep = np.full(actor.n_markers, False)
        keep[given] = True
        obs = np.where(keep[None, :, None], obs, np.nan)
    times, cpu, iters = np.empty(len(obs)), np.empty(len(obs)), np.empty(len(obs))
    for _ in range(2):                                          # first pass warms caches
        solver.reset()
        for f in range(len(obs)):
            c0, t0 = time.thread_time(), time.perf_counter()
            solver.solve(obs[f])
            times[f], cpu[f] = time.perf_counter() - t0, time.thread_time() - c0
            iters[f] = solver.last_iterations
    ms, cpu_ms = times * 1e3, cpu * 1e3
    # wall time includes waiting for a core on a busy machine; thread CPU time does not
    return {"markers_given": int(actor.n_markers if n_given is None else len(given)),
            "median_ms": float(np.median(ms)), "p99_ms": float(np.percentile(ms, 99)),
            "max_ms": float(ms.max()), "cpu_median_ms": float(np.median(cpu_ms)),
            "cpu_p99_ms": float(np.percentile(cpu_ms, 99)), "mean_iterations": float(iters.mean()),
            "iteration_budget": solver.iterations, "frames": int(len(obs))}


def machine_load() -> dict:
    """The 1-minute load average, the core count and the time of one tiny NumPy operation (µs).

    Solve times are a few dozen such operations, so the last number says how
    busy the machine was while they were measured.
    """
    import os

    x = np.zeros(13)
    c0 = time.thread_time()
    for _ in range(20000):
        x * 2.0
    op_us = (time.thread_time() - c0) / 20000 * 1e6
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return {"loadavg_1min": load, "cores": os.cpu_count(), "numpy_op_us": op_us}


def _train(capture, k: int, **settings) -> tuple[object, dict]:
    # imported here, not at the top: it loads scipy.signal, which every `facepuppet` start would pay
    from facepuppet.offline.actuation.train import train_actor

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        model = train_actor(capture, k=k, **settings)
    m = model.metrics_
    return model, {"frames": m["n_frames"], "markers": m["n_markers"], "k": k, "classes": m["n_classes"],
                   "preprocess_s": m["preprocess_s"], "ica_s": m["ica_s"], "fit_s": m["fit_s"],
                   "train_s": m["train_s"], "holdout_linear_rms": m["holdout"]["linear_rms"],
                   "holdout_cubic_rms": m["holdout"]["cubic_rms"],
                   "holdout_cubic_ridge_rms": m["holdout"]["cubic_ridge_rms"], "ridge_ab": m["holdout"]["ridge_ab"],
                   "units": model.actor_.units}


def run(args: argparse.Namespace) -> dict:
    results: dict = {"solve": {}, "training": {}, "machine_before": machine_load()}
    cap, _ = synthetic_capture(n_frames=3500, n_markers=68, k=13, seed=0)
    model, row = _train(cap, 13, head_markers=["M00", "M01", "M02", "M03"])
    results["training"]["synthetic_68x3500"] = row
    print(f"synthetic 68 markers x 3500 frames, K=13: preprocess {row['preprocess_s']:.2f} s, ICA "
          f"{row['ica_s']:.2f} s, cubic {row['fit_s']:.2f} s = {row['train_s']:.2f} s (goal < 2 s)")
    results["solve"]["synthetic_68x3500"] = [
        _solve_times(model.actor_, model.stabilised_.markers[:args.solve_frames], n) for n in (None, 5, 1)]
    data = data_dir(args.data)
    for take in TAKES:
        path = data / "markers" / take
        if not path.is_file():
            results["training"][take] = {"skipped": f"{path} not found"}
            continue
        capture = read_capture(path)
        model, row = _train(capture, 13)
        results["training"][take] = row
        print(f"{take}: train {row['train_s']:.2f} s (preprocess {row['preprocess_s']:.2f}, ICA {row['ica_s']:.2f}, "
              f"cubic {row['fit_s']:.2f}); held-out RMS linear {row['holdout_linear_rms']:.4f} vs cubic "
              f"{row['holdout_cubic_rms']:.4f}, cubic + a,b ridge {row['ridge_ab']:g} "
              f"{row['holdout_cubic_ridge_rms']:.4f} {row['units']}")
        results["solve"][take] = [_solve_times(model.actor_, model.stabilised_.markers, n) for n in (None, 5, 1)]
    results["machine_after"] = machine_load()
    for name, rows in results["solve"].items():
        for r in rows:
            print(f"solve {name}, {r['markers_given']:>2} markers: median {r['median_ms']:.3f} ms, p99 "
                  f"{r['p99_ms']:.3f} ms, max {r['max_ms']:.3f} ms (CPU median {r['cpu_median_ms']:.3f}, p99 "
                  f"{r['cpu_p99_ms']:.3f} ms), {r['mean_iterations']:.2f} iterations (goal: median < 0.1, p99 < 0.5)")
    for when in ("machine_before", "machine_after"):
        m = results[when]
        print(f"{when}: load average {m['loadavg_1min']:.2f} on {m['cores']} cores, one tiny NumPy op "
              f"{m['numpy_op_us']:.2f} us")
    return results


def _arguments(parser) -> None:
    add_data_argument(parser)
    parser.add_argument("--solve-frames", type=int, default=1500, help="synthetic frames to solve (default 1500)")


def register_benches(register_bench: Callable[..., None]) -> None:
    """Entry point: add the ``shin`` benchmark."""
    register_bench("shin", run, "Shin & Lee: training time (synthetic 68x3500, real takes), solve ms, "
                                "linear vs cubic error", _arguments)
