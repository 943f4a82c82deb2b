"""The ``voice`` stage: the learned mouth channels sampled once per tick, and where they go.

:class:`VoiceStage` runs right after the ``audio`` tap: it takes the tick's channels from its source (a
:class:`~facepuppet.runtime.voice.source.WavVoice` or ``MicVoice``, or in a replay the channels the live run
recorded, :class:`RecordedVoice`) and keeps them as :attr:`VoiceStage.values`, which the recorder writes, so
a replay of the same ticks hands every later stage the same numbers. Where they go (``--voice-mode``):

* ``loss`` (default): only while the tracker is lost, in the regions whose ``[tracking_loss]`` mode is
  ``voice``: ``mouth = "voice"`` is the learned mouth, not the level's jaw (the filter stage's generator);
* ``hybrid``: the tracker drives everything but the mouth: after the filter, :class:`HybridMouth` puts the
  voice's channels in place of the tracker's;
* with the voice alone (``run --input audio``) the stage makes the frame itself;
* with several inputs (``--input X --input audio``) the ``audio`` mix source gives the voice's channels, and
  ``[mix]`` orders decide per channel.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.mapping.channels import canonical

if TYPE_CHECKING:
    from facepuppet.runtime.voice.source import MicVoice, WavVoice

VOICE_MODES = ("loss", "hybrid")
VOICE = "voice"


class RecordedVoice:
    """The voice channels a live recording kept, one row per tick time: a source for :class:`VoiceStage`."""

    def __init__(self, outputs: tuple[str, ...], rows: Iterable[tuple[float, np.ndarray]]) -> None:
        self.outputs = tuple(outputs)
        self._by_t = {float(t): np.asarray(v, np.float32) for t, v in rows}

    def channels(self, t: float) -> np.ndarray | None:
        return self._by_t.get(float(t))

    def __len__(self) -> int:
        return len(self._by_t)


class VoiceStage:
    """The ``voice`` stage (see the module docstring).

    Parameters
    ----------
    source : has ``outputs`` (tuple of ARKit names) and ``channels(t) -> ndarray (n_outputs,) or None``
    make_frame : bool, with the voice alone: a tick without a frame gets the voice's frame
    path : str, the ``--voice`` file
    """

    name = "voice"

    def __init__(self, source: WavVoice | MicVoice | RecordedVoice, make_frame: bool = False, path: str = "") -> None:
        self.source = source
        self.path = path  # the --voice file (the panel names it and saves a re-calibration over it)
        self.outputs = tuple(source.outputs)
        self.make_frame = make_frame
        self.values: np.ndarray | None = None

    def __call__(self, frame: Frame | None, t: float) -> Frame | None:
        v = self.source.channels(t)
        self.values = None if v is None else np.asarray(v, np.float32)
        if frame is None and self.make_frame:
            return self.frame(t)
        return frame

    def frame(self, t: float) -> Frame | None:
        """The tick's channels as a frame of their own (None before the first)."""
        if self.values is None:
            return None
        return Frame(t=t, source=VOICE, channels=self.outputs, weights=self.values.copy())


class HybridMouth:
    """The ``hybrid`` stage: the voice's channels replace the tracker's mouth channels of the same names
    (channels the frame lacks are added); the rest of the face stays the tracker's, its last frame on a tick
    without a new one."""

    name = "hybrid"

    def __init__(self, voice: VoiceStage) -> None:
        self.voice = voice
        self._maps: dict = {}
        self._last: Frame | None = None

    def __call__(self, frame: Frame | None, t: float) -> Frame | None:
        if frame is not None and frame.weights is not None:
            self._last = frame
        elif frame is None and self._last is not None:
            frame = self._last  # a tick without a new frame: the tracker's face holds, the voice's mouth moves on
        values = self.voice.values
        if values is None:
            return frame
        if frame is None or frame.weights is None:
            return self.voice.frame(t) if frame is None else frame
        channels, at = self._map(frame.channels)
        weights = np.zeros(len(channels), np.float32)
        weights[:len(frame.weights)] = frame.weights
        weights[at] = values
        return Frame(t=frame.t, source=frame.source, channels=channels, weights=weights,
                     head_rotation=frame.head_rotation, head_translation=frame.head_translation,
                     audio_level=frame.audio_level, t_sender=frame.t_sender, number=frame.number)

    def _map(self, channels: tuple[str, ...]) -> tuple[tuple[str, ...], np.ndarray]:
        cached = self._maps.get(channels)
        if cached is None:
            index = {canonical(c): i for i, c in enumerate(channels)}
            out = list(channels)
            at = []
            for name in self.voice.outputs:
                i = index.get(canonical(name))
                if i is None:
                    i = len(out)
                    out.append(name)
                at.append(i)
            cached = self._maps[channels] = (tuple(out), np.array(at, np.intp))
        return cached


def with_voice(voice: VoiceStage, other: Callable[[float], Frame | None] | None = None
               ) -> Callable[[float], Frame | None]:
    """The filter's loss generator: the voice's channels, over the face of ``other`` (the gesture layer's) if any."""
    def generate(t: float) -> Frame | None:
        base = other(t) if other is not None else None
        mine = voice.frame(t)
        if mine is None or base is None or base.weights is None:
            return mine if mine is not None else base
        index = {canonical(c): i for i, c in enumerate(base.channels)}
        channels, weights = list(base.channels), list(np.asarray(base.weights, np.float64))
        for name, v in zip(mine.channels, mine.weights):
            i = index.get(canonical(name))
            if i is None:
                channels.append(name)
                weights.append(float(v))
            else:
                weights[i] = float(v)
        return Frame(t=t, source=base.source, channels=tuple(channels), weights=np.array(weights, np.float32),
                     head_rotation=base.head_rotation, head_translation=base.head_translation)
    return generate

