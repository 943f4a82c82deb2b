"""The Filter section: the One Euro filter's min cutoff and beta per region (``[filters]``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from facepuppet.runtime.live.config import LiveConfig
    from facepuppet.runtime.panel.ui import Ui

WEIGHT_REGIONS = ("eyes", "brows", "mouth", "other", "head")
#: per region: the ImGui ids of its two sliders and their rect labels (made once)
_FILTER_LABELS = {r: (f"##cutoff.{r}", f"##beta.{r}", f"filter.{r}.min_cutoff", f"filter.{r}.beta")
                  for r in WEIGHT_REGIONS}


def filter_section(ui: Ui, config_now: Callable[[], LiveConfig]) -> LiveConfig | None:
    """Two sliders per region; the config with the one dragged changed, or None."""
    imgui = ui.imgui
    if not imgui.collapsing_header("Filter (One Euro)", imgui.TreeNodeFlags_.default_open):
        return None
    config = config_now()
    filters = dict(config.filters)
    changed = False
    slider, same_line, remember, log = imgui.slider_float, imgui.same_line, ui.remember, \
        imgui.SliderFlags_.logarithmic
    imgui.push_item_width(130)  # one width for the section's sliders, not one call per slider
    for region, (cutoff_id, beta_id, cutoff_rect, beta_rect) in _FILTER_LABELS.items():
        fs = filters[region]
        c1, cutoff = slider(cutoff_id, fs.min_cutoff, 0.05, 10.0, "%.2f Hz", log)
        remember(cutoff_rect)
        same_line()
        c2, beta = slider(beta_id, fs.beta, 0.0, 5.0, "beta %.2f")
        remember(beta_rect)
        same_line()
        imgui.text_unformatted(region)
        if c1 or c2:
            # only the value dragged changes: ImGui hands back float32, the other keeps its exact value
            filters[region] = replace(fs, min_cutoff=max(float(cutoff), 1e-3) if c1 else fs.min_cutoff,
                                      beta=max(float(beta), 0.0) if c2 else fs.beta)
            changed = True
    imgui.pop_item_width()
    return replace(config, filters=filters) if changed else None
