"""A run's recording that starts and stops while the run goes on (the panel's Record and Stop).

``run`` wires one :class:`SwitchableRecorder` into the receiver (``on_packet``), the tick hook
(:class:`~facepuppet.runtime.live.sinks.RecordingHook`), the config listener and the event listener
when it starts; each of them always calls it, and it hands the call on to the
:class:`~facepuppet.runtime.recording.recorder.PacketRecorder` in force, or drops it when none is.
``--record FILE`` opens the first recording before the receiver starts; :meth:`SwitchableRecorder.start`
opens another at any tick (a new file, never an existing one), :meth:`SwitchableRecorder.stop` closes
the one in force on a background thread (the writer's queue written, fsync, close), so neither holds the
tick for more than opening a file.

A recording started during a run must replay like one made from the start. Its TICK records say how many
frames the source had completed when each tick took its snapshot; a replay counts the frames its own
packets decode to. So the first frames of the run, whose packets went by before the recording started,
are taken off: until a tick takes a frame whose packet was recorded, the recording decodes its own packets
with a fresh adapter of the input kind (as ``replay`` does; a few datagrams) and the tick that takes the
first recorded frame, found by its receive time, fixes the offset; TICK records before it say "no frame
yet". The filter stage's state before that tick (its filters' history, the last frame's times, what it
drew, an ease in or a neutral capture in progress) is the STATE record written with it, and a replay goes
on from it, so from that frame on it draws what the run drew. A recording started while tracking is lost
takes the state before its first tick instead (no frames come while lost), so its replay follows the voice
and the idle motion, the ease out and then the ease in as the run did, from its first tick. The gesture
layer's state (``--gestures``) is not kept: its first moments may differ.
The config in force is the header's (``info.config``) and the first CONFIG record.
"""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from facepuppet.runtime.errors import UsageError

if TYPE_CHECKING:
    import numpy as np

    from facepuppet.runtime.frames import Frame
    from facepuppet.runtime.protocols import InputAdapter
    from facepuppet.runtime.recording.recorder import PacketRecorder

EXTENSION = ".fps"  # the project's session files
ALIGN_PACKETS = 4096  # datagrams kept while a recording started mid-run looks for its first frame


def default_name(when: float | None = None) -> str:
    """``facepuppet-YYYYmmdd-HHMMSS.fps`` of the local time ``when`` (default now)."""
    return time.strftime("facepuppet-%Y%m%d-%H%M%S", time.localtime(when)) + EXTENSION


class _Totals(Mapping):
    """The ``record`` counter group: every recording's counters added up, plus ``recordings``."""

    def __init__(self, owner: SwitchableRecorder) -> None:
        self._owner = owner

    def _values(self) -> dict:
        o = self._owner
        with o._lock:
            values = dict(o._done)
            live = [r.counters for r in (o._recorder, *o._closing_recorders) if r is not None]
        for counters in live:
            for k, v in dict(counters).items():
                values[k] = values.get(k, 0) + v
        values["recordings"] = o.recordings
        values["record_failed"] = o.failed
        return values

    def __getitem__(self, key: str) -> int:
        return self._values()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._values())

    def __len__(self) -> int:
        return len(self._values())


class _Aligner:
    """Finds how many of the run's frames a recording started mid-run lacks (see the module docstring)."""

    def __init__(self, adapter: InputAdapter | None, base: int | None = None) -> None:
        self.adapter = adapter
        self.base = base  # None until found
        # recorded datagrams not decoded yet (bounded); a deque: the receive thread appends while the frame loop
        # takes them off (a receiver thread's on_packet), each end atomic
        self.packets: collections.deque[tuple[bytes, float]] = collections.deque()
        # (index, receive time) of the frames the recorded datagrams decoded to so far (the newest, bounded)
        self.times: collections.deque[tuple[int, float]] = collections.deque(maxlen=ALIGN_PACKETS)
        self.decoded = 0

    def keep(self, data: bytes, t: float) -> None:
        if self.base is None and len(self.packets) < ALIGN_PACKETS:
            self.packets.append((data, t))

    def frames(self, frames_taken: int, raw: Frame | None) -> int:
        """The TICK record's frame count for a tick that took ``raw`` (None: none new) with the source at
        ``frames_taken``."""
        if self.base is None:
            if raw is None or self.adapter is None:
                return 0
            packets = self.packets
            while packets:
                data, t = packets.popleft()
                try:
                    frame = self.adapter.handle(data, t)
                except Exception:  # the replay's adapter counts and skips what it cannot decode: so do we
                    frame = None
                if frame is not None:
                    self.times.append((self.decoded, frame.t))
                    self.decoded += 1
            found = [i for i, t in self.times if t == raw.t]
            if not found:
                return 0  # the frame taken came from a datagram before the recording
            self.base = frames_taken - (found[-1] + 1)
            self.times.clear()
        return max(frames_taken - self.base, 0)


class SwitchableRecorder:
    """The run's recording: started and stopped at any tick; a no-op while none is in force.

    Parameters
    ----------
    open_recorder : callable(path) -> PacketRecorder, opens a recording with the run's header info (computed
        when called: the config in force then)
    directory : Path, where recordings named by default go (the ``--record`` file's folder, else the
        current one)
    make_adapter : callable() -> InputAdapter or None, a fresh adapter of the run's input kind (as
        ``replay`` decodes), to align a recording started mid-run; None: frames are counted from the start
    frames_taken : callable() -> int, the source's frame count (the base of a recording of a source
        without datagrams, ``--input audio``)
    pipeline : LivePipeline or None, the run's filter stage: a recording started mid-run takes its state
        before the tick of the first recorded frame (its ``keep_snapshots`` / ``before_tick``) as a STATE record
    refuse_midrun : str, why a recording cannot start once the run ticks ("" when it can: a run with several
        inputs says so, their frame counts are not aligned)
    clock : callable() -> seconds since the epoch, for default names (injectable for tests)
    log : callable(str) or None, told each start and stop, and a failed write
    on_failure : callable() or None, called (on the recorder's writer thread) when a recording's write fails:
        ``run`` stops then, so that a run never goes on as if it were recorded

    Attributes
    ----------
    path : Path or None, the recording in force, else the last one (None before any)
    recording : bool
    counters : the ``record`` counter group (all recordings of the run, ``recordings``, ``record_failed``)
    message : str, what the last start / stop did or why it failed (the panel shows it)
    failure : str or None, the first recording whose writes failed: what its file keeps
        (:attr:`PacketRecorder.failure`); None while every write succeeded
    """

    def __init__(self, open_recorder: Callable[[Path], PacketRecorder], directory: Path | None = None, *,
                 make_adapter: Callable[[], InputAdapter] | None = None,
                 frames_taken: Callable[[], int] | None = None, refuse_midrun: str = "",
                 pipeline: Any = None,
                 clock: Callable[[], float] = time.time, log: Callable[[str], None] | None = None,
                 on_failure: Callable[[], None] | None = None) -> None:
        self.open_recorder = open_recorder
        self.directory = Path(directory) if directory is not None else Path(".")
        self.make_adapter = make_adapter
        self.frames_taken = frames_taken
        self.refuse_midrun = refuse_midrun
        self.pipeline = pipeline
        if pipeline is not None:
            pipeline.keep_snapshots = True  # its state before each tick: a start's first recorded frame may be
            # the very tick's (a process receiver's datagrams reach the recorder at the tick hook)
        self._state_due = False
        self.clock = clock
        self.log = log
        self.on_failure = on_failure
        self.failure: str | None = None
        self.path: Path | None = None
        self.recordings = 0
        self.failed = 0
        self.message = ""
        self.last_t = 0.0  # the newest tick time seen (the time of a start's first CONFIG)
        self.ticks_seen = 0
        self._recorder: PacketRecorder | None = None
        self._align: _Aligner | None = None
        self._tagged: dict[str, Callable[..., None]] = {}
        self._lock = threading.Lock()
        self._done: dict[str, int] = {}
        self._closing: list[threading.Thread] = []
        self._closing_recorders: list[PacketRecorder] = []
        self.counters = _Totals(self)

    @property
    def recording(self) -> bool:
        return self._recorder is not None

    @property
    def recorder(self) -> PacketRecorder | None:
        return self._recorder

    # -- start / stop ------------------------------------------------------------------------------

    def next_path(self, name: str = "") -> Path:
        """Where a start with ``name`` ("" or blank: the default name) records: a bare name goes into
        :attr:`directory`, ``.fps`` is added when there is no suffix; a default name taken already gets
        ``-2``, ``-3``..."""
        name = name.strip()
        if name:
            path = Path(name).expanduser()
            if not path.suffix:
                path = path.with_suffix(EXTENSION)
            return path if path.is_absolute() or path.parent != Path(".") else self.directory / path
        stem = default_name(self.clock())[:-len(EXTENSION)]
        path, n = self.directory / (stem + EXTENSION), 1
        while path.exists():
            n += 1
            path = self.directory / f"{stem}-{n}{EXTENSION}"
        return path

    def start(self, name: str | Path = "", config_text: str | None = None) -> Path:
        """Open a new recording (stopping the one in force first) and make it the one in force.

        ``config_text``: the config in force (TOML), written as the first CONFIG record at the newest tick
        time. Raises OSError (the file exists, the folder cannot be written) or ValueError; the run goes on.
        """
        if self.ticks_seen > 0 and self.refuse_midrun:
            self.failed += 1
            self.message = f"record: {self.refuse_midrun}"
            raise UsageError(self.message)
        path = self.next_path(str(name)) if not isinstance(name, Path) else name
        if self._recorder is not None:
            self.stop()
        try:
            recorder = self.open_recorder(path)
        except (OSError, ValueError) as exc:
            self.failed += 1
            self.message = f"record: cannot start {path}: {exc}"
            if self.log is not None:
                self.log(f"run: {self.message}")
            raise
        recorder.on_failure = self._failed
        midrun = self.ticks_seen > 0
        if not midrun:
            align = _Aligner(None, base=0)
        elif self.make_adapter is not None:
            align = _Aligner(self.make_adapter())
        else:  # no datagrams to decode: count from the frames the source has now
            align = _Aligner(None, base=int(self.frames_taken()) if self.frames_taken is not None else 0)
        if config_text is not None:
            recorder.put_config(self.last_t, config_text)
        self._state_due = midrun and self.pipeline is not None and align.base is None
        self._align = align
        self._tagged = {}
        self.path = Path(recorder.path)
        self.recordings += 1
        self._recorder = recorder  # from here on every hook hands its records to it
        self.message = f"recording to {self.path}"
        if self.log is not None and midrun:
            self.log(f"run: {self.message}")
        return self.path

    def stop(self) -> Path | None:
        """Stop the recording in force (its file completed on a background thread; :meth:`close` waits)."""
        recorder, self._recorder = self._recorder, None
        self._state_due = False  # (stopped before its first recorded frame)
        if recorder is None:
            return None
        self._align = None
        self._tagged = {}
        with self._lock:
            self._closing = [t for t in self._closing if t.is_alive()]
            self._closing_recorders.append(recorder)
        thread = threading.Thread(target=self._finish, args=(recorder,), name="facepuppet-record-close")
        self._closing.append(thread)
        thread.start()
        self.message = f"stopped {recorder.path}"
        if self.log is not None:
            self.log(f"run: recording {self.message}")
        return Path(recorder.path)

    def _failed(self, recorder: PacketRecorder) -> None:
        """A write of ``recorder`` failed (its writer thread, or its close): say what the file keeps, stop the
        run."""
        with self._lock:
            first = self.failure is None
            if first:
                self.failure = recorder.failure
            self.failed += 1
        self.message = f"record: {recorder.failure}"
        if self.log is not None:
            self.log(f"run: {self.message}" + ("; the run stops" if self.on_failure is not None else ""))
        if first and self.on_failure is not None:
            self.on_failure()

    def _finish(self, recorder: PacketRecorder) -> None:
        recorder.close()  # a failure on close is told to _failed too
        with self._lock:
            for k, v in recorder.counters.items():
                self._done[k] = self._done.get(k, 0) + v
            self._closing_recorders.remove(recorder)

    def wait_closed(self, timeout_s: float | None = None) -> None:
        """Wait until every stopped recording's file is complete."""
        for thread in list(self._closing):
            thread.join(timeout_s)

    def close(self) -> None:
        """Stop (the file of the recording in force completed) and wait for every file."""
        self.stop()
        self.wait_closed()

    # -- what the run's parts call ---------------------------------------------------------------

    def put(self, data: bytes, t_receive: float, sender: tuple | None = None) -> None:
        r = self._recorder
        if r is not None:
            align = self._align
            if align is not None and align.base is None:
                align.keep(data, t_receive)
            r.put(data, t_receive, sender)

    def tagged(self, label: str) -> Callable[..., None]:
        """An ``on_packet`` of another input of the run (see :meth:`PacketRecorder.tagged`)."""
        def put(data: bytes, t_receive: float, sender: tuple | None = None) -> None:
            r = self._recorder
            if r is None:
                return
            fn = self._tagged.get(label)
            if fn is None:
                fn = self._tagged[label] = r.tagged(label)
            fn(data, t_receive, sender)
        return put

    def put_audio(self, t: float, level_db: float) -> None:
        r = self._recorder
        if r is not None:
            r.put_audio(t, level_db)

    def put_voice(self, t: float, values: np.ndarray) -> None:
        r = self._recorder
        if r is not None:
            r.put_voice(t, values)

    def tick_frames(self, frames_taken: int, raw: Any) -> int:
        """The frame count a TICK record stores for this tick (see the module docstring). The filter stage's
        state before a tick is written as a STATE record (before this tick's TICK): at the recording's first
        tick when tracking was lost then, else at the tick that took the first recorded frame."""
        align = self._align
        if align is None:
            return frames_taken
        if self._state_due and self.pipeline.before_tick_state == "lost":
            self._write_state()  # no frames come while lost: every recorded tick goes on from the state then
        aligned = align.base is not None
        frames = align.frames(frames_taken, raw)
        if not aligned and align.base is not None and self._state_due:
            self._write_state()
        return frames

    def _write_state(self) -> None:
        import json

        self._state_due = False
        snapshot = self.pipeline.before_tick
        recorder = self._recorder
        if snapshot is not None and recorder is not None:
            recorder.put_state(self.last_t, json.dumps(snapshot, allow_nan=False))

    def put_tick(self, k: int, t: float, frames: int, t_clock: float) -> None:
        r = self._recorder
        if r is not None:
            r.put_tick(k, t, frames, t_clock)

    def saw_tick(self, t: float) -> None:
        """The tick hook's note of each tick (recording or not): the time a start's first CONFIG gets."""
        self.last_t = t
        self.ticks_seen += 1

    def put_sources(self, k: int, frames: tuple[int, ...]) -> None:
        r = self._recorder
        if r is not None:
            r.put_sources(k, frames)

    def put_config(self, t: float, text: str) -> None:
        r = self._recorder
        if r is not None:
            r.put_config(t, text)

    def put_control(self, t: float, command: dict) -> None:
        r = self._recorder
        if r is not None:
            r.put_control(t, command)

    def put_event(self, t: float, found: bool) -> None:
        r = self._recorder
        if r is not None:
            r.put_event(t, found)
