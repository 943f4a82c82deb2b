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
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.kpls.stage import KplsRetarget
from facepuppet.runtime.tables import hash_inputs

from facepuppet.offline.kpls.model import KernelPLS
from facepuppet.offline.kpls.pairs import TrainingPairs, expression_pairs, read_pairing

if TYPE_CHECKING:
    from facepuppet.runtime.character import Character


def to_runtime(model: KernelPLS, pairs: TrainingPairs, source: Character, target: Character,
               settings: dict | None = None, metrics: dict | None = None) -> KplsRetarget:
    """The runtime stage of a fitted model (float32 tables, channel names of both characters)."""
    a = model.export_arrays()
    return KplsRetarget(
        source_names=source.shape_names, target_names=target.shape_names,
        source_features=pairs.source_features, train_inputs=a["train_inputs"], dual_coef=a["dual_coef"],
        kernel_col_mean=a["kernel_col_mean"], kernel_grand_mean=a["kernel_grand_mean"],
        target_mean=a["target_mean"], kernel=a["kernel"], gamma=a["gamma"], coef0=a["coef0"],
        degree=a["degree"], units=source.units,
        metadata={"settings": dict(settings or {}), "metrics": dict(metrics or {}),
                  "input_hash": hash_inputs(pairs.X, pairs.Y)},
    )


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
    p.add_argument("--kernel", choices=("rbf", "poly", "linear"), default="rbf", help="kernel (default rbf)")
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
    from facepuppet.runtime.character import Character

    start = time.perf_counter()
    source, target = Character.load(args.source), Character.load(args.target)
    pairing = read_pairing(args.pairing) if args.pairing is not None else None
    pairs = expression_pairs(source, target, pairing=pairing, n_mixes=args.mixes, seed=args.seed,
                             k_source=args.source_points, k_target=args.target_points)
    model = KernelPLS(n_components=args.components, kernel=args.kernel).fit(pairs.X, pairs.Y)
    rms = float(np.sqrt(np.mean((model.predict(pairs.X) - pairs.Y) ** 2)))
    settings = {"kernel": args.kernel, "components": str(args.components), "n_components": model.n_components_,
                "source": str(args.source), "target": str(args.target), "mixes": args.mixes, "seed": args.seed,
                "source_points": pairs.source_points.tolist(), "target_points": pairs.target_points.tolist()}
    metrics = {"train_rms_weight": rms, "n_pairs": len(pairs.X), "matched_shapes": len(pairs.matched)}
    if getattr(model, "cv_errors_", None):
        metrics["cv_mse"] = {str(k): v for k, v in model.cv_errors_.items()}
    stage = to_runtime(model, pairs, source, target, settings, metrics)
    out = stage.save(args.output)
    log(f"{out}: kernel PLS ({args.kernel}, {model.n_components_} components) from {source.name!r} "
        f"({len(pairs.source_points)} feature points, {source.n_shapes} shapes) to {target.name!r} "
        f"({target.n_shapes} shapes); {len(pairs.X)} pairs over {len(pairs.matched)} matched shapes; "
        f"training RMS weight error {rms:.4f}; {time.perf_counter() - start:.2f} s")
    return 0
