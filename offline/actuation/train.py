"""Train an actor model from a marker capture: stabilise -> actuations (§4) -> cubic functions (§5).

The three stages of Shin & Lee 2009 in one estimator. ``ActorModel`` stores
its settings in the constructor; ``fit(capture)`` learns ``actor_`` (the
runtime :class:`~facepuppet.runtime.actuation.actor.Actor` table), ``s_`` (the training
actuations), ``stabilised_`` and ``metrics_`` (timings, errors, K report).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.errors import InputFileError, UsageError
from facepuppet.runtime.files.tables import hash_inputs

from facepuppet.offline.actuation.basis import ActuationModel, k_report, neutral_frame
from facepuppet.offline.actuation.cubic_fit import choose_ridge_ab, fit_polynomial, holdout_errors
from facepuppet.offline.actuation.stabilise import MM_PER_UNIT, RIGID_WARN_MM, stabilise
from facepuppet.offline.io.capture import Capture

Progress = Callable[[str, float, str], None]
BOUND_MARGIN = 0.25  # solver bounds: the training range widened by this fraction of it
S_QUANTILE_LEVELS = (0.0, 0.01, 0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 0.99, 1.0)  # stored per actuation
S_SAMPLES = 400  # training frames whose s the actor table keeps (evenly spaced) for the transfer's pairs


class ActorModel:
    """Estimator: marker capture -> actor tables.

    Parameters
    ----------
    k : int, number of actuations K (default 13, as in the paper)
    head_markers : sequence of str (names) or None to find the least-deforming set
    neutral_frame : int or None (the frame closest to the median pose)
    bandwidth : float, mean-shift bandwidth on the unit sphere
    handover_power : float, sharpness of the hand-over between classes
    random_state : int, FastICA seed
    report_ks : tuple of int, the K values of the reconstruction report
    ridge_ab : float or "auto", ridge on the cubic and quadratic terms (a, b); "auto" picks it by
        held-out error on a split of the take (:func:`~facepuppet.offline.actuation.cubic_fit.choose_ridge_ab`).
        On the AnimFace jaw take the plain cubic overfits (held-out 0.0836 cm vs linear 0.0823);
        the chosen ridge (0.03) gives 0.0779
    threads : int or None, BLAS threads during the fit (default 1: these matrices are small, and
        threaded BLAS on them is slower, badly so on a busy machine); None leaves BLAS alone
    """

    def __init__(self, k: int = 13, head_markers: Sequence[str] | None = None, neutral_frame: int | None = None,
                 bandwidth: float = 0.5, handover_power: float = 4.0, random_state: int = 0,
                 report_ks: tuple[int, ...] = (1, 2, 4, 8, 13, 20, 30), threads: int | None = 1,
                 ridge_ab: float | str = "auto") -> None:
        self.k = k
        self.head_markers = head_markers
        self.neutral_frame = neutral_frame
        self.bandwidth = bandwidth
        self.handover_power = handover_power
        self.random_state = random_state
        self.report_ks = report_ks
        self.threads = threads
        self.ridge_ab = ridge_ab

    def fit(self, capture: Capture, progress: Progress | None = None) -> ActorModel:
        """Learn the actor from ``capture`` (any units; head motion is removed first)."""
        if self.threads is None:
            return self._fit(capture, progress)
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=self.threads, user_api="blas"):
            return self._fit(capture, progress)

    def _fit(self, capture: Capture, progress: Progress | None) -> ActorModel:
        say = progress or (lambda stage, fraction, message: None)
        if not isinstance(capture, Capture):
            raise TypeError(f"ActorModel.fit: expected a Capture, got {type(capture).__name__}")
        if capture.n_markers < 3:
            raise InputFileError(f"{capture.source or 'capture'}: need at least 3 markers, found {capture.n_markers}")
        n = capture.n_frames
        if self.neutral_frame is not None and not 0 <= self.neutral_frame < n:
            raise UsageError(f"neutral_frame: expected 0..{n - 1}, got {self.neutral_frame}")
        t0 = time.perf_counter()
        say("stabilise", 0.0, f"{n} frames x {capture.n_markers} markers")
        reference = self.neutral_frame if self.neutral_frame is not None else 0
        stab = stabilise(capture.markers, capture.names, self.head_markers, reference_frame=reference,
                         mm_per_unit=MM_PER_UNIT[capture.units])
        say("stabilise", 0.5, stab.choice.describe(capture.names))
        say("stabilise", 1.0, stab.summary())
        markers = stab.markers.astype(np.float64)
        neutral = self.neutral_frame if self.neutral_frame is not None else neutral_frame(markers)
        if np.isnan(markers[neutral]).any():
            raise UsageError(f"neutral_frame {neutral}: some markers are occluded there; choose another frame")
        disp = markers - markers[neutral]
        complete = np.isfinite(disp).all(axis=(1, 2))
        t1 = time.perf_counter()

        say("actuation", 0.0, f"mean-shift classes, ICA into K = {self.k}")
        act = ActuationModel(self.k, self.bandwidth, self.handover_power, random_state=self.random_state)
        act.fit(disp[complete])
        s = act.transform(disp[complete])
        say("actuation", 1.0, f"{len(act.axes_)} marker classes -> {self.k} actuations")
        t2 = time.perf_counter()

        say("cubic", 0.0, "least squares for all markers at once")
        y = disp[complete].reshape(int(complete.sum()), -1)
        if self.ridge_ab == "auto":
            ridge_ab, ridge_table = choose_ridge_ab(s, y, capture.n_markers)
        elif isinstance(self.ridge_ab, (int, float)) and self.ridge_ab >= 0:
            ridge_ab, ridge_table = float(self.ridge_ab), []
        else:
            raise ValueError(f"ridge_ab: expected 'auto' or a number >= 0, got {self.ridge_ab!r}")
        cubic = fit_polynomial(s, y, 3, ridge_ab=ridge_ab)           # Shin & Lee eqs 2-4
        linear = fit_polynomial(s, y, 1)
        t3 = time.perf_counter()
        errors = holdout_errors(s, y, capture.n_markers)
        say("cubic", 1.0, f"held-out RMS linear {errors['linear_rms']:.4f} vs cubic {errors['cubic_rms']:.4f}, "
                          f"cubic + ridge {errors['cubic_ridge_rms']:.4f} {capture.units}")
        lo, hi = s.min(axis=0), s.max(axis=0)
        margin = BOUND_MARGIN * (hi - lo)
        k_rows = k_report(disp[complete], act.signals(disp[complete]), self.report_ks)

        settings = {"k": int(self.k), "bandwidth": self.bandwidth, "handover_power": self.handover_power,
                    "random_state": self.random_state, "neutral_frame": int(neutral), "ridge_ab": ridge_ab,
                    "head_markers": [capture.names[i] for i in stab.head_markers],
                    "head_fixed": bool(stab.head_fixed), "source": capture.source, "rate": capture.rate,
                    "head_markers_found": stab.choice.how != "given", "head_markers_how": stab.choice.how}
        train_rms = float(np.sqrt(np.mean(np.sum(
            ((np.concatenate([s ** 3, s ** 2, s], 1) @ cubic.reshape(-1, y.shape[1])) - y).reshape(
                len(y), -1, 3) ** 2, axis=2))))
        self.metrics_ = {
            "n_frames": int(n), "n_training_frames": int(complete.sum()), "n_markers": capture.n_markers,
            "n_classes": int(len(act.axes_)), "ica_converged": bool(act.converged_),
            "preprocess_s": t1 - t0, "ica_s": t2 - t1, "fit_s": t3 - t2, "train_s": t3 - t0,
            "train_rms": train_rms, "holdout": errors, "k_report": k_rows, "ridge_ab_table": ridge_table,
            "head_rms_residual": stab.rms_residual, "head_max_angle_deg": stab.max_angle_deg,
            "head_rigidity_mm": stab.choice.rigidity_mm, "head_span": stab.choice.span,
            "gaps_left": len(capture.gaps), "samples_filled": int(capture.filled),
            # the actuations' real range, for transfer training pairs (offline/actuation/transfer.py)
            "s_quantiles": {"levels": list(S_QUANTILE_LEVELS),
                            "values": np.quantile(s, S_QUANTILE_LEVELS, axis=0).round(6).tolist()},
        }
        self.actor_ = Actor(
            names=capture.names, units=capture.units, neutral=markers[neutral],
            cubic=cubic.reshape(3, self.k, capture.n_markers, 3),
            linear=linear.reshape(self.k, capture.n_markers, 3),
            unmixing=act.unmixing_, class_axes=act.axes_, class_marker=act.axis_marker_,
            head_markers=np.asarray(stab.head_markers),
            s_samples=s[np.unique(np.linspace(0, len(s) - 1, min(S_SAMPLES, len(s))).astype(int))],
            s_lower=np.minimum(lo - margin, 0.0), s_upper=np.maximum(hi + margin, 0.0),
            metadata={"settings": settings, "metrics": self.metrics_,
                      "input_hash": hash_inputs(capture.markers)},
        )
        self.s_ = s
        self.training_frames_ = np.flatnonzero(complete)
        self.stabilised_ = stab
        self.actuation_ = act
        return self

    def summary(self) -> str:
        """A few lines on the fit: sizes, timings, errors, the K report."""
        if not hasattr(self, "actor_"):
            raise RuntimeError("ActorModel is not fitted; call fit(capture) first")
        m, a = self.metrics_, self.actor_
        h = m["holdout"]
        lines = [
            f"actor: {a.n_markers} markers, {m['n_classes']} marker classes, K = {a.n_actuations}, {a.units}",
            f"  frames: {m['n_training_frames']} of {m['n_frames']} used (complete); neutral frame "
            f"{a.metadata['settings']['neutral_frame']}; "
            f"head markers {', '.join(a.metadata['settings']['head_markers'])} "
            f"(rigidity: distance SD up to {m['head_rigidity_mm']:.2f} mm"
            + (f", over {RIGID_WARN_MM:g} mm: not rigid" if m["head_rigidity_mm"] > RIGID_WARN_MM else "") + ")",
            f"  head: {self.stabilised_.summary()}",
            f"  time: preprocess {m['preprocess_s']:.2f} s, ICA {m['ica_s']:.2f} s, cubic fit {m['fit_s']:.2f} s",
            f"  held-out RMS marker error: linear {h['linear_rms']:.4f}, cubic {h['cubic_rms']:.4f}, cubic with "
            f"a, b ridge {h['ridge_ab']:g} {h['cubic_ridge_rms']:.4f} {a.units} ({h['n_test']} frames; "
            f"the table uses ridge {a.metadata['settings']['ridge_ab']:g})",
            "  K report (RMS marker error, linear model, held-in):  K: ICA-signals / PCA-markers",
        ]
        lines += [f"    K={r['k']:>2}: {r['ica_rms']:.4f} / {r['pca_rms']:.4f}" for r in m["k_report"]]
        return "\n".join(lines)


def train_actor(capture: Capture, k: int = 13, progress: Progress | None = None, **settings: Any) -> ActorModel:
    """``ActorModel(k, **settings).fit(capture, progress)``."""
    return ActorModel(k=k, **settings).fit(capture, progress)
