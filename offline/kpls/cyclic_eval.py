"""Cyclic retarget error (Ouzounis, Kiliadis & Mousas eq. 11, Fig. 5) over retargeting methods.

A source motion (weights of character A per frame) is retargeted to a target
character B and back to A, each direction by a model fitted on that
direction's training pairs (:mod:`facepuppet.offline.kpls.pairs`). The cyclic error

    e_d = 1 / (N_f N_v) Σ_f Σ_v ‖v_{f,v} − v'_{f,v}‖          (eq. 11)

compares A's vertices under the original weights (v) with those under the
weights that came back (v'), over the frames f and the vertices v that some
shape of A moves, in A's units.

Symbols and names: v, v' ``original``, ``returned`` (vertex positions); N_f
frames of ``motion``; N_v vertices of ``region``; e_d ``e_d``.

Targets, and what correspondence each asks the methods to learn, are in
:mod:`facepuppet.offline.kpls.targets`; the spatial baseline of Dutreve et al. is in
:mod:`.dutreve_rbf`.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.mapping.channels import ChannelMap
from facepuppet.runtime.model.character import Character

from facepuppet.offline.kpls.baselines import KernelRidgeRetarget, LinearPLS, LinearRetarget, PairRBF, PCARBFRetarget
from facepuppet.offline.kpls.dutreve_rbf import DutreveRBF, corresponding_vertices
from facepuppet.offline.kpls.model import KernelPLS
from facepuppet.offline.kpls.pairs import feature_matrix, feature_points, moving_region, pair_weights
from facepuppet.offline.kpls.targets import stylise  # noqa: F401  (kept importable from here)

REFERENCE = "KPLS rbf"
DUTREVE = "Dutreve spatial RBF"


def default_methods() -> dict:
    """Method name -> factory of an unfitted regressor with ``fit``/``predict``."""
    return {
        "KPLS rbf": lambda: KernelPLS(kernel="rbf"),
        "KPLS poly": lambda: KernelPLS(kernel="poly", degree=2),
        "KPLS linear": lambda: KernelPLS(kernel="linear"),
        "RBF on pairs": PairRBF,
        "Deng PCA+RBF": PCARBFRetarget,
        "kernel ridge": KernelRidgeRetarget,
        "linear PLS": LinearPLS,
        "linear regression": LinearRetarget,
    }


def motion_weights(frames: Iterable[Frame], character: Character) -> np.ndarray:
    """Per-frame weights (n_frames, n_shapes) float64 of ``character`` driven by tracker frames by name."""
    frames = [f for f in frames if f.weights is not None]
    if not frames:
        raise ValueError("motion_weights: no frame carries weights")
    cmap = ChannelMap.build(frames[0].channels, character.shape_names)
    return np.stack([cmap.apply(f.weights) for f in frames]).astype(np.float64)


def cyclic_error(character: Character, motion: np.ndarray, returned: np.ndarray,
                 region: np.ndarray | None = None) -> float:
    """e_d (eq. 11), units of ``character``: mean vertex distance between two weight sequences.

    Parameters
    ----------
    motion, returned : ndarray of shape (n_frames, n_shapes), weights before and after the cycle
    region : vertex indices to average over (default: every vertex some shape moves)
    """
    if motion.shape != returned.shape:
        raise ValueError(f"cyclic_error: motion {motion.shape} and returned {returned.shape} differ in shape")
    region = moving_region(character, 0.0) if region is None else region
    D = character.dense_deltas()[:, region].reshape(character.n_shapes, -1).astype(np.float64)
    diff = (motion - returned) @ D  # v − v' per frame: the neutral cancels
    # Ouzounis eq. 11: e_d = 1/(N_f N_v) Σ_f Σ_v ‖v − v'‖
    return float(np.linalg.norm(diff.reshape(len(motion), len(region), 3), axis=2).mean())


def evaluate(source: Character, targets: dict, motion: np.ndarray, methods: dict | None = None,
             n_mixes: int = 300, seed: int = 0, k_source: int = 45, dutreve: bool = True,
             log: Callable[[str], None] | None = None) -> list[dict]:
    """Cycle ``motion`` of ``source`` through every target with every method.

    Per target, the training expressions are the source weights W of
    :func:`~facepuppet.offline.kpls.pairs.pair_weights` over the shapes the target matches;
    the pairs are x = F_A w (the source's ``k_source`` feature points) and
    y = ``target.features(W)`` (the target's own feature points). The forward
    model learns x -> y, the backward model y -> w on the same pairs; a
    frame goes w -> x -> ŷ -> ŵ and e_d compares w with ŵ on the source's
    vertices. With ``dutreve``, the spatial method of :mod:`.dutreve_rbf`
    (no learning from the pairs) is evaluated too, as "Dutreve spatial RBF".

    Parameters
    ----------
    targets : dict of name -> target of :mod:`facepuppet.offline.kpls.targets` (``features``, ``points``,
        ``neutral_points``, ``character``, ``matched``)
    motion : ndarray of shape (n_frames, n_source_shapes), source weights

    Returns
    -------
    list of dict with keys target, method, e_d (source units), e_target (mean
    distance of the forward prediction from the target's true feature points,
    target units; eq. 11 cannot see a consistent but wrong target), fit_s (both
    directions), predict_us_per_frame (both directions), n_components and
    gamma (KPLS only, [forward, backward]).
    """
    methods = dict(methods or default_methods())
    region = moving_region(source, 0.0)
    sp = feature_points(source, k_source, None, seed)
    F_a = feature_matrix(source, sp)
    x_motion = motion @ F_a.T
    rows = []
    for tname, target in targets.items():
        W = pair_weights(source.n_shapes, target.matched, n_mixes, seed=seed)
        X, Y = W @ F_a.T, target.features(W)
        y_motion = target.features(motion)
        todo = dict(methods)
        if dutreve:
            todo[DUTREVE] = None
        for mname, factory in todo.items():
            t0 = time.perf_counter()
            if factory is None:
                there, back = _dutreve_pair(source, target, sp, region)
            else:
                there, back = factory(), factory()
            there.fit(X, Y)
            back.fit(Y, W)
            t1 = time.perf_counter()
            y_there = there.predict(x_motion)
            w_back = back.predict(y_there)
            t2 = time.perf_counter()
            # forward error against the target's true expression (known here, unlike in the paper)
            miss = (y_there - y_motion).reshape(len(motion), -1, 3)
            row = {"target": tname, "method": mname, "e_d": cyclic_error(source, motion, w_back, region),
                   "e_target": float(np.linalg.norm(miss, axis=2).mean()),
                   "fit_s": t1 - t0, "predict_us_per_frame": 1e6 * (t2 - t1) / len(motion)}
            if hasattr(there, "n_components_"):
                row["n_components"] = [int(there.n_components_), int(back.n_components_)]
                row["gamma"] = [float(there.gamma_), float(back.gamma_)]
            rows.append(row)
            if log:
                extra = f"  components {row['n_components']}" if "n_components" in row else ""
                log(f"  {tname:<26} {mname:<20} e_d {row['e_d']:.4f} {source.units}  e_target {row['e_target']:.4f}  "
                    f"fit {row['fit_s']:.2f} s{extra}")
    return rows


def _dutreve_pair(source: Character, target, sp: np.ndarray, region: np.ndarray):
    """Forward and backward :class:`DutreveRBF` between ``source`` and ``target``'s geometry."""
    tc = target.character
    fwd = DutreveRBF(in_points=source.vertices[sp].astype(np.float64),
                     in_on_out=tc.vertices[corresponding_vertices(source, tc, sp)].astype(np.float64),
                     out_positions=target.neutral_points)
    D = source.dense_deltas()[:, region].reshape(source.n_shapes, -1).astype(np.float64)
    bwd = DutreveRBF(in_points=target.neutral_points,
                     in_on_out=source.vertices[corresponding_vertices(tc, source, target.points)].astype(np.float64),
                     out_positions=source.vertices[region].astype(np.float64), out_basis=D.T)
    return fwd, bwd


def improvements(rows: list[dict], reference: str = REFERENCE) -> dict:
    """{target: {method: 100 (e_method − e_ref) / e_method}}, percent, as the paper reports them.

    None (printed "n/a") where the method's error is zero: below 1e-9 of the reference's error (or,
    where the reference is itself zero, of the target's median error), i.e. rounding, where the ratio
    is meaningless (it printed -526179663866110 %). The median, not the largest: one method that blows
    up (1e13) must not turn every other comparison in its column into "n/a".
    """
    out: dict = {}
    for target in dict.fromkeys(r["target"] for r in rows):
        errs = {r["method"]: r["e_d"] for r in rows if r["target"] == target}
        ref = errs.get(reference)
        if ref is None:
            continue
        finite = [e for e in errs.values() if np.isfinite(e)]
        zero = 1e-9 * (ref if ref > 0 else float(np.median(finite)) if finite else 0.0)
        out[target] = {m: (100.0 * (e - ref) / e if e > zero and np.isfinite(e) else None)
                       for m, e in errs.items() if m != reference}
    return out


def format_table(rows: list[dict], units: str = "", reference: str = REFERENCE, key: str = "e_d") -> str:
    """Plain-text table: ``key`` (e_d or e_target) per method (rows) and target (columns), and the
    reference's improvement."""
    targets = list(dict.fromkeys(r["target"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    errs = {(r["target"], r["method"]): r[key] for r in rows}
    imp = improvements([dict(r, e_d=r[key]) for r in rows], reference)
    width = max(20, *(len(t) + 2 for t in targets))
    title = "cyclic error e_d (eq. 11)" if key == "e_d" else "forward error on the target's feature points"
    lines = [f"{title} ({units}); in brackets: improvement of {reference} over the method",
             f"{'method':<20}" + "".join(f"{t:>{width}}" for t in targets)]
    for m in methods:
        cells = []
        for t in targets:
            pct = imp.get(t, {}).get(m, "")
            note = "       " if pct == "" else " (n/a) " if pct is None else f" ({pct:+.0f}%)"
            cells.append(f"{errs[(t, m)]:.4f}" + note)
        lines.append(f"{m:<20}" + "".join(f"{c:>{width}}" for c in cells))
    return "\n".join(lines)


def bar_plot(rows: list[dict], path: str | os.PathLike, units: str = "", size: tuple[int, int] = (960, 480)) -> Path:
    """Grouped bar chart of e_d (one group per target, one bar per method), drawn with Pillow."""
    from PIL import Image, ImageDraw

    targets = list(dict.fromkeys(r["target"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    errs = {(r["target"], r["method"]): r["e_d"] for r in rows}
    W, H = size
    left, right, top, bottom = 60, 190, 30, 50
    img = Image.new("RGB", size, "white")
    draw = ImageDraw.Draw(img)
    top_val = max(errs.values()) * 1.1 or 1.0
    palette = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
               (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207)]
    plot_h = H - top - bottom
    draw.line([(left, top), (left, H - bottom), (W - right, H - bottom)], fill="black")
    for i in range(5):
        v = top_val * i / 4
        y = H - bottom - plot_h * i / 4
        draw.line([(left - 4, y), (left, y)], fill="black")
        draw.text((4, y - 6), f"{v:.3f}", fill="black")
    group_w = (W - left - right) / max(len(targets), 1)
    bar_w = group_w * 0.8 / max(len(methods), 1)
    for g, t in enumerate(targets):
        x0 = left + g * group_w + group_w * 0.1
        for j, m in enumerate(methods):
            h = plot_h * errs[(t, m)] / top_val
            draw.rectangle([x0 + j * bar_w, H - bottom - h, x0 + (j + 1) * bar_w - 2, H - bottom],
                           fill=palette[j % len(palette)])
        draw.text((x0, H - bottom + 8), t, fill="black")
    for j, m in enumerate(methods):
        y = top + 16 * j
        draw.rectangle([W - right + 10, y, W - right + 20, y + 10], fill=palette[j % len(palette)])
        draw.text((W - right + 26, y - 1), m, fill="black")
    draw.text((left, 8), f"cyclic retarget error e_d ({units}), Ouzounis et al. eq. 11", fill="black")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    img.save(path)
    return path
