"""A kernel-PLS retarget stage with random tables, for the stage tests."""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.kpls.stage import KplsRetarget


def random_stage(kernel="rbf", n_train=30, n_features=12, source=("jawOpen", "eyeBlinkLeft", "eyeBlinkRight"),
           target=("a", "b", "c", "d"), seed=0):
    rng = np.random.default_rng(seed)
    return KplsRetarget(
        source_names=source, target_names=target,
        source_features=rng.normal(size=(n_features, len(source))), train_inputs=rng.normal(size=(n_train, n_features)),
        dual_coef=rng.normal(size=(n_train, len(target))) * 0.1, kernel_col_mean=rng.uniform(0, 1, n_train),
        kernel_grand_mean=0.4, target_mean=rng.uniform(0, 1, len(target)), kernel=kernel, gamma=0.05,
        coef0=1.0, degree=2, units="cm",
    )
