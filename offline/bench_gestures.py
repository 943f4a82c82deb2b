"""``facepuppet bench gestures``: synthesised gestures against the reference and a Perlin-noise baseline.

The database is built from the first 80 % of the speech take (plus the Live
Link Face and marker takes); the last 20 % of its speech is held out and
drives the synthesis. Statistics, synthesised and noise versus reference
(goal: within 20 %): blink rate (eyeBlinkLeft rising through 0.5, per minute),
lag-5-frame autocorrelation per stochastic channel (mean), correlation between
gesture energy (|frame-to-frame change| summed over the stochastic channels)
and speech intensity, and for the lips the correlation of jawOpen with
intensity on the held-out part. Also synthesis speed and database size.
"""

from __future__ import annotations

from .bench_data import add_data_argument, data_dir

import tempfile
import time
from pathlib import Path

import numpy as np



def _add_arguments(parser) -> None:
    add_data_argument(parser)
    parser.add_argument("--seed", type=int, default=0, help="first seed; --seeds consecutive seeds are run")
    parser.add_argument("--seeds", type=int, default=3, help="synthesis runs with consecutive seeds (default 3)")
    parser.add_argument("--minutes", type=float, default=10.0,
                        help="minutes of synthesis (the held-out speech repeated; default 10: a blink rate from "
                             "one minute has ~25 %% Poisson noise)")
    parser.add_argument("--sigma", type=float, default=None, help="σ of the candidate draw (default: the synth's)")
    parser.add_argument("--blend-frames", type=int, default=600, help="frames for the blend-solver comparison")


def blink_rate(blink: np.ndarray, fps: float) -> float:
    up = np.count_nonzero((blink[1:] >= 0.5) & (blink[:-1] < 0.5))
    return 60.0 * up / (len(blink) / fps)


def autocorr(x: np.ndarray, lag: int = 5) -> float:
    vals = []
    for c in x.T:
        c = c - c.mean()
        if c.std() > 1e-6:
            vals.append(float(np.dot(c[:-lag], c[lag:]) / np.dot(c, c)))
    return float(np.mean(vals)) if vals else 0.0


def energy_corr(x: np.ndarray, intensity: np.ndarray) -> float:
    e = np.abs(np.diff(x, axis=0)).sum(1)
    s = intensity[1:]
    return float(np.corrcoef(e, s)[0, 1]) if e.std() > 0 and s.std() > 0 else 0.0


def perlin(n: int, d: int, period: float, rng) -> np.ndarray:
    """1-D gradient (Perlin) noise, (n, d), one lattice point every ``period`` frames."""
    grads = rng.uniform(-1, 1, size=(int(n / period) + 2, d))
    x = np.arange(n) / period
    i = x.astype(int)
    f = (x - i)[:, None]
    fade = f * f * f * (f * (f * 6 - 15) + 10)
    return (1 - fade) * grads[i] * f + fade * grads[i + 1] * (f - 1)


def spikes_per_min(x: np.ndarray, fps: float, jump: float = 0.2) -> float:
    """Single-frame spikes per minute: x(t) above (or below) both neighbours by more than ``jump``."""
    up = np.minimum(x[1:-1] - x[:-2], x[1:-1] - x[2:])
    down = np.minimum(x[:-2] - x[1:-1], x[2:] - x[1:-1])
    return 60.0 * np.count_nonzero((up > jump) | (down > jump)) / (len(x) / fps)


def _stats(x, blink, intensity, fps):
    return {"blink_per_min": blink_rate(blink, fps), "blink_spikes_per_min": spikes_per_min(blink, fps),
            "autocorr_lag5": autocorr(x), "energy_intensity_corr": energy_corr(x, intensity)}


def _ratio(a, ref):
    return {k: (a[k] / ref[k] if abs(ref[k]) > 1e-9 else None) for k in ref}


def _mean(dicts):
    return {k: float(np.mean([d[k] for d in dicts])) for k in dicts[0]}


def _loadavg() -> str:
    try:
        return Path("/proc/loadavg").read_text().strip()
    except OSError:
        return "unknown"


def run_bench(args) -> dict:
    from facepuppet.runtime.gestures import GestureSynth, SpeakerNormaliser, load_gesture_db

    from .blend_weights import BlendWeights, choose_basis
    from .gesture_db import build_gesture_db, read_llf_take
    from .speech_intensity import speech_intensity

    d = data_dir(args.data)
    speech = (d / "speech/facegood_1114_3_15.wav", d / "speech/facegood_1114_3_15_blendshapes.csv",
              d / "speech/facegood_to_arkit.csv")
    llf = [d / "tracker/livelinkface_alex_rom_3.csv", d / "tracker/livelinkface_myslate_3.csv"]
    markers = [d / "markers/animface_jaw.c3d", d / "markers/animface_cheeks.c3d"]
    fps = 30.0
    load_start = _loadavg()
    level, z_all, stats = speech_intensity(speech[0], fps=fps, n_frames=1472)
    cut = int(0.8 * len(level))
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        path, takes = build_gesture_db(Path(tmp) / "g.npz", speech, llf, markers, fps=fps,
                                       speech_frames=slice(0, cut), seed=args.seed)
        build_s = time.perf_counter() - t0
        size = path.stat().st_size
        db = load_gesture_db(path)
    extra = {} if args.sigma is None else {"sigma": args.sigma}
    held = level[cut:]
    reps = max(1, int(np.ceil(args.minutes * 60 * fps / len(held))))
    drive = np.tile(held, reps)   # the held-out speech, repeated
    z_drive = np.tile(z_all[cut:], reps)
    # reference: the stochastic channels of every Live Link Face take in the database (the frames the
    # eyes/brows/rest groups draw from), each take with its (proxy) intensity; stats pooled by frame count
    ref_takes = [read_llf_take(p, z_all[:cut], fps) for p in llf]
    runs, steps, index_s = [], [], []
    for seed in range(args.seed, args.seed + args.seeds):
        t0 = time.perf_counter()
        synth = GestureSynth(db, seed=seed, normaliser=SpeakerNormaliser(*stats, rate=0.0), **extra)
        index_s.append(time.perf_counter() - t0)
        out = np.zeros((len(drive), len(synth.out_names)), np.float32)
        st = np.zeros(len(drive))
        for i, v in enumerate(drive):
            s0 = time.perf_counter()
            out[i] = synth.step(float(v))
            st[i] = time.perf_counter() - s0
        steps.append(st)
        runs.append((out, synth.run_lengths))
    names = list(synth.out_names)
    stoch = [n for n in names if n.startswith(("brow", "eye", "cheek", "nose"))]
    blink = "eyeBlinkLeft"
    per_take = {t.name: _stats(np.column_stack([t.columns[n] for n in stoch]), t.columns[blink], t.intensity, fps)
                for t in ref_takes}
    weights = np.array([t.n_frames for t in ref_takes], np.float64)
    ref = {k: float(np.average([per_take[t.name][k] for t in ref_takes], weights=weights)) for k in
           per_take[ref_takes[0].name]}
    syn_runs = [_stats(out[:, [names.index(n) for n in stoch]], out[:, names.index(blink)], z_drive, fps)
                for out, _ in runs]
    syn = _mean(syn_runs)
    rng = np.random.default_rng(args.seed)
    ref_x = np.vstack([np.column_stack([t.columns[n] for n in stoch]) for t in ref_takes])
    noise = perlin(len(drive), len(stoch), 15.0, rng)
    noise = ref_x.mean(0) + (noise - noise.mean(0)) / np.maximum(noise.std(0), 1e-9) * ref_x.std(0)
    noi = _stats(noise, noise[:, stoch.index(blink)], z_drive, fps)
    jaw_ref = float(np.corrcoef(db["features"][:cut, list(db.channels["features"]).index("jawOpen")],
                                z_all[:cut])[0, 1])
    jaw = [out[:, names.index("jawOpen")] for out, _ in runs]
    silent = drive <= stats[2]
    # blend solvers (§4.1): error and speed on the first frames of the range-of-motion take
    x = np.column_stack([ref_takes[0].columns[n] for n in stoch])[:args.blend_frames]
    basis = choose_basis(x, 6)
    blend = {}
    for method in ("lsq", "knn"):
        t0 = time.perf_counter()
        fit = BlendWeights(basis, method=method).fit(x)
        blend[method] = {"rms_error": fit.error_, "ms_per_frame": 1e3 * (time.perf_counter() - t0) / len(x)}
    all_steps = np.concatenate(steps)
    return {
        "reference": ref, "reference_per_take": per_take, "synthesised": syn,
        "synthesised_per_seed": syn_runs, "perlin_noise": noi,
        "synth_over_reference": _ratio(syn, ref), "noise_over_reference": _ratio(noi, ref),
        "run_length_frames": _mean([r for _, r in runs]),
        "jawopen": {"intensity_corr_reference_train": jaw_ref,
                    "intensity_corr_synthesised_heldout": float(np.mean([np.corrcoef(j, z_drive)[0, 1] for j in jaw])),
                    "mean_in_silence": float(np.mean([j[silent].mean() for j in jaw])) if silent.any() else None,
                    "mean_when_voiced": float(np.mean([j[~silent].mean() for j in jaw])),
                    "silent_frames": int(silent.sum()), "gate_db": stats[2]},
        "speed": {"frames": int(len(all_steps)), "realtime_factor": len(all_steps) / fps / all_steps.sum(),
                  "step_us_median": float(np.median(all_steps) * 1e6),
                  "step_us_p99": float(np.percentile(all_steps, 99) * 1e6),
                  "index_build_s": float(np.median(index_s)), "db_build_s": build_s,
                  "loadavg_start": load_start, "loadavg_end": _loadavg()},
        "database": {"bytes": size, "frames": int(len(db["intensity"])), "takes": list(db.channels["takes"]),
                     "features": len(db.channels["features"]), "continuity_dims": synth.dims},
        "blend_solvers": blend,
        "held_out_speech_s": len(held) / fps, "synthesised_s_per_seed": len(drive) / fps, "seeds": args.seeds,
    }


def register_benches(register_bench) -> None:
    register_bench("gestures", run_bench, "Ju & Lee gestures: synthesised vs reference vs Perlin noise, speed, size",
                   _add_arguments)
