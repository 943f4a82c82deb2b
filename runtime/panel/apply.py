"""How the panel hands a config change to the pipeline.

The contract (issue 15): :meth:`LivePipeline.apply_config` takes a whole ``LiveConfig`` and applies it at
the next tick without a pause; its ``neutral`` becomes the neutral in force (None clears it). So every
edit starts from :meth:`LivePipeline.current_config` (the config in force with the captured neutral), never
from an older copy, or an edit would drop a neutral captured since.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from facepuppet.runtime.live.config import LiveConfig
    from facepuppet.runtime.live.pipeline import LivePipeline


def config_in_force(pipeline: LivePipeline) -> LiveConfig:
    """The config to edit: the one in force, with its neutral."""
    return pipeline.current_config()


def apply_config(pipeline: LivePipeline | None, config: LiveConfig) -> None:
    """Hand ``config`` to the pipeline (applied at its next tick)."""
    if pipeline is not None:
        pipeline.apply_config(config)


def clear_calibration(pipeline: LivePipeline) -> None:
    """Drop the neutral (weights, rotation and translation as sent from the next tick)."""
    pipeline.apply_config(replace(pipeline.current_config(), neutral=None))
