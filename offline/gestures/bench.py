"""``facepuppet bench gestures``: synthesised gestures against the reference and a Perlin-noise baseline.

What is compared with what
--------------------------
The database is built from the first 80 % of the speech take plus the Live
Link Face and marker takes; the last 20 % of the speech (9.8 s) is held out
and, repeated, drives ``--seeds`` syntheses of ``--minutes`` each.

*Reference* for the stochastic channels (brows, eyes, rest: what the groups
the blink and gesture statistics are measured on draw from) is the motion the
synthesis imitates: the Live Link Face takes of the database, whole, pooled by
frame count. It is **not held out**: the kit has no second take of these
performers (one 134 s range-of-motion take, one 5 s take), so these figures
say whether the synthesis keeps the statistics of its own source material, not
whether it generalises. The FACEGOOD curves have no eye or brow motion and the
marker takes give only the head, so neither has blinks. Only the speech is
held out; the reference takes have no audio, their intensity is the proxy of
:mod:`facepuppet.offline.gestures.database` (the take's jawOpen).

Statistics (per minute of animation; synthesised: mean and spread over seeds):

* ``blink_per_min``: eyeBlinkLeft rising through 0.5 (every crossing);
  ``blink_hysteresis_per_min``: the same, re-armed only once the lid is back
  below 0.25 (a signal hovering at 0.5 is one blink, not several);
  ``blink_short_per_min``: closures (>= 0.5) lasting at most 10 frames (a
  blink, not a held eye closure of the range-of-motion take).
* ``autocorr_lag5``: lag-5-frame autocorrelation per stochastic channel (mean).
* ``energy_intensity_corr``: correlation of gesture energy (|frame-to-frame
  change| summed over the stochastic channels) with speech intensity.

Goals (``goals`` in the JSON): rates and autocorrelation are judged by the
ratio synthesised / reference within 0.8-1.2, on the seed mean (the spread is
reported next to it, and the reference's own block-bootstrap interval: a
reference of 43 blinks is itself uncertain by about +-15 %). The reference
energy correlation is about 0, so a ratio to it means nothing; it is judged
by the difference of correlations dr = r_syn - r_ref with a 95 % interval
(reference block bootstrap combined with the seeds): met when the interval
contains 0. The same for a Perlin-noise baseline of equal mean and std.
Also synthesis speed, database size, the blend solvers (§4.1) and the jaw.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from facepuppet.runtime.bench.registry import load_average
from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.gestures.speaker_normaliser import SpeakerNormaliser
from facepuppet.runtime.gestures.synth import GestureSynth
from facepuppet.runtime.gestures.tables import load_gesture_db

from facepuppet.offline.bench_data import add_data_argument, data_dir

BLOCK_FRAMES = 60      # block length of the reference bootstrap (2 s at 30 fps)
N_BOOT = 1000
SHORT_BLINK_FRAMES = 10


def _add_arguments(parser) -> None:
    add_data_argument(parser)
    parser.add_argument("--seed", type=int, default=0, help="first seed; --seeds consecutive seeds are run")
    parser.add_argument("--seeds", type=int, default=8, help="synthesis runs with consecutive seeds (default 8)")
    parser.add_argument("--minutes", type=float, default=10.0,
                        help="minutes of synthesis per seed (the held-out speech repeated; default 10: a blink "
                             "rate from one minute has ~25 %% Poisson noise)")
    parser.add_argument("--sigma", type=float, default=None, help="σ of the candidate draw (default: the synth's)")
    parser.add_argument("--recent", type=int, default=None,
                        help="frames a shown reference frame is barred (default: the synth's; 0: off, the "
                             "behaviour before the loop fix)")
    parser.add_argument("--whole", default=None,
                        help="comma-separated groups shown whole (own residual + own frame's mood c·B; default: "
                             "the synth's, eyes); 'none': the mood pick's c·B summed into every channel, the "
                             "behaviour before the one-moment blink fix")
    parser.add_argument("--blend-frames", type=int, default=600, help="frames for the blend-solver comparison")


def blink_onsets(blink: np.ndarray) -> np.ndarray:
    """Frames where ``blink`` rises through 0.5 (every crossing), int64."""
    return np.flatnonzero((blink[1:] >= 0.5) & (blink[:-1] < 0.5)) + 1


def blink_onsets_hysteresis(blink: np.ndarray, high: float = 0.5, low: float = 0.25) -> np.ndarray:
    """Frames where ``blink`` reaches ``high``, counted once and re-armed only after falling below ``low``.

    A signal that starts at or above ``high`` starts closed (not counted).
    """
    state = np.full(len(blink), np.nan)
    state[blink >= high], state[blink < low] = 1.0, 0.0
    idx = np.where(np.isnan(state), 0, np.arange(len(blink)))
    held = state[np.maximum.accumulate(idx)]          # last decided state (forward fill)
    held = np.where(np.isnan(held), 0.0, held)       # before the first decision: open
    return np.flatnonzero(np.diff(held) > 0) + 1


def short_blink_onsets(blink: np.ndarray, max_frames: int = SHORT_BLINK_FRAMES) -> np.ndarray:
    """Start frames of closures (``blink`` >= 0.5) lasting at most ``max_frames`` frames, int64."""
    edges = np.diff(np.r_[0, (blink >= 0.5).astype(np.int8), 0])
    start, end = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return start[end - start <= max_frames]


BLINK_KINDS = {"blink_per_min": blink_onsets, "blink_hysteresis_per_min": blink_onsets_hysteresis,
               "blink_short_per_min": short_blink_onsets}


def autocorr(x: np.ndarray, lag: int = 5) -> float:
    vals = []
    for c in x.T:
        c = c - c.mean()
        if c.std() > 1e-6:
            vals.append(float(np.dot(c[:-lag], c[lag:]) / np.dot(c, c)))
    return float(np.mean(vals)) if vals else 0.0


def _energy(x: np.ndarray) -> np.ndarray:
    return np.abs(np.diff(x, axis=0)).sum(1)


def energy_corr(x: np.ndarray, intensity: np.ndarray) -> float:
    e = _energy(x)
    s = intensity[1:]
    return float(np.corrcoef(e, s)[0, 1]) if e.std() > 0 and s.std() > 0 else 0.0


def perlin(n: int, d: int, period: float, rng: np.random.Generator) -> np.ndarray:
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
    minutes = len(blink) / fps / 60.0
    out = {k: len(f(blink)) / minutes for k, f in BLINK_KINDS.items()}
    out.update({"blink_spikes_per_min": spikes_per_min(blink, fps), "autocorr_lag5": autocorr(x),
                "energy_intensity_corr": energy_corr(x, intensity)})
    return out


def _ratio(a, ref):
    return {k: (a[k] / ref[k] if abs(ref[k]) > 1e-9 else None) for k in ref}


def _mean(dicts):
    return {k: float(np.mean([d[k] for d in dicts])) for k in dicts[0]}


def _spread(dicts):
    return {k: {"mean": float(np.mean(v)), "std": float(np.std(v, ddof=1)) if len(v) > 1 else 0.0,
                "min": float(np.min(v)), "max": float(np.max(v))}
            for k in dicts[0] for v in [[d[k] for d in dicts]]}


def _block_bootstrap(takes, stoch, blink, fps, rng):
    """Reference statistics over ``N_BOOT`` resamples of non-overlapping ``BLOCK_FRAMES``-frame blocks.

    Blink events are found on each whole take and belong to the block of their first frame (so the
    blocks' counts add up to the take's); the energy-intensity correlation pools the blocks' frame
    differences (none across the joins). Returns dict statistic -> (N_BOOT,) float64.
    """
    counts, energy, level = [], [], []
    for t in takes:
        x = np.column_stack([t.columns[n] for n in stoch])
        n_blocks = t.n_frames // BLOCK_FRAMES
        per = [np.bincount(f(t.columns[blink]) // BLOCK_FRAMES, minlength=n_blocks + 1)[:n_blocks]
               for f in BLINK_KINDS.values()]
        counts += list(np.stack(per, 1))
        for s in range(0, n_blocks * BLOCK_FRAMES, BLOCK_FRAMES):
            energy.append(_energy(x[s:s + BLOCK_FRAMES]))
            level.append(t.intensity[s + 1:s + BLOCK_FRAMES])
    counts = np.array(counts, np.float64)
    minutes = len(counts) * BLOCK_FRAMES / fps / 60.0
    out: dict[str, list] = {k: [] for k in (*BLINK_KINDS, "energy_intensity_corr")}
    for _ in range(N_BOOT):
        pick = rng.integers(len(counts), size=len(counts))
        for k, c in zip(BLINK_KINDS, counts[pick].sum(0) / minutes):
            out[k].append(c)
        e = np.concatenate([energy[i] for i in pick])
        s = np.concatenate([level[i] for i in pick])
        out["energy_intensity_corr"].append(float(np.corrcoef(e, s)[0, 1]))
    return {k: np.array(v) for k, v in out.items()}


def _goals(ref, boot, runs, noise):
    """Verdicts: ratio within 0.8-1.2 for rates/autocorrelation; interval of dr containing 0 for the energy."""
    goals = {}
    for k in ("blink_per_min", "blink_hysteresis_per_min", "blink_short_per_min", "autocorr_lag5"):
        vals = np.array([r[k] for r in runs])
        ratio = float(vals.mean() / ref[k]) if abs(ref[k]) > 1e-9 else None
        row = {"judged_by": "ratio of the seed mean to the reference, goal 0.8-1.2",
               "synth_over_reference": ratio,
               "seed_ratio_min_max": [float(vals.min() / ref[k]), float(vals.max() / ref[k])] if ratio else None,
               "noise_over_reference": float(noise[k] / ref[k]) if ratio else None,
               "met": bool(ratio is not None and 0.8 <= ratio <= 1.2)}
        if k in boot:
            row["reference_95pct_interval"] = [float(v) for v in np.percentile(boot[k], [2.5, 97.5])]
        goals[k] = row
    k = "energy_intensity_corr"
    syn = np.array([r[k] for r in runs])
    rng = np.random.default_rng(0)
    dr = syn[rng.integers(len(syn), size=N_BOOT)] - boot[k]
    lo, hi = np.percentile(dr, [2.5, 97.5])
    dn = noise[k] - boot[k]
    goals[k] = {"judged_by": "dr = r_synth - r_reference (absolute difference of correlations; the reference r is "
                             "about 0, so a ratio is undefined); 95 % interval from the reference block bootstrap "
                             "combined with the seeds; met when the interval contains 0",
                "reference": ref[k], "synth_mean": float(syn.mean()), "dr": float(syn.mean() - ref[k]),
                "dr_95pct_interval": [float(lo), float(hi)], "met": bool(lo <= 0.0 <= hi),
                "noise_dr": float(noise[k] - ref[k]),
                "noise_dr_95pct_interval": [float(v) for v in np.percentile(dn, [2.5, 97.5])],
                "note": "the reference takes have no audio: their intensity is the jawOpen proxy, so r_reference "
                        "measures mouth-motion/gesture coupling in a range-of-motion take, not speech"}
    return goals


def run_bench(args: argparse.Namespace) -> dict:
    # imported here, not at the top: they load scipy.signal and .ndimage, which every `facepuppet` start would pay
    from facepuppet.offline.gestures.blend_weights import BlendWeights, choose_basis
    from facepuppet.offline.gestures.database import build_gesture_db, read_llf_take
    from facepuppet.offline.gestures.speech_intensity import speech_intensity

    d = data_dir(args.data)
    speech = (d / "speech/facegood_1114_3_15.wav", d / "speech/facegood_1114_3_15_blendshapes.csv",
              d / "speech/facegood_to_arkit.csv")
    llf = [d / "tracker/livelinkface_alex_rom_3.csv", d / "tracker/livelinkface_myslate_3.csv"]
    markers = [d / "markers/animface_jaw.c3d", d / "markers/animface_cheeks.c3d"]
    fps = 30.0
    load_start = load_average()
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
    if args.recent is not None:
        extra["recent"] = args.recent
    if args.whole is not None:
        extra["whole"] = () if args.whole == "none" else tuple(g for g in args.whole.split(",") if g)
    held = level[cut:]
    reps = max(1, int(np.ceil(args.minutes * 60 * fps / len(held))))
    drive = np.tile(held, reps)   # the held-out speech, repeated
    z_drive = np.tile(z_all[cut:], reps)
    # reference: the takes the stochastic groups draw from (see the module docstring)
    ref_takes = [read_llf_take(p, z_all[:cut], fps) for p in llf]
    take_names = list(db.channels["takes"])
    frame_take = np.asarray(db["frame_take"])
    runs, steps, index_s, occupancy = [], [], [], []
    bar = Progress("bench gestures", total=args.seeds * len(drive), unit="steps")
    for seed in range(args.seed, args.seed + args.seeds):
        t0 = time.perf_counter()
        synth = GestureSynth(db, seed=seed, normaliser=SpeakerNormaliser(*stats, rate=0.0), **extra)
        index_s.append(time.perf_counter() - t0)
        out = np.zeros((len(drive), len(synth.out_names)), np.float32)
        eyes = np.zeros(len(drive), np.int64)
        st = np.zeros(len(drive))
        for i, v in enumerate(drive):
            s0 = time.perf_counter()
            out[i] = synth.step(float(v))
            st[i] = time.perf_counter() - s0
            eyes[i] = synth.pick("eyes")
            if i % 256 == 0:
                bar.update((seed - args.seed) * len(drive) + i, note=f"seed {seed}")
        steps.append(st)
        runs.append((out, synth.run_lengths))
        bar.update((seed - args.seed + 1) * len(drive), note=f"seed {seed}")
        share = np.bincount(frame_take[eyes], minlength=len(take_names)) / len(eyes)
        occupancy.append({"eyes_share_per_take": {n: float(v) for n, v in zip(take_names, share) if v > 0},
                          "eyes_distinct_frames": int(len(np.unique(eyes))),
                          "eyes_max_visits_of_one_frame": int(np.bincount(eyes).max())})
    names = list(synth.out_names)
    bar.close()
    stoch = [n for n in names if n.startswith(("brow", "eye", "cheek", "nose"))]
    blink = "eyeBlinkLeft"
    per_take = {t.name: _stats(np.column_stack([t.columns[n] for n in stoch]), t.columns[blink], t.intensity, fps)
                for t in ref_takes}
    weights = np.array([t.n_frames for t in ref_takes], np.float64)
    ref = {k: float(np.average([per_take[t.name][k] for t in ref_takes], weights=weights)) for k in
           per_take[ref_takes[0].name]}
    boot = _block_bootstrap(ref_takes, stoch, blink, fps, np.random.default_rng(args.seed))
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
        "reference_is": "the Live Link Face takes the brows/eyes/rest groups draw from, whole, pooled by frame "
                        "count; NOT held out (no second take of these performers): the figures say whether the "
                        "synthesis keeps its source's statistics. Held out: the last 20 % of the speech, which "
                        "drives the synthesis. The FACEGOOD curves and the marker takes carry no blinks.",
        "goals": _goals(ref, boot, syn_runs, noi),
        "reference": ref, "reference_per_take": per_take,
        "reference_bootstrap_95pct": {k: [float(v) for v in np.percentile(b, [2.5, 97.5])] for k, b in boot.items()},
        "synthesised": syn, "synthesised_spread_over_seeds": _spread(syn_runs),
        "synthesised_per_seed": syn_runs, "perlin_noise": noi,
        "synth_over_reference": _ratio(syn, ref), "noise_over_reference": _ratio(noi, ref),
        "run_length_frames": _mean([r for _, r in runs]), "eyes_occupancy_per_seed": occupancy,
        "synth_settings": {"sigma": synth.sigma, "n_candidates": synth.n_candidates, "history": synth.h,
                           "recent": synth.recent, "whole": list(synth.whole)},
        "jawopen": {"intensity_corr_reference_train": jaw_ref,
                    "intensity_corr_synthesised_heldout": float(np.mean([np.corrcoef(j, z_drive)[0, 1] for j in jaw])),
                    "mean_in_silence": float(np.mean([j[silent].mean() for j in jaw])) if silent.any() else None,
                    "mean_when_voiced": float(np.mean([j[~silent].mean() for j in jaw])),
                    "silent_frames": int(silent.sum()), "gate_db": stats[2]},
        "speed": {"frames": int(len(all_steps)), "realtime_factor": len(all_steps) / fps / all_steps.sum(),
                  "step_us_median": float(np.median(all_steps) * 1e6),
                  "step_us_p99": float(np.percentile(all_steps, 99) * 1e6),
                  "index_build_s": float(np.median(index_s)), "db_build_s": build_s,
                  "loadavg_start": load_start, "loadavg_end": load_average()},
        "database": {"bytes": size, "frames": int(len(db["intensity"])), "takes": take_names,
                     "features": len(db.channels["features"]), "continuity_dims": synth.dims},
        "blend_solvers": blend,
        "held_out_speech_s": len(held) / fps, "synthesised_s_per_seed": len(drive) / fps, "seeds": args.seeds,
    }


def register_benches(register_bench: Callable[..., None]) -> None:
    register_bench("gestures", run_bench, "Ju & Lee gestures: synthesised vs reference vs Perlin noise, speed, size",
                   _add_arguments)
