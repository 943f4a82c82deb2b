"""``--vmc-out HOST:PORT``: the character's weights and head pose sent as VMC (PROTOCOLS.md §1).

Every tick sends, over one UDP socket, bundles of at most ``max_bundle`` bytes
(1,200, as VirtualMotionCapture does), each a complete OSC bundle:

1. the status bundle: ``/VMC/Ext/OK i loaded i calibState i calibMode i
   tracking`` (V2.7's four ints: loaded 1, the character is loaded before the
   first tick; calibState 3 "calibrated", 2 "calibrating" while facepuppet
   captures the neutral pose; calibMode 0 normal; tracking 1 while the run's
   tracking state is live, 0 before the first frame and while tracking is lost
   and the face eases to neutral: see :func:`pipeline_status`),
   ``/VMC/Ext/T f seconds`` (since the sender started: the sender's relative
   time, a sign of life), ``/VMC/Ext/Root/Pos s "root"`` at the origin, and
   ``/VMC/Ext/Bone/Pos s "Head" f px py pz qx qy qz qw``. OK and T go out
   every tick: the marionette spec marks only the Light, VRM, Remote, Option,
   Setting and Config messages as low-frequency, and a performer's
   ``/VMC/Ext/Set/Period`` status interval counts in frames;
2. the blend bundles, ``/VMC/Ext/Blend/Val s Name f value`` each:

   * the 52 ARKit shapes, every tick, in the PascalCase of perfect sync
     (``EyeBlinkLeft`` … ``TongueOut``), the rig's channels folded into them as
     :func:`facepuppet.runtime.mapping.vrm_names.fold_to_arkit` says (split
     ``browInnerUp_L/_R`` by their max; a shape the rig lacks is 0);
   * the 17 VRM 0.x presets (``Blink``, ``Blink_L``, ``Blink_R``, ``A`` …
     ``O``, ``Joy``, ``LookUp`` …, ``Neutral``) derived from those 52 by
     :func:`facepuppet.runtime.mapping.vrm_names.vrm0_from_arkit`;
   * with ``extra=True`` (``--vmc-extra``), the rig's channels outside ARKit
     (``CheekRaiserLeft``, ``PupilDilateRight``) under their PascalCase names;

   **The avatar's own names** (``--vmc-names``, for a character with VRM expressions):
   ``expressions`` gives the names of its expressions, each sent with the
   value the avatar showed this tick (after isBinary and overrides; the
   frame loop's :attr:`TickInfo.expressions`) — a preset under its VRM 0.x
   name as the VMC spec asks (``Blink``, ``Blink_L``, ``A``, ``Joy``), a
   custom expression under its own name. ``names="both"`` (the default) sends
   the 52 ARKit shapes and the avatar's expressions *instead of* the 17
   presets derived from ARKit, ``"vrm"`` only the expressions, ``"arkit"``
   what an OBJ rig sends (the 52 and the derived presets). ``both`` is the
   default because it is what makes VSeeFace move the same avatar out of the
   box: VSeeFace applies each received name to the avatar's blend shape clip
   of that name, so a VRM 0.x avatar reacts to its presets and a perfect-sync
   one to the 52 (a shape the 52 drive directly is not also driven through an
   expression by facepuppet's map, so nothing closes twice). For a character
   without expressions every mode but ``vrm`` sends what it always did, and
   ``vrm`` sends the derived presets;

   split greedily over as many bundles as keep each within ``max_bundle``,
   with one ``/VMC/Ext/Blend/Apply`` at the end of the last.

Values are clipped to [0, 1] (a BlendShapeProxy value); NaN is sent as 0.

The bundles are built once with python-osc's builders (time tag "immediately")
and only the big-endian float32 argument bytes are patched per tick, so a tick
costs one ``struct.pack_into`` per value and one ``send`` per bundle.

**Socket.** Connected to the destination at start: the kernel binds it to the local address that
routes there (the loopback for 127.0.0.1), never to 0.0.0.0, and drops whatever comes from anyone else.

**Axes.** Ours are right-handed, x to the character's left; VMC's are Unity's
(left-handed, x to the avatar's right): a position (x, y, z) is sent as
(-x, y, z) and a rotation (x, y, z, w) as (x, -y, -z, w), the mirror the VMC
input applies the other way. Positions keep the character's units.
"""

from __future__ import annotations

import socket
import struct
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.files.outputs import OutputError
from facepuppet.runtime.mapping.channels import pascal
from facepuppet.runtime.mapping.vrm_names import PERFECT_SYNC_NAMES, VRM0_PRESETS, fold_to_arkit, vrm0_from_arkit

if TYPE_CHECKING:
    from facepuppet.runtime.live.loop import TickInfo

MAX_BUNDLE = 1200
VMC_NAMES = ("both", "arkit", "vrm")  # --vmc-names, the first the default (see the module doc)
CALIBRATED, CALIBRATING = 3, 2  # /VMC/Ext/OK calibration states (0 uncalibrated, 1 waiting, 2, 3)
_BUNDLE_HEAD = 16  # "#bundle\0" + 8-byte time tag
_F32 = struct.Struct(">f")
_I32 = struct.Struct(">i")


def _message(address: str, *args):
    builder = OscMessageBuilder(address)
    for value, type_ in args:
        builder.add_arg(value, type_)
    return builder.build()


def _bundle(messages: list) -> bytes:
    builder = OscBundleBuilder(IMMEDIATELY)
    for m in messages:
        builder.add_content(m)
    return builder.build().dgram


def _split(messages: list, max_bundle: int) -> list[list]:
    """Messages in order, grouped greedily so that each group's bundle is at most ``max_bundle`` bytes."""
    groups, current, size = [], [], _BUNDLE_HEAD
    for m in messages:
        if current and size + 4 + m.size > max_bundle:  # each element costs 4 (size prefix) + its length
            groups.append(current)
            current, size = [], _BUNDLE_HEAD
        current.append(m)
        size += 4 + m.size
    groups.append(current)
    return groups


class VmcSender:
    """Send a character's weights and head pose as VMC bundles (see the module doc).

    Parameters
    ----------
    host, port : where to send (UDP)
    names : sequence of n str, the character's channel names, any spelling
    max_bundle : int, bytes; every datagram is at most this long
    extra : bool, also send the channels outside ARKit (``--vmc-extra``)
    presets : bool, send the VRM 0.x presets (default; ``--no-vmc-presets`` leaves them out for a perfect-sync
        avatar whose ``Blink``/vowel clips drive the same mesh shapes as the 52, which would add up twice)
    clock : callable returning seconds, for ``/VMC/Ext/T`` when :meth:`send` gets no time
    expressions : sequence of str, the avatar's expression names to send (VRM 0.x spelling for a preset; see
        the module doc), in the order of the values :meth:`send` gets; empty for a character without
    names : "both" (default), "arkit" or "vrm" (``--vmc-names``, see the module doc)
    status : callable returning (calibration state int, tracking bool), read each tick by :meth:`on_tick`;
        None: calibrated, tracking once a frame is on screen

    Attributes
    ----------
    sent_names : tuple of str, the Blend/Val names sent each tick, in order (52 ARKit, 17 presets, extras)
    held_back : tuple of str, the rig's channels outside ARKit not sent (no ``extra``, or a name
        that clashes with one already sent)
    datagrams : list of bytearray, the bundles sent each tick (status first, Apply in the last)
    counters : dict: ``bundles_sent``, ``send_errors``
    """

    def __init__(self, host: str, port: int, names: Sequence[str], max_bundle: int = MAX_BUNDLE,
                 extra: bool = False, clock: Callable[[], float] = time.monotonic, presets: bool = True,
                 expressions: Sequence[str] = (), names_mode: str = "both",
                 status: Callable[[], tuple[int, bool]] | None = None) -> None:
        self._status_of = status
        if names_mode not in VMC_NAMES:
            raise ValueError(f"--vmc-names: expected one of {', '.join(VMC_NAMES)}, got {names_mode!r}")
        if names_mode == "vrm" and not presets:
            raise UsageError("--no-vmc-presets: leaves out every VRM name, and --vmc-names vrm sends only those")
        self.address = (host, int(port))
        names = tuple(names)
        self.names_mode = names_mode
        own = tuple(expressions) if names_mode != "arkit" and presets else ()
        self._n = len(names)
        self._first, self._second, extras = fold_to_arkit(names)
        arkit_sent = names_mode != "vrm"
        own_sent = [e for e, n in enumerate(own) if not (arkit_sent and n in PERFECT_SYNC_NAMES)]
        self._own = np.array(own_sent, dtype=np.intp)
        self._n_own = len(own)
        derived = presets and not own  # the 17 presets derived from ARKit, when the avatar's own are not sent
        taken = set(PERFECT_SYNC_NAMES) | set(VRM0_PRESETS) | set(own)
        sent_extras, held = [], []
        self._clashing = tuple(n for n in own if arkit_sent and n in PERFECT_SYNC_NAMES)  # the 52 go instead
        for i in extras:
            name = pascal(names[i])
            if extra and name not in taken:
                sent_extras.append(i)
                taken.add(name)
            else:
                held.append(names[i])
        self._extras = np.array(sent_extras, dtype=np.intp)
        self._n_arkit = len(PERFECT_SYNC_NAMES) if arkit_sent else 0
        self._n_presets = len(VRM0_PRESETS) if derived else 0
        self.sent_names = ((PERFECT_SYNC_NAMES if arkit_sent else ()) + (VRM0_PRESETS if derived else ())
                           + tuple(own[e] for e in own_sent) + tuple(pascal(names[i]) for i in sent_extras))
        self.held_back = tuple(held)
        self._extra = extra
        self.counters = {"bundles_sent": 0, "send_errors": 0}
        self._clock = clock
        self._t0 = clock()
        self._values = np.zeros(len(self.sent_names))
        self._padded = np.zeros(self._n + 1)  # the rig's values and a 0 for ARKit shapes it lacks

        status = [
            _message("/VMC/Ext/OK", (1, "i"), (3, "i"), (0, "i"), (0, "i")),
            _message("/VMC/Ext/T", (0.0, "f")),
            _message("/VMC/Ext/Root/Pos", ("root", "s"), *[(0.0, "f")] * 6, (1.0, "f")),
            _message("/VMC/Ext/Bone/Pos", ("Head", "s"), *[(0.0, "f")] * 7),
        ]
        self._status = bytearray(_bundle(status))
        offsets = self._offsets(status)
        self._tracking_at = offsets[0] + status[0].size - 4  # the OK message's last int
        self._calib_at = self._tracking_at - 8  # its second int
        self._t_at = offsets[1] + status[1].size - 4
        self._head_at = offsets[3] + status[3].size - 7 * 4  # the 7 floats end the Head message

        vals = [_message("/VMC/Ext/Blend/Val", (name, "s"), (0.0, "f")) for name in self.sent_names]
        groups = _split(vals + [_message("/VMC/Ext/Blend/Apply")], max_bundle)
        self.datagrams = [self._status] + [bytearray(_bundle(g)) for g in groups]
        if any(len(d) > max_bundle for d in self.datagrams):
            raise OutputError(f"--vmc-out: a channel name is too long to fit a {max_bundle}-byte bundle")
        # (datagram index, byte offset of the value) of each Val, in order: the value is the message's last 4 bytes
        self._slots = [(gi, at + m.size - 4) for gi, g in enumerate(groups, start=1)
                       for at, m in zip(self._offsets(g), g) if m.address != "/VMC/Ext/Blend/Apply"]

        self._sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.connect(self.address)
        except OSError as exc:
            self._sock.close()
            raise OSError(f"--vmc-out {host}:{port}: cannot send there: {exc.strerror or exc}") from exc

    @staticmethod
    def _offsets(messages: list) -> list[int]:
        """Byte offset of each message inside the bundle built from ``messages``."""
        out, at = [], _BUNDLE_HEAD
        for m in messages:
            out.append(at + 4)
            at += 4 + m.size
        return out

    def values(self, weights: np.ndarray, expressions: np.ndarray | None = None) -> np.ndarray:
        """The Blend/Val values of ``weights`` (n,) float and the avatar's ``expressions`` (n_expressions,)
        float (None: all 0), in :attr:`sent_names` order (float64, in [0, 1])."""
        padded = self._padded
        padded[:-1] = weights
        np.nan_to_num(padded, copy=False, nan=0.0)
        np.clip(padded, 0.0, 1.0, out=padded)
        out = self._values
        arkit = np.maximum(padded[self._first], padded[self._second])
        n_arkit, n_presets, n_own = self._n_arkit, self._n_presets, len(self._own)
        out[:n_arkit] = arkit[:n_arkit]
        if n_presets:
            out[n_arkit:n_arkit + n_presets] = vrm0_from_arkit(arkit)
        at = n_arkit + n_presets
        if n_own:
            if expressions is None or len(expressions) != self._n_own:
                out[at:at + n_own] = 0.0
            else:
                out[at:at + n_own] = np.clip(np.nan_to_num(np.asarray(expressions)[self._own], nan=0.0), 0.0, 1.0)
        out[at + n_own:] = padded[self._extras]
        return out

    def send(self, weights: np.ndarray, rotation: np.ndarray | None = None,
             translation: np.ndarray | None = None, t: float | None = None, tracking: bool = True,
             expressions: np.ndarray | None = None, calib_state: int = CALIBRATED) -> None:
        """Send one tick: weights (n,) float, rotation (4,) (x, y, z, w) or None (identity),
        translation (3,) or None (zero), ``t`` seconds for ``/VMC/Ext/T`` (None: since the sender
        started), ``tracking`` and ``calib_state`` for the OK message, the avatar's ``expressions`` values (or None).
        Send errors are counted, never raised."""
        for (gi, at), v in zip(self._slots, self.values(weights, expressions).tolist()):
            _F32.pack_into(self.datagrams[gi], at, v)
        px, py, pz = (0.0, 0.0, 0.0) if translation is None else (float(c) for c in translation)
        qx, qy, qz, qw = (0.0, 0.0, 0.0, 1.0) if rotation is None else (float(c) for c in rotation)
        struct.pack_into(">7f", self._status, self._head_at, -px, py, pz, qx, -qy, -qz, qw)  # mirror x
        _F32.pack_into(self._status, self._t_at, self._clock() - self._t0 if t is None else t)
        _I32.pack_into(self._status, self._tracking_at, 1 if tracking else 0)
        _I32.pack_into(self._status, self._calib_at, int(calib_state))
        for d in self.datagrams:
            try:
                self._sock.send(d)
                self.counters["bundles_sent"] += 1
            except OSError:
                self.counters["send_errors"] += 1

    def on_tick(self, info: TickInfo) -> None:
        """FrameLoop ``on_tick`` hook: send what this tick drew, with the status of ``status`` (default:
        calibrated, tracking once a frame is on screen)."""
        if self._status_of is not None:
            calib, tracking = self._status_of()
        else:
            calib, tracking = CALIBRATED, info.frame is not None
        self.send(info.weights, info.rotation, info.translation, tracking=tracking, calib_state=calib,
                  expressions=info.expressions)

    def describe(self) -> str:
        """One line for the start of a run: what goes out, in how many bundles, what is held back."""
        n_own = len(self._own)
        n_extra = len(self.sent_names) - self._n_arkit - self._n_presets - n_own
        parts = ["52 ARKit (perfect sync)"] if self._n_arkit else []
        if n_own:
            parts.append(f"the avatar's {n_own} VRM expressions")
        elif self._n_presets:
            parts.append(f"{self._n_presets} VRM presets")
        else:
            parts.append("no VRM presets (--no-vmc-presets)")
        line = (f"vmc-out: {self.address[0]}:{self.address[1]} (--vmc-names {self.names_mode}), "
                + " + ".join(parts) + (f" + {n_extra} extra" if n_extra else "")
                + f", {len(self.datagrams)} bundles a tick")
        if self._clashing:
            line += f"; expressions named like an ARKit shape go as that shape: {', '.join(self._clashing[:6])}"
        if self.held_back:
            shown = ", ".join(self.held_back[:6]) + (" …" if len(self.held_back) > 6 else "")
            why = "their names clash with one sent" if self._extra else "not ARKit; --vmc-extra sends them"
            line += f"; not sent ({why}): {shown}"
        return line

    def close(self) -> None:
        self._sock.close()


def pipeline_status(stage: object) -> Callable[[], tuple[int, bool]]:
    """The ``status`` of a run whose ``filter`` stage is ``stage`` (:class:`~facepuppet.runtime.live.pipeline.
    LivePipeline`): calibrating (2) while it captures the neutral, else calibrated (3); tracking while its
    state is ``live`` or ``returning`` (frames arriving), not while ``waiting`` (none yet) or ``lost``."""
    def status() -> tuple[int, bool]:
        calib = CALIBRATING if getattr(stage, "calibrating", False) else CALIBRATED
        return calib, getattr(stage, "state", "live") in ("live", "returning")
    return status
