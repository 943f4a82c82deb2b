"""Keep the live draw within its frame budget while the run goes on.

At start, a live run draws without MSAA on a software rasteriser and times a few frames on a GPU
(:mod:`~facepuppet.runtime.render.quality`). A machine can still get slower later (another program takes
the GPU, the window grows). :class:`DrawBudgetWatch` is a tick observer that keeps the draw times of the
last :data:`WINDOW` ticks (map done -> GPU finished) in a fixed ring; once the ring is full and their
median takes more than :data:`~facepuppet.runtime.render.quality.BUDGET_SHARE` of the frame budget, it
turns MSAA off, once, says so, and hands the new framebuffer to whoever draws into it (the panel).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.render.quality import budget_note

if TYPE_CHECKING:  # the renderer and the loop's tick: for the signatures only (moderngl is not imported here)
    from facepuppet.runtime.live.loop import TickInfo
    from facepuppet.runtime.render.renderer import FaceRenderer

#: Ticks whose draw times are weighed (the last ones; about 2 s at 60 fps).
WINDOW = 120


class DrawBudgetWatch:
    """A tick observer lowering MSAA once when the draw keeps missing its share of the frame budget.

    Parameters
    ----------
    renderer : FaceRenderer, drawing offscreen (``set_msaa``)
    budget_ms : float, the frame budget (1000 / fps)
    log : callable(str), told once what was lowered
    retarget : list of callable(fbo), told the new framebuffer (the panel's overlay is added once made)
    window : int, ticks weighed
    """

    def __init__(self, renderer: FaceRenderer, budget_ms: float, log: Callable[[str], None],
                 retarget: list[Callable] | None = None, window: int = WINDOW) -> None:
        self.renderer, self.budget_ms, self.log = renderer, float(budget_ms), log
        self.retarget = retarget if retarget is not None else []
        self._ms = np.zeros(int(window))
        self._n = 0
        self.lowered = False

    def __call__(self, info: TickInfo) -> None:
        if self.lowered:
            return
        self._ms[self._n % len(self._ms)] = (info.stamps[4] - info.stamps[2]) * 1e3
        self._n += 1
        if self._n < len(self._ms) or self._n % 10:  # a full window, weighed every 10 ticks
            return
        samples = self.renderer.samples
        note = budget_note(float(np.median(self._ms)), self.budget_ms, samples,
                           f"median of the last {len(self._ms)} ticks")
        if not note:
            return
        self.lowered = True  # once, whatever comes of it
        if self.renderer.set_msaa(0):
            for retarget in self.retarget:
                retarget(self.renderer.fbo)
            self.log(note)
