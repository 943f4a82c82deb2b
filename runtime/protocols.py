"""The seams of the live path, as typing Protocols: what each part must offer the next.

A datagram becomes pixels through these parts, in this order (ARCHITECTURE.md, the frame walk):

==============  ==========================================================  ===============================
seam            what it does                                                implemented by
==============  ==========================================================  ===============================
InputAdapter    bytes of one datagram -> a completed Frame (or None)        runtime/inputs/{vmc,facecap,...}
FrameSource     the newest Frame by tick time, stale ones counted           runtime/inputs/udp*.py,
                (``latest`` has no side effects)                            runtime/recording/*_source.py
Stage           one step of the per-frame chain: (frame or None, t) ->      runtime/live/stages.py builds
                frame or None                                               the chain
Renderer        weights + head pose -> an image                             runtime/render/renderer.py
TickObserver    what the loop hands each drawn tick to: pictures, weights,  runtime/live/sinks.py,
                video, OSC outputs, the recorder, the live stats            runtime/session/outputs.py
==============  ==========================================================  ===============================
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from facepuppet.runtime.frames import Frame

if TYPE_CHECKING:
    from facepuppet.runtime.live.loop import TickInfo


@runtime_checkable
class InputAdapter(Protocol):
    """Decodes one tracker protocol. ``handle`` never raises: malformed input is counted in ``counters``."""

    kind: str  # the input kind (``vmc``, ``facecap``, ...): names the receive thread and bind errors
    default_port: int
    counters: dict[str, int]

    def handle(self, data: bytes, t: float) -> Frame | None:
        """The frame this datagram completes (receive time ``t``, seconds), or None."""
        ...


@runtime_checkable
class FrameSource(Protocol):
    """Answers once per tick: the newest frame that has arrived by ``t``, and how many older ones were skipped.

    ``latest`` is a snapshot: it has no side effects beyond marking the frame taken (no callbacks, no
    recording, no calibration). Live sources may also offer ``wait_for_frame(timeout_s) -> bool`` (draw on
    arrival), ``frames_taken``, ``watched`` (datagrams carrying the calibrate message, a count) and
    ``deliver_packets()`` (hand received datagrams to the recorder; called by the recording sink).
    """

    def latest(self, t: float) -> tuple[Frame | None, int]: ...


@runtime_checkable
class Stage(Protocol):
    """One step of the per-frame chain.

    Called once per tick with the newest new frame (None when none arrived, or the previous stage had
    nothing new) and the tick time ``t`` (seconds). Returns the frame for the next stage, or None to keep
    what is on screen. Runs on the frame-loop thread and must stay cheap; ``name`` is what the chain
    prints (``stages: vmc→filter→gestures→map→draw``).
    """

    name: str

    def __call__(self, frame: Frame | None, t: float) -> Frame | None: ...


@runtime_checkable
class Renderer(Protocol):
    """Draws channel values; ``shape_names`` are the channels it takes, in order."""

    path: str

    def draw(self, weights: np.ndarray, head_rotation: np.ndarray | None = None,
             head_translation: np.ndarray | None = None) -> None: ...

    def finish(self) -> None: ...

    def read_pixels(self) -> np.ndarray: ...

    def close(self) -> None: ...


@runtime_checkable
class TickObserver(Protocol):
    """Takes every drawn tick once the GPU is done with it: a :class:`~facepuppet.runtime.live.loop.TickInfo`
    (index, time, the new raw frame, the frame on screen, the weights and pose drawn, the stage stamps and
    the renderer, for pixels). The info object and its arrays are the loop's, reused next tick: copy to keep.
    Runs on the frame-loop thread: it must not block (hand slow work to a thread of its own)."""

    def __call__(self, info: TickInfo) -> None: ...
