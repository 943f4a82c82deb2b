"""The option groups of what feeds a session: ``run``'s trackers and recording, ``replay``'s recording.

Like the groups of :mod:`~facepuppet.runtime.session.options`, each is a frozen dataclass with
``add_arguments(parser)`` and ``from_args(namespace)`` (the checked values; UsageError naming the option).
"""

from __future__ import annotations

import argparse
import ipaddress
import math
from dataclasses import dataclass
from pathlib import Path

from facepuppet.runtime.commands.options import parse_allow, parse_host_port
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.inputs.kinds import INPUT_KINDS
from facepuppet.runtime.inputs.phone import parse_phone
from facepuppet.runtime.live.mix import source_names
from facepuppet.runtime.recording.replay_source import DEFAULT_MAX_GAP_S
from facepuppet.runtime.session.options import StageOptions, get

RECEIVERS = ("process", "thread")


# -- live inputs ------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class MixInput:
    """One input of a run with several besides the frame loop's own: its source name, kind and address."""

    name: str
    kind: str
    host: str = "127.0.0.1"
    port: int = 0


def input_default_port(kind: str | None) -> int:
    """The default port of an input kind (0 for none)."""
    return 0 if kind is None else INPUT_KINDS[kind].default_port


def _is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


@dataclass(frozen=True)
class LiveInputOptions:
    """What ``run`` listens to: the trackers and the voice.

    Attributes
    ----------
    inputs : tuple of str, every ``--input`` in the order given
    names : tuple of str, their source names (``vmc``, ``vmc#2``, ..., ``audio``)
    input : str, the frame loop's own input (the first tracker, or ``audio`` alone)
    host, port : where the loop's own input listens
    mix : tuple of MixInput, the other inputs (a run with several)
    allow : frozenset of str or None, the senders accepted
    phone : (ip, port) or None, the phone asked to stream here (``--phone``)
    audio : str or None, the microphone (``""``: the default device); audio_file : Path or None, a WAV
    face_id : int or None (OpenSeeFace)
    receiver : str, ``process`` or ``thread``
    """

    inputs: tuple[str, ...]
    names: tuple[str, ...]
    input: str
    host: str
    port: int
    mix: tuple[MixInput, ...] = ()
    allow: frozenset | None = None
    phone: tuple[str, int] | None = None
    audio: str | None = None
    audio_file: Path | None = None
    face_id: int | None = None
    receiver: str = "process"

    @property
    def voice_only(self) -> bool:
        """No tracker: the face from the voice (``--input audio`` alone)."""
        return self.input == "audio"

    @property
    def kind(self) -> str | None:
        """The input kind of the loop's own frames (None for the voice alone)."""
        return None if self.voice_only else self.input

    @property
    def label(self) -> str:
        """What the stage chain names as its input."""
        return "voice" if self.voice_only else "+".join(self.names) if self.mix else self.input

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        group = parser.add_argument_group("inputs", "the trackers and the voice this run listens to")
        group.add_argument("--input", required=True, action="append", choices=(*INPUT_KINDS, "audio"),
                           help="tracker protocol, or 'audio': no tracker, the face from the voice (needs "
                                "--gestures); give it more than once for several inputs at once (--input "
                                "livelinkface --input audio, --input vmc --input openseeface): each channel and the "
                                "head come from the first live source in the [mix] order of --config (default: the "
                                "inputs in the order given)")
        group.add_argument("--listen", metavar="HOST:PORT", default=None, action="append",
                           help="address to listen on (default 127.0.0.1 on the input's default port); an address "
                                "other than loopback must be named here explicitly; with several tracker inputs, one "
                                "--listen per tracker, in the order of their --input (or none at all)")
        group.add_argument("--allow", metavar="IP[,IP...]", default=None,
                           help="accept packets only from these senders")
        group.add_argument("--phone", metavar="IP[:PORT]", default=None,
                           help="--input ifacialmocap / vtubestudio: the phone's IP address, sent the app's start "
                                "payload or data request (repeated) so that it streams here; only this address is "
                                "ever sent to")
        group.add_argument("--audio", nargs="?", const="", default=None, metavar="DEVICE",
                           help="measure the microphone level (default input device, or DEVICE by name or number)")
        group.add_argument("--audio-file", type=Path, default=None, metavar="WAV",
                           help="a WAV file as the audio input (and the sound of --video)")
        group.add_argument("--face-id", type=int, default=None, metavar="ID",
                           help="--input openseeface: follow the face with this id (default: the first of each "
                                "datagram)")
        group.add_argument("--receiver", choices=RECEIVERS, default="process",
                           help="where datagrams are decoded: 'process' (default: a child process, never competing "
                                "with the frame loop for the GIL) or 'thread' (a thread of this process)")

    @classmethod
    def from_args(cls, ns: argparse.Namespace) -> LiveInputOptions:
        """The inputs, checked: one address per tracker, no two on one address, the voice's level source, the
        phone reachable, ``--face-id`` only for OpenSeeFace.

        Raises
        ------
        ValueError
            naming the option: ``audio`` twice, ``markers`` with another input, a count of ``--listen`` that is
            not one per tracker (or none), two trackers on one address, a voice without ``--audio``/
            ``--audio-file``, a bad ``--allow``, ``--phone`` or ``--receiver``.
        """
        receiver = get(ns, "receiver", "process")
        if receiver not in RECEIVERS:
            raise UsageError(f"--receiver: expected one of {RECEIVERS}, got {receiver!r}")
        given = get(ns, "input")
        inputs = tuple(given) if isinstance(given, (list, tuple)) else (given,)
        listen = get(ns, "listen")
        listens = list(listen) if isinstance(listen, (list, tuple)) else [] if listen is None else [listen]
        audio, audio_file = get(ns, "audio"), get(ns, "audio_file")
        names = source_names(inputs)
        trackers = [k for k in inputs if k != "audio"]
        if len(listens) > max(1, len(trackers)) or (listens and len(trackers) > 1 and len(listens) != len(trackers)):
            raise UsageError(f"--listen: {len(listens)} given for {len(trackers)} tracker input(s) "
                             f"({', '.join(trackers) or 'none'}); give one per tracker input, in the order of their "
                             "--input, or none (each on its kind's default port)")
        mix: list[MixInput] = []
        if len(inputs) == 1:
            loop_input = inputs[0]
        else:
            if inputs.count("audio") > 1:
                raise UsageError("--input audio: given twice; the voice is one input")
            if "markers" in inputs:
                raise UsageError("--input markers: not with other inputs (the marker solve takes one marker stream)")
            if not trackers:
                raise UsageError("--input: several inputs need at least one tracker")
            if "audio" in inputs and audio is None and audio_file is None:
                raise UsageError("--input audio: the voice as an input needs --audio [DEVICE] or --audio-file WAV")
            addresses = [parse_host_port(listens[i], "--listen") if listens else ("127.0.0.1", input_default_port(k))
                         for i, k in enumerate(trackers)]
            tracker_names = [n for n, k in zip(names, inputs) if k != "audio"]
            for i in range(len(addresses)):
                for j in range(i):
                    if addresses[i] == addresses[j]:
                        raise UsageError(f"--listen: {tracker_names[j]} and {tracker_names[i]} would both listen on "
                                         f"{addresses[i][0]}:{addresses[i][1]}; give each tracker input its own "
                                         "--listen")
            loop_input = trackers[0]
            mix = [MixInput(n, k, *addresses[i]) for i, (n, k) in enumerate(zip(tracker_names, trackers)) if i > 0]
            if "audio" in inputs:
                mix.append(MixInput("audio", "audio"))
        kind = None if loop_input == "audio" else loop_input
        host, port = (("127.0.0.1", input_default_port(kind)) if not listens
                      else parse_host_port(listens[0], "--listen"))
        face_id = get(ns, "face_id")
        if face_id is not None and "openseeface" not in inputs:
            raise UsageError(f"--face-id: only for --input openseeface (not {loop_input})")
        allow = parse_allow(get(ns, "allow"))
        return cls(inputs, names, loop_input, host, port, tuple(mix), None if allow is None else frozenset(allow),
                   _check_phone(get(ns, "phone"), loop_input, host), audio, audio_file, face_id, receiver)

    def recorded(self) -> dict:
        """The header facts of a recording about the inputs (the listen address, the mix sources)."""
        mix = [{"name": m.name, "kind": m.kind, "listen": f"{m.host}:{m.port}"} for m in self.mix
               if m.kind != "audio"]
        return {"listen": f"{self.host}:{self.port}",
                **({"inputs": list(self.names), "mix_sources": mix} if mix or len(self.names) > 1 else {})}


def _check_phone(text: str | None, kind: str, host: str) -> tuple[str, int] | None:
    """(ip, port) of ``--phone`` for the phone input kinds, or None; ValueError naming the option otherwise."""
    if text is None:
        return None
    cls = INPUT_KINDS.get(kind)
    if cls is None or not hasattr(cls, "phone_request"):
        kinds = [k for k, c in INPUT_KINDS.items() if hasattr(c, "phone_request")]
        raise UsageError(f"--phone: only for --input {' or '.join(kinds)} (not {kind})")
    phone = parse_phone(text, cls.phone_port)
    if _is_loopback(host) and not ipaddress.ip_address(phone[0]).is_loopback:
        raise UsageError(f"--phone {phone[0]}: the phone's frames cannot reach {host}, where this run listens; "
                         f"listen where the phone can send, e.g. --listen 0.0.0.0:{cls.default_port} or this "
                         "machine's own LAN address")
    return phone


@dataclass(frozen=True)
class RecordOptions:
    """``--record FILE`` (the packets, levels and ticks of the run) and ``--save-profile``."""

    record: Path | None = None
    save_profile: bool = False

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--record", type=Path, default=None, metavar="FILE",
                            help="record packets and audio levels")
        parser.add_argument("--save-profile", action="store_true",
                            help="with --profile: save the config in force (the neutral captured by --calibrate, "
                                 "key C or /facepuppet/calibrate included) to the profile when the run ends")

    @classmethod
    def from_args(cls, ns: argparse.Namespace) -> RecordOptions:
        record = get(ns, "record")
        return cls(None if record is None else Path(record), bool(get(ns, "save_profile", False)))


# -- replay -----------------------------------------------------------------------------------------------

def _gap_seconds(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds (or inf), got {text!r}")
    return value


@dataclass(frozen=True)
class ReplayInputOptions:
    """What ``replay`` plays: a recording, and whether its frames go through the filter stage.

    Attributes
    ----------
    session : Path, a session file, a Live Link Face CSV or a marker take
    max_gap : float, seconds; longer pauses between recorded frames are cut to this
    pipeline : bool or None, the filter stage asked for (True), refused (False) or by default (None: a live
        recording's and a marker take's, implied by ``--config`` and ``--calibrate``)
    """

    session: Path
    max_gap: float = DEFAULT_MAX_GAP_S
    pipeline: bool | None = None

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        parser.add_argument("session", type=Path,
                            help="session file (.fps), Live Link Face CSV, or a marker take (.trc/.c3d/.csv, with "
                                 "--actor/--pair)")
        parser.add_argument("--max-gap", type=_gap_seconds, default=DEFAULT_MAX_GAP_S, metavar="SECONDS",
                            help=f"cut a pause between recorded frames longer than this to this length, and say so "
                                 f"(default {DEFAULT_MAX_GAP_S:g}; 'inf' keeps every pause)")
        parser.add_argument("--pipeline", action=argparse.BooleanOptionalAction, default=None,
                            help="run the filter stage (filters, calibration, tracking loss) as `run` does; default: "
                                 "on for a live recording (run --record) and a marker take, so the replay draws what "
                                 "the live run drew, off for other recordings; implied by --config and --calibrate; "
                                 "--no-pipeline plays the raw frames")

    @classmethod
    def from_args(cls, ns: argparse.Namespace, stages: StageOptions) -> ReplayInputOptions:
        pipeline = get(ns, "pipeline")
        if pipeline is False and (stages.config is not None or stages.calibrate):
            raise UsageError("--no-pipeline: --config and --calibrate configure the filter stage; drop them or it")
        max_gap = float(get(ns, "max_gap", DEFAULT_MAX_GAP_S))
        if not (max_gap > 0 or math.isinf(max_gap)):
            raise UsageError(f"--max-gap: expected a positive number of seconds (or inf), got {max_gap}")
        return cls(Path(ns.session), max_gap, pipeline)

    def implied_pipeline(self, stages: StageOptions) -> bool:
        """The filter stage asked for, or implied by ``--config`` / ``--calibrate``."""
        return bool(self.pipeline) or stages.config is not None or stages.calibrate
