"""The shared-memory block between :mod:`~facepuppet.runtime.inputs.udp_process` and its child.

One block per receiver (:class:`SharedBlock` lays it out): control words (int64, indices below), the
newest frame's times / pose / weights / markers (the seqlock slot), the child's counters, a ring of names (records
``u32 length | JSON [kind, value]`` for channel tuples, marker names and sources, each known by its absolute
position in the ring, which is never reused, so old layouts are overwritten and the ring never fills), an
append-only log of counter names and errors (``u32 length | JSON [kind, key, value]``, bounded by
MAX_COUNTERS and MAX_ERRORS_LOGGED), and a ring of accepted datagrams
(records :data:`RECORD` ``u32 length | f64 receive time | u16 sender port | u8 host length | pad``,
then the host and the bytes, each record padded to 16 bytes; a length of :data:`WRAP` skips to the
ring's start). The parent reads, the child writes; ordering relies on stores becoming visible in
program order (x86-64's model).
"""

from __future__ import annotations

import struct
from multiprocessing import shared_memory

import numpy as np

MAX_WEIGHTS = 1024
MAX_MARKERS = 2048
MAX_COUNTERS = 64
NAMES_BYTES = 1 << 20
META_BYTES = 1 << 18  # counter names and errors
MAX_NAME_RECORD = NAMES_BYTES // 4  # a bigger name record is refused (counted names_too_large)
RELOG_AFTER = NAMES_BYTES // 4  # the child writes a name again once this many bytes were written after it
VALID_FOR = NAMES_BYTES // 2  # the parent trusts a record while fewer bytes than this were written after it
RING_BYTES = 4 << 20
MAX_ERRORS_LOGGED = 100  # the child logs at most this many errors (the meta log)
# control words (int64)
SEQ, COMPLETED, NAMES_END, RING_W, RING_R, READY, STOP, N_WEIGHTS, N_MARKERS, CHANNELS, MARKER_NAMES, SOURCE, \
    NUMBER, FLAGS, WATCHED, META_END, N_CTL = range(17)
HAS_WEIGHTS, HAS_MARKERS, HAS_ROTATION, HAS_TRANSLATION = 1, 2, 4, 8
RECORD = struct.Struct("<IdHBx")  # datagram length, receive time, sender port, sender host length (16 bytes)
WRAP = 0xFFFFFFFF
NAME = struct.Struct("<I")


class SharedBlock:
    """Views of the shared block: control words, times, pose, counters, weights, markers, names ring, meta log,
    datagram ring."""

    def __init__(self, shm: shared_memory.SharedMemory, ring_bytes: int) -> None:
        self.shm = shm
        self.ring_bytes = ring_bytes
        buf = shm.buf
        o = 0

        def take(n_bytes):
            nonlocal o
            view = buf[o:o + n_bytes]
            o += n_bytes
            return view

        self.ctl = take(8 * N_CTL).cast("q")
        self.times = np.frombuffer(take(8 * 3), dtype=np.float64)  # t, t_sender, audio_level
        self.pose = np.frombuffer(take(4 * 8), dtype=np.float32)  # rotation (4), translation (3), pad
        self.counters = take(8 * MAX_COUNTERS).cast("q")
        self.weights = np.frombuffer(take(4 * MAX_WEIGHTS), dtype=np.float32)
        self.markers = np.frombuffer(take(4 * 3 * MAX_MARKERS), dtype=np.float32)
        self.names = take(NAMES_BYTES)
        self.meta = take(META_BYTES)
        self.ring = take(ring_bytes)

    @staticmethod
    def size(ring_bytes: int) -> int:
        return (8 * N_CTL + 24 + 32 + 8 * MAX_COUNTERS + 4 * MAX_WEIGHTS + 12 * MAX_MARKERS + NAMES_BYTES + META_BYTES
                + ring_bytes)

    def release(self) -> None:
        for name in ("ctl", "counters", "names", "meta", "ring"):
            getattr(self, name).release()
        self.times = self.pose = self.weights = self.markers = None


def padded(n: int) -> int:
    """``n`` rounded up to a multiple of 16 (ring records are 16-byte aligned)."""
    return (n + 15) & ~15
