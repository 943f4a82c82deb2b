"""``facepuppet fit-retarget SOURCE.npz TARGET.npz -o retarget.npz``: fit and export a kernel-PLS retarget.

SOURCE and TARGET are character tables. Training pairs come from
:mod:`facepuppet.offline.kpls.pairs` (shapes matched by name, or ``--pairing``), the model
from :mod:`facepuppet.offline.kpls.model`; the result is a ``retarget_kpls`` tables file that
``facepuppet replay --retarget`` loads.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.files.tables import hash_inputs
from facepuppet.runtime.kpls.stage import KplsRetarget
from facepuppet.runtime.model.character import Character

from facepuppet.offline.kpls.model import KernelPLS
from facepuppet.offline.kpls.pairs import TrainingPairs, expression_pairs, match_matrix, pair_weights, read_pairing


def to_runtime(model: KernelPLS, pairs: TrainingPairs, source: Character, target: Character,
               settings: dict | None = None, metrics: dict | None = None) -> KplsRetarget:
    """The runtime stage of a fitted model (float32 tables, channel names of both characters).

    A linear-kernel model is exported in its primal form, the same function: eq. 10 with
    k(x, X_i) = xᵀX_i is ŷ = x β + ŷ(0), β = Xᵀ B − X̄ ⊗ Σ_i B_i, written as the training inputs
    [I; 0] with dual coefficients [β; −Σ β] and no centring terms. The dual form's coefficients
    cancel one another across hundreds of pairs and lose up to 0.1 of a weight in float32 on the
    ICT head; β does not.
    """
    a = model.export_arrays()
    if a["kernel"] == "linear":
        X, B = a["train_inputs"], a["dual_coef"]
        beta = X.T @ B - np.outer(X.mean(axis=0), B.sum(axis=0))
        at_zero = (a["kernel_grand_mean"] - a["kernel_col_mean"]) @ B + a["target_mean"]
        nf = X.shape[1]
        a = dict(a, train_inputs=np.vstack([np.eye(nf), np.zeros((1, nf))]),
                 dual_coef=np.vstack([beta, -beta.sum(axis=0)]), kernel_col_mean=np.zeros(nf + 1),
                 kernel_grand_mean=0.0, target_mean=at_zero)
    meta = {"settings": dict(settings or {}), "metrics": dict(metrics or {}),
            "input_hash": hash_inputs(pairs.X, pairs.Y)}
    return KplsRetarget(
        source_names=source.shape_names, target_names=target.shape_names,
        source_features=pairs.source_features, train_inputs=a["train_inputs"], dual_coef=a["dual_coef"],
        kernel_col_mean=a["kernel_col_mean"], kernel_grand_mean=a["kernel_grand_mean"],
        target_mean=a["target_mean"], kernel=a["kernel"], gamma=float(a["gamma"]), coef0=a["coef0"],
        degree=a["degree"], units=source.units, metadata=meta,
    )


def fit_kpls(source: Character, target: Character, kernel: str = "auto", components: int | str = "auto",
             pairing: list[tuple[str, str]] | None = None, n_mixes: int = 300, seed: int = 0,
             k_source: int = 45, k_target: int = 37, label: str = "fit-retarget",
             progress: bool | None = None) -> tuple[KernelPLS, TrainingPairs]:
    """Training pairs and the cross-validated model of ``fit-retarget`` (its defaults are these).

    ``progress``: draw a progress line over the cross-validation folds (None: when stderr is a
    terminal, see :class:`~facepuppet.runtime.cli.progress.Progress`).
    """
    pairs = expression_pairs(source, target, pairing=pairing, n_mixes=n_mixes, seed=seed,
                             k_source=k_source, k_target=k_target)
    model = KernelPLS(n_components=components, kernel=kernel)
    total = len(model.candidates()) * model.cv_folds
    with Progress(f"{label}: cross-validation", total or None, unit="folds", enabled=progress) as bar:
        model.fit(pairs.X, pairs.Y, progress=lambda note: bar.advance(1, note))
    return model, pairs


def by_name_agreement(stage: KplsRetarget, source: Character, target: Character,
                      pairing: list[tuple[str, str]] | None = None, n_mixes: int = 400,
                      seed: int = 1) -> list[dict]:
    """Per target channel, the retarget against the plain by-name mapping on held-out expressions.

    The expressions are :func:`~facepuppet.offline.kpls.pairs.pair_weights` of another seed
    (each shape over its range and busy mixes). Each row: ``channel``, ``matched`` (whether a
    source shape maps onto it by name or pairing), ``max_abs`` (largest |retarget − by name|),
    ``r`` (correlation over the expressions, NaN where either side is constant).
    """
    M = match_matrix(source.shape_names, target.shape_names, pairing)
    matched = np.flatnonzero(M.any(axis=0))
    W = pair_weights(source.n_shapes, matched, n_mixes, seed=seed)
    by_name = W @ M.T
    got = np.stack([stage.predict_weights(w) for w in W]).astype(np.float64)
    rows = []
    for j, name in enumerate(target.shape_names):
        a, b = by_name[:, j], got[:, j]
        r = float(np.corrcoef(a, b)[0, 1]) if a.std() > 0 and b.std() > 0 else float("nan")
        rows.append({"channel": name, "matched": bool(M[j].any()), "max_abs": float(np.abs(a - b).max()),
                     "r": r})
    return rows


def agreement_lines(rows: list[dict], tolerance: float = 0.02) -> list[str]:
    """Text of :func:`by_name_agreement`: a verdict, then one line per target channel."""
    matched = [r for r in rows if r["matched"]]
    worst = max((r["max_abs"] for r in matched), default=0.0)
    if matched and worst <= tolerance:
        verdict = (f"by-name agreement: the retarget equals the by-name mapping within {worst:.4f} on all "
                   f"{len(matched)} matched channels: the characters share names and meaning here, and "
                   f"a plain by-name map (no --retarget) gives the same result")
    else:
        far = sum(r["max_abs"] > tolerance for r in matched)
        verdict = (f"by-name agreement: the retarget departs from the by-name mapping by more than "
                   f"{tolerance} on {far} of {len(matched)} matched channels (largest {worst:.4f})")
    lines = [verdict, f"  {'channel':<22} {'max |kpls - by name|':>20} {'r':>8}"]
    for r in rows:
        if r["matched"]:
            lines.append(f"  {r['channel']:<22} {r['max_abs']:>20.4f} {r['r']:>8.4f}")
        else:
            lines.append(f"  {r['channel']:<22} {'(no source shape by name)':>29}")
    return lines


def parse_components(text: str) -> int | str:
    """``"auto"`` or a positive int, for ``--components``."""
    if text == "auto":
        return "auto"
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected 'auto' or a positive integer, got {text!r}")
    return value


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "fit-retarget",
        help="fit a kernel-PLS retarget between two characters (Ouzounis et al.) -> retarget tables",
        description="Fit kernel PLS from the source character's feature-point displacements to the "
                    "target character's blendshape weights on semantically matching expressions.",
    )
    p.add_argument("source", type=Path, help="source character .npz")
    p.add_argument("target", type=Path, help="target character .npz")
    p.add_argument("-o", "--output", type=Path, required=True, help="retarget tables to write (.npz)")
    p.add_argument("--kernel", choices=("auto", "rbf", "poly", "linear"), default="auto",
                   help="kernel, or 'auto' (default): cross-validate linear, rbf (several widths) and poly "
                        "and keep the best")
    p.add_argument("--components", type=parse_components, default="auto",
                   help="latent components, or 'auto' for cross-validation (default)")
    p.add_argument("--pairing", type=Path, help="text file of 'source_shape,target_shape' lines "
                                                 "(default: match shapes by name)")
    p.add_argument("--source-points", type=int, default=45, help="feature points on the source (default 45)")
    p.add_argument("--target-points", type=int, default=37, help="feature points on the target (default 37)")
    p.add_argument("--mixes", type=int, default=300, help="random mixed expressions added to the pairs")
    p.add_argument("--seed", type=int, default=0, help="seed of the mixes and the feature points")
    p.set_defaults(func=fit_retarget_command)


def fit_retarget_command(args: argparse.Namespace, log: Callable[[str], None] = print) -> int:
    """Run ``fit-retarget`` from parsed ``args``; returns the exit code."""
    start = time.perf_counter()
    source, target = Character.load(args.source), Character.load(args.target)
    pairing = read_pairing(args.pairing) if args.pairing is not None else None
    model, pairs = fit_kpls(source, target, kernel=args.kernel, components=args.components, pairing=pairing,
                            n_mixes=args.mixes, seed=args.seed, k_source=args.source_points,
                            k_target=args.target_points)
    rms = float(np.sqrt(np.mean((model.predict(pairs.X) - pairs.Y) ** 2)))
    settings = {"kernel": model.kernel_, "kernel_asked": args.kernel, "components": str(args.components),
                "n_components": model.n_components_, "gamma": float(model.gamma_),
                "source": str(args.source), "target": str(args.target), "mixes": args.mixes, "seed": args.seed,
                "source_points": pairs.source_points.tolist(), "target_points": pairs.target_points.tolist()}
    metrics = {"train_rms_weight": rms, "n_pairs": len(pairs.X), "matched_shapes": len(pairs.matched)}
    if getattr(model, "cv_errors_", None):
        metrics["cv_mse"] = {str(k): v for k, v in model.cv_errors_.items()}
        metrics["cv_mse_by_kernel"] = dict(model.cv_scores_)
    rows = by_name_agreement(to_runtime(model, pairs, source, target), source, target, pairing)
    metrics["by_name_max_abs"] = max((r["max_abs"] for r in rows if r["matched"]), default=0.0)
    stage = to_runtime(model, pairs, source, target, settings, metrics)
    out = stage.save(args.output)
    tried = ""
    if getattr(model, "cv_scores_", None) and len(model.cv_scores_) > 1:
        tried = "; cross-validated MSE " + ", ".join(f"{k} {v:.2e}" for k, v in model.cv_scores_.items())
    log(f"{out}: kernel PLS ({model.kernel_}, {model.n_components_} components) from {source.name!r} "
        f"({len(pairs.source_points)} feature points, {source.n_shapes} shapes) to {target.name!r} "
        f"({target.n_shapes} shapes); {len(pairs.X)} pairs over {len(pairs.matched)} matched shapes; "
        f"training RMS weight error {rms:.4f}{tried}; {time.perf_counter() - start:.2f} s")
    for line in agreement_lines(rows):
        log(line)
    return 0
