"""How the panel hands a config change to the pipeline.

The agreed contract (issue 15, P1/P2): ``LivePipeline.apply_config(config)`` takes a whole ``LiveConfig``
and applies it at the next tick without a pause; ``LivePipeline.clear_calibration()`` drops the neutral.
Both belong to the desk-profile branch. Until it is merged, the fallbacks below stand in for them.

SHIM (desk-panel): remove ``_apply_shim`` and ``_clear_shim`` at the merge with desk-profile, when
LivePipeline has ``apply_config`` and ``clear_calibration`` itself.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.channels import filter_region

if TYPE_CHECKING:
    from facepuppet.runtime.live.config import LiveConfig
    from facepuppet.runtime.live.pipeline import LivePipeline


def apply_config(pipeline: LivePipeline | None, config: LiveConfig) -> None:
    """``pipeline.apply_config(config)``, or the shim below when the pipeline has none yet."""
    if pipeline is None:
        return
    method = getattr(pipeline, "apply_config", None)
    if method is not None:
        method(config)
    else:
        _apply_shim(pipeline, config)


def clear_calibration(pipeline: LivePipeline) -> None:
    """``pipeline.clear_calibration()``, or the shim below."""
    method = getattr(pipeline, "clear_calibration", None)
    if method is not None:
        method()
    else:
        _clear_shim(pipeline)


def _apply_shim(pipeline, config) -> None:
    """SHIM: the new config in force; the running filters take its settings in place (their state kept,
    so the output does not jump), and gain/clamp per channel likewise."""
    pipeline.config = config
    cs, channels = getattr(pipeline, "_cs", None), getattr(pipeline, "_channels", None)
    if cs is None or channels is None:
        return
    settings = [config.filters[filter_region(c)] for c in channels]
    cs.weights.min_cutoff[:] = [s.min_cutoff for s in settings]
    cs.weights.beta[:] = [s.beta for s in settings]
    cs.weights.d_cutoff[:] = [s.d_cutoff for s in settings]
    head = config.filters["head"]
    for f in (cs.rotation, cs.translation):
        f.min_cutoff[:], f.beta[:], f.d_cutoff[:] = head.min_cutoff, head.beta, head.d_cutoff
    per = [config.channel(c) for c in channels]
    cs.gain[:] = [p.gain for p in per]
    cs.low[:] = [p.clamp[0] for p in per]
    cs.high[:] = [p.clamp[1] for p in per]
    cs.neutral_out = np.clip(np.zeros(len(channels)), cs.low, cs.high)


def _clear_shim(pipeline) -> None:
    """SHIM: no neutral (weights, rotation and translation as sent)."""
    pipeline.neutral_weights = None
    pipeline._neutral_rot = np.array([0.0, 0.0, 0.0, 1.0])
    pipeline._neutral_trans = None
    pipeline._capture = None
    pipeline._calib_pending = False
