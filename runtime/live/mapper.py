"""The ``map`` step: a frame's channels onto what the renderer draws, one cached map per channel layout.

A frame names its channels; the renderer draws a fixed list (the character's shapes, or the elastic path's
channels). The map between them depends only on the channel tuple, so it is built once per layout and kept
(at most :data:`MAX_CHANNEL_MAPS`; a sender whose layout keeps changing evicts the oldest). A character with
VRM expressions, or a ``[mapping]`` in the config, maps through an
:class:`~facepuppet.runtime.mapping.expressions.ExpressionDrive` (channels onto morphs and expressions); otherwise a
:class:`~facepuppet.runtime.mapping.channels.ChannelMap` by name.

One :class:`Mapper` per session: the frame loop maps with it every tick, the operator's panel reads from the
same cache what each input channel drives (its meters), and a ``[mapping]`` applied live
(:func:`follow_mapping`, a config listener on the session's bus) swaps the drive for both at once.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.mapping.channels import ChannelMap
from facepuppet.runtime.mapping.expressions import MappingError, MappingSettings, make_drive

if TYPE_CHECKING:
    from facepuppet.runtime.mapping.expressions import ExpressionDrive, ExpressionMap
    from facepuppet.runtime.model.character_parts import Expressions

logger = logging.getLogger(__name__)

MAX_CHANNEL_MAPS = 64  # channel maps cached (one per distinct channel tuple); the oldest goes first


class Mapper:
    """Channel layouts onto the renderer's channels, cached per layout.

    Parameters
    ----------
    names : sequence of str, the channels the renderer draws, in order (the maps' targets)
    drive : ExpressionDrive or None (:func:`~facepuppet.runtime.mapping.expressions.make_drive`); None: a plain
        ChannelMap by name, as for an OBJ rig
    log : callable taking one str; each layout's report goes here the first time the loop maps it

    Call :meth:`map_for` and :meth:`set_drive` on the frame loop's thread (the loop, a stage, the panel's
    overlay), so one tick maps with one drive throughout.
    """

    def __init__(self, names: Sequence[str], drive: ExpressionDrive | None = None,
                 log: Callable[[str], None] = logger.info) -> None:
        if isinstance(names, str) or not all(isinstance(n, str) for n in names):
            raise ValueError(f"Mapper names: expected a sequence of channel names, got {names!r}")
        self.names = tuple(names)
        self.log = log
        self.drive: ExpressionDrive | None = None
        self._maps: dict[tuple[str, ...], ChannelMap | ExpressionMap] = {}  # the loop's, reported
        self._quiet: dict[tuple[str, ...], ChannelMap | ExpressionMap] = {}  # asked for by the panel first
        self._first: dict[tuple[str, ...], tuple[np.ndarray, list[int]]] = {}
        self.set_drive(drive)

    def set_drive(self, drive: ExpressionDrive | None) -> None:
        """Map with ``drive`` from now on: each layout's map is built again at its next frame."""
        if drive is not None and tuple(drive.shape_names) != self.names:
            raise ValueError("Mapper drive: its shapes are not the renderer's channels")
        self.drive = drive
        self._maps.clear()
        self._quiet.clear()
        self._first.clear()

    def map_for(self, channels: tuple[str, ...], source: str = "",
                report: bool = True) -> ChannelMap | ExpressionMap:
        """The cached map of a channel tuple, built on first sight; with ``report`` (the loop's own use) its
        report is logged the first time. The loop's maps are one dictionary lookup per tick; a map the panel
        asked for first waits, unreported, until the loop maps that layout."""
        cmap = self._maps.get(channels)
        if cmap is not None:
            return cmap
        cmap = self._quiet.get(channels)
        if cmap is None:
            cmap = ChannelMap.build(channels, self.names) if self.drive is None else self.drive.build(channels)
        if not report:
            _bounded_put(self._quiet, channels, cmap)
            return cmap
        self._quiet.pop(channels, None)
        _bounded_put(self._maps, channels, cmap)
        n_driven = len(self.names) - len(cmap.undriven_target)
        head = (f"channel map ({source or 'source'}): {len(channels)} source channels -> "
                f"{n_driven} of {len(self.names)} rig shapes driven")
        text = cmap.report()
        self.log(head + ("\n" + text if text else "; every channel matched"))
        return cmap

    def first_targets(self, channels: tuple[str, ...]) -> tuple[np.ndarray, list[int]]:
        """For each channel of a layout the first thing it drives (-1: nothing), as an array and as a list of
        ints (read per row without NumPy): a shape index, or ``n_shapes + e`` for expression e (the panel's
        meters read the shapes' weights followed by the expressions' values)."""
        first = self._first.get(channels)
        if first is None:
            idx = self.map_for(channels, report=False).first_targets()
            first = (idx, idx.tolist())
            _bounded_put(self._first, channels, first)
        return first


def _bounded_put(cache: dict, key: tuple, value: object) -> None:
    """``cache[key] = value``, the oldest entry dropped past MAX_CHANNEL_MAPS (a sender whose channel set keeps
    changing)."""
    if len(cache) >= MAX_CHANNEL_MAPS:
        del cache[next(iter(cache))]
    cache[key] = value


def same_mapping(a: MappingSettings, b: MappingSettings) -> bool:
    """``[mapping]``s that map alike (how a file spelled the channels and where it was aside)."""
    return a.emotions == b.emotions and a.channels == b.channels


def follow_mapping(mapper: Mapper, expressions: Expressions | None,
                   log: Callable[[str], None] = logger.info) -> Callable[[float, object], None]:
    """A config listener (:meth:`~facepuppet.runtime.live.bus.SessionBus.on_config`): a config taking effect
    whose ``[mapping]`` differs from the one in force builds the drive again
    (:func:`~facepuppet.runtime.mapping.expressions.make_drive`) for the loop and the panel, from this tick's map on.
    A mapping naming what the character lacks is refused with a warning (the mapping in force stays)."""
    def hook(t: float, config) -> None:
        current = mapper.drive.mapping if mapper.drive is not None else MappingSettings()
        if same_mapping(config.mapping, current):
            return
        try:
            look_at = mapper.drive.look_at if mapper.drive is not None else None
            drive = make_drive(mapper.names, expressions, config.mapping, look_at)
        except MappingError as exc:
            log(f"mapping: warning: {exc}; the mapping in force stays")
            return
        mapper.set_drive(drive)
        log(f"mapping: {len(config.mapping.channels)} channel(s) of [mapping.channels] in force from t = {t:.3f} s")
    return hook
