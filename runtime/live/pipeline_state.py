"""The filter stage's state as JSON: what a recording started mid-run carries so that its replay goes on as
the run did (the STATE record, :mod:`~facepuppet.runtime.recording.switch`).

:class:`RawState` is the stage's state copied cheaply once per tick (arrays copied where they change in
place); :func:`snapshot_doc` writes it as a JSON-able document (version 2: tracking state, the One Euro
filters' ``x_hat`` / ``dx_hat``, the last input frame's times, what was processed and shown, an ease in or
out, a neutral capture in progress); :func:`read_snapshot` checks a document from a file (a stranger's, as
any recording) field by field and gives the state back, or raises ValueError naming the field. Version 1
documents (live state only) are still read. Nothing here is unpickled: a snapshot is plain JSON.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from facepuppet.runtime.frames import Frame

SNAPSHOT_VERSION = 2
STATES = ("live", "returning", "lost")


class RawState(NamedTuple):
    """The filter stage's state (see :meth:`~facepuppet.runtime.live.pipeline.LivePipeline.state_snapshot`).

    Attributes
    ----------
    state : str, ``live``, ``returning`` or ``lost``
    channels : tuple of str, the layout the filters run on
    filters : three (x_hat, dx_hat) pairs of float64 arrays: weights (n,), rotation (4,), translation (3,)
    last_q : ndarray (4,) or None, the last rotation fed to the filter (its hemisphere)
    last_frame : Frame, the last accepted input frame (its times and number; the weights are not kept)
    last_tick : float, its tick time (s)
    live, out : (weights, rotation, translation) or None: the last input processed, what was last shown
    ease : (held, ease_start, loss_from, lost_done): the values an ease runs from and its times
    capture : dict or None, a neutral capture in progress (its running sums)
    calib_pending : bool, a calibration requested and not started
    """

    state: str
    channels: tuple
    filters: tuple
    last_q: np.ndarray | None
    last_frame: Frame
    last_tick: float
    live: tuple | None
    out: tuple | None
    ease: tuple
    capture: dict | None
    calib_pending: bool


def _float(x) -> float | None:
    """A float for JSON: None for NaN and infinities."""
    x = float(x)
    return x if math.isfinite(x) else None


def _floats(a: np.ndarray) -> list:
    return [_float(x) for x in np.asarray(a, np.float64).ravel()]


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _array(values, n: int, where: str) -> np.ndarray:
    """(n,) float64 from a JSON list (None: NaN); ValueError naming ``where`` otherwise."""
    if not isinstance(values, list) or len(values) != n or not all(v is None or _finite(v) for v in values):
        raise ValueError(f"pipeline state: '{where}' is not a list of {n} numbers")
    return np.array([math.nan if v is None else float(v) for v in values], np.float64)


def _parts(parts: tuple | None) -> list | None:
    """(weights, rotation, translation), each an array or None, for JSON."""
    return None if parts is None else [None if p is None else _floats(p) for p in parts]


def snapshot_doc(raw: RawState | None) -> dict | None:
    """The JSON-able document of a :class:`RawState` (None: none)."""
    if raw is None:
        return None
    held, ease_start, loss_from, lost_done = raw.ease
    last, capture = raw.last_frame, raw.capture
    return {
        "version": SNAPSHOT_VERSION, "state": raw.state, "channels": list(raw.channels),
        "filters": {name: [_floats(x), _floats(dx)] for name, (x, dx) in zip(("weights", "rotation",
                                                                             "translation"), raw.filters)},
        "last_q": None if raw.last_q is None else _floats(raw.last_q),
        "last_frame": {"t": float(last.t), "t_sender": _float(last.t_sender), "number": int(last.number),
                       "source": str(last.source), "weights": last.weights is not None},
        "last_tick": float(raw.last_tick), "live": _parts(raw.live), "out": _parts(raw.out),
        "held": _parts(held), "ease_start": float(ease_start), "loss_from": float(loss_from),
        "lost_done": bool(lost_done), "calib_pending": bool(raw.calib_pending),
        "capture": None if capture is None else {
            "t0": float(capture["t0"]), "n": int(capture["n"]), "ntr": int(capture["ntr"]),
            "channels": None if capture["channels"] is None else list(capture["channels"]),
            **{k: _floats(capture[k]) for k in ("w", "wn", "q", "tr")}},
    }


def _unparts(doc, n: int, where: str) -> tuple | None:
    if doc is None:
        return None
    if not isinstance(doc, list) or len(doc) != 3:
        raise ValueError(f"pipeline state: '{where}' is not [weights, rotation, translation]")
    return tuple(None if p is None else _array(p, k, f"{where}[{i}]") for i, (p, k) in enumerate(zip(doc, (n, 4, 3))))


def _capture_of(doc) -> dict | None:
    """A neutral capture in progress from its snapshot (None: none)."""
    if doc is None:
        return None
    if not isinstance(doc, dict) or not _finite(doc.get("t0")) or not isinstance(doc.get("n"), int) or \
            not isinstance(doc.get("ntr"), int):
        raise ValueError("pipeline state: 'capture' lacks its start, frame count or head count")
    names = doc.get("channels")
    if names is not None and (not isinstance(names, list) or not all(isinstance(c, str) for c in names)):
        raise ValueError("pipeline state: 'capture.channels' is not a list of names")
    k = len(names or ())
    return {"t0": float(doc["t0"]), "n": doc["n"], "ntr": doc["ntr"],
            "channels": None if names is None else tuple(names),
            **{key: _array(doc.get(key), m, f"capture.{key}") for key, m in (("w", k), ("wn", k), ("q", 4), ("tr", 3))}}


def read_snapshot(doc: object) -> RawState:
    """The state of a snapshot document (version 1 or 2), every field checked; ValueError naming the first
    field that is not what :func:`snapshot_doc` writes."""
    if not isinstance(doc, dict) or doc.get("version") not in (1, 2):
        raise ValueError("pipeline state: expected a version 1 or 2 snapshot")
    v2 = doc["version"] == 2
    state = doc.get("state") if v2 else "live"
    if state not in STATES:
        raise ValueError("pipeline state: 'state' is not live, returning or lost")
    channels = doc.get("channels")
    if not isinstance(channels, list) or not all(isinstance(c, str) for c in channels):
        raise ValueError("pipeline state: 'channels' is not a list of names")
    channels = tuple(channels)
    n = len(channels)
    filters = doc.get("filters")
    if not isinstance(filters, dict):
        raise ValueError("pipeline state: 'filters' missing")
    states = []
    for name, size in (("weights", n), ("rotation", 4), ("translation", 3)):
        pair = filters.get(name)
        if not isinstance(pair, list) or len(pair) != 2:
            raise ValueError(f"pipeline state: 'filters.{name}' is not [x_hat, dx_hat]")
        states.append((_array(pair[0], size, f"filters.{name}"), _array(pair[1], size, f"filters.{name}")))
    last_q = None if doc.get("last_q") is None else _array(doc["last_q"], 4, "last_q")
    last = doc.get("last_frame")
    if not isinstance(last, dict) or not _finite(last.get("t")) or not isinstance(last.get("number"), int):
        raise ValueError("pipeline state: 'last_frame' lacks its time and number")
    if not _finite(doc.get("last_tick")):
        raise ValueError("pipeline state: 'last_tick' is not a number")
    live = _unparts(doc.get("live"), n, "live")
    out = _unparts(doc.get("out"), n, "out")
    held, ease, capture, pending = None, (0.0, 0.0, False), None, False
    if v2:
        held = _unparts(doc.get("held"), n, "held")
        for key in ("ease_start", "loss_from"):
            if not _finite(doc.get(key)):
                raise ValueError(f"pipeline state: '{key}' is not a number")
        if not isinstance(doc.get("lost_done"), bool) or not isinstance(doc.get("calib_pending"), bool):
            raise ValueError("pipeline state: 'lost_done' and 'calib_pending' must be true or false")
        if state != "live" and out is None:
            raise ValueError(f"pipeline state: '{state}' needs 'out', what was shown")
        ease = (float(doc["ease_start"]), float(doc["loss_from"]), doc["lost_done"])
        capture, pending = _capture_of(doc.get("capture")), doc["calib_pending"]
    frame = Frame(t=float(last["t"]), source=str(last.get("source", "")),
                  channels=channels if last.get("weights") else None,
                  weights=np.full(n, np.nan) if last.get("weights") else None,
                  t_sender=float(last["t_sender"]) if _finite(last.get("t_sender")) else math.nan,
                  number=int(last["number"]))
    return RawState(state, channels, tuple(states), last_q, frame, float(doc["last_tick"]), live, out,
                    (held, *ease), capture, pending)
