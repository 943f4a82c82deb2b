"""``facepuppet run``: drive a character live from a tracker over UDP.

One UDP socket read by a child process
(:class:`~facepuppet.runtime.inputs.udp_process.UdpProcessSource`; with ``--receiver thread`` a
thread of this process, :class:`~facepuppet.runtime.inputs.udp.UdpSource`) decodes the
input kind's datagrams into frames; the frame loop draws as soon as a new
frame arrives (``--draw arrival``, the default; without new frames it redraws
at ``--fps``) or on a fixed ``--fps`` grid (``--draw tick``), takes the newest
frame each tick (older ones are dropped and counted, never queued), runs the live pipeline (filter, calibrate,
gain/clamp, tracking-loss easing; :mod:`~facepuppet.runtime.live.pipeline`), maps
it onto the rig and draws. Around that loop:

* ``--record FILE``: every accepted datagram (raw bytes, receive time, input
  kind) and the audio level of each tick go to a session file
  (:mod:`~facepuppet.runtime.recording.recorder`); ``facepuppet replay FILE`` re-decodes it.
* ``--audio [DEVICE]`` / ``--audio-file WAV``: the audio level (dBFS) on every
  drawn frame; no device is a message, not an error.
* ``--vmc-out HOST:PORT``: the face as VMC perfect sync + VRM 0.x presets and the head pose, every tick
  (:mod:`~facepuppet.runtime.live.vmc_out`); ``--vmc-extra`` adds the rig's channels outside ARKit;
  ``--vmc-names both|arkit|vrm`` whether a VRM avatar's own expression names go out with the 52.
* ``--llf-out HOST:PORT``: the face and head as Live Link Face packets, every tick
  (:mod:`~facepuppet.runtime.live.llf_out`), for Unreal's Live Link and anything that reads the phone.
* ``--video FILE``: the drawn ticks encoded as a video (:mod:`~facepuppet.runtime.live.video_out`),
  with ``--audio-file`` as its sound track.
* ``--phone IP[:PORT]`` (``--input ifacialmocap`` / ``vtubestudio``): the app's start payload or data request,
  sent only to that address, at once and then periodically from a daemon thread that stops with the run
  (:mod:`~facepuppet.runtime.inputs.phone`); a loopback ``--listen`` with a LAN phone is refused.
* ``--events-out HOST:PORT`` (and ``--vmc-out``): tracking lost / found as OSC ``/facepuppet/tracking i``
  (:mod:`~facepuppet.runtime.live.events_out`); with ``--record`` the events are also recorded (EVENT records).
* ``--stats``: counters and per-stage latency once a second and at exit.
* Parameter spaces (:mod:`~facepuppet.runtime.live.stages`): ``--input markers``
  with ``--actor``/``--pair`` (marker solve, Shin & Lee), ``--retarget`` (kernel
  PLS), ``--elastic`` (elastic path; muscles as input channels).
* With ``--record``, one TICK record per drawn tick (which frame it took and
  when), so ``replay`` with the same options draws the same weights.
* Calibration (neutral capture over ``capture_s`` = 0.5 s by default): at the
  start with ``--calibrate``, whenever the OSC message ``/facepuppet/calibrate``
  arrives on the listening port (any arguments; detected before the adapter,
  which counts it as an unknown address), or with the key C in a window.

It listens on 127.0.0.1 unless ``--listen`` names another address; ``--allow``
keeps only the listed sender IPs. ``--duration`` stops it by itself; Ctrl-C
stops it cleanly; either way the final stats are printed.
"""

from __future__ import annotations

import argparse
import ipaddress
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.character import Character
from facepuppet.runtime.commands.options import parse_allow, parse_host_port, parse_size
from facepuppet.runtime.inputs.osc import CALIBRATE_ADDRESS
from facepuppet.runtime.live.events_out import TrackingEventSender
from facepuppet.runtime.live.llf_out import LlfSender
from facepuppet.runtime.live.loop import ARRIVAL_GRID_HZ, FrameLoop, LoopResult, WallClock
from facepuppet.runtime.live.sinks import PngSink, RecordingHook, WeightLog
from facepuppet.runtime.live.stages import add_stage_arguments, build_chain, follow_mapping, make_input_adapter
from facepuppet.runtime.live.stats import LiveStats
from facepuppet.runtime.live.video_out import VideoPlan, VideoSink, add_video_arguments, plan_video_from_args
from facepuppet.runtime.live.vmc_out import VMC_NAMES, VmcSender, pipeline_status
from facepuppet.runtime.render.options import add_render_arguments, render_options

if TYPE_CHECKING:
    from facepuppet.runtime.live.loop import TickInfo
    from facepuppet.runtime.live.stages import Chain

RECEIVERS = ("process", "thread")
THREAD_SWITCH_INTERVAL_S = 0.0005  # GIL switch interval while a receive *thread* shares the loop's process


def register(subparsers: argparse._SubParsersAction) -> None:
    from facepuppet.runtime.inputs.kinds import INPUT_KINDS

    p = subparsers.add_parser(
        "run", help="drive a character live from a tracker over UDP (VMC, Face Cap, FaceOSC, markers, Live Link Face, "
                     "iFacialMocap, VTube Studio, OpenSeeFace)",
        description="Drive a character live from OSC / UDP tracker input on this machine.")
    p.add_argument("-c", "--character", type=Path, required=True, help="character .npz")
    p.add_argument("--input", required=True, action="append", choices=tuple(INPUT_KINDS) + ("audio",),
                   help="tracker protocol, or 'audio': no tracker, the face from the voice (needs --gestures); "
                        "give it more than once for several inputs at once (--input livelinkface --input audio, "
                        "--input vmc --input openseeface): each channel and the head come from the first live "
                        "source in the [mix] order of --config (default: the inputs in the order given)")
    p.add_argument("--listen", metavar="HOST:PORT", default=None, action="append",
                   help="address to listen on (default 127.0.0.1 on the input's default port); "
                        "an address other than loopback must be named here explicitly; with several tracker "
                        "inputs, one --listen per tracker, in the order of their --input (or none at all)")
    p.add_argument("--allow", metavar="IP[,IP...]", default=None, help="accept packets only from these senders")
    p.add_argument("--phone", metavar="IP[:PORT]", default=None,
                   help="--input ifacialmocap / vtubestudio: the phone's IP address, sent the app's start payload "
                        "or data request (repeated) so that it streams here; only this address is ever sent to")
    p.add_argument("--audio", nargs="?", const="", default=None, metavar="DEVICE",
                   help="measure the microphone level (default input device, or DEVICE by name or number)")
    p.add_argument("--audio-file", type=Path, default=None, metavar="WAV", help="a WAV file as the audio input")
    p.add_argument("--record", type=Path, default=None, metavar="FILE", help="record packets and audio levels")
    p.add_argument("--save-profile", action="store_true",
                   help="with --profile: save the config in force (the neutral captured by --calibrate, key C or "
                        "/facepuppet/calibrate included) to the profile when the run ends")
    p.add_argument("--vmc-out", default=None, metavar="HOST:PORT",
                   help="send the face and head as VMC: the 52 ARKit shapes (perfect sync), the VRM 0.x presets "
                        "derived from them, the head bone")
    p.add_argument("--events-out", default=None, metavar="HOST:PORT",
                   help="send tracking lost/found as OSC /facepuppet/tracking i (1 found, 0 lost) here "
                        "(also sent to --vmc-out when given)")
    p.add_argument("--vmc-extra", action="store_true",
                   help="with --vmc-out, also send the character's channels outside ARKit (e.g. CheekRaiserLeft)")
    p.add_argument("--vmc-presets", action=argparse.BooleanOptionalAction, default=True,
                   help="with --vmc-out, also send the VRM 0.x presets (Blink, A, I, U, E, O, ...; default on); "
                        "--no-vmc-presets for a perfect-sync avatar whose preset clips move the same shapes")
    p.add_argument("--llf-out", default=None, metavar="HOST:PORT",
                   help="send the face and head as Live Link Face packets (the phone's UDP format; Unreal's Live "
                        "Link listens on port 11111)")
    add_video_arguments(p, audio_help=None)
    p.add_argument("--vmc-names", choices=VMC_NAMES, default=None,
                   help="with --vmc-out and a character with VRM expressions: 'both' (default) sends the 52 ARKit "
                        "shapes and the avatar's own expressions (VRM 0.x preset names Blink, A, Joy, ..., custom "
                        "ones by name) with the values drawn; 'vrm' only the expressions; 'arkit' the 52 and the "
                        "presets derived from them, as for an OBJ rig")
    p.add_argument("--face-id", type=int, default=None, metavar="ID",
                   help="--input openseeface: follow the face with this id (default: the first of each datagram)")
    p.add_argument("--stats", action="store_true", help="print counters and latencies every second and at exit")
    p.add_argument("--headless", action="store_true", help="render offscreen through EGL (no window)")
    p.add_argument("--panel", action="store_true",
                   help="with --headless: draw the operator's panel into the frames (--out, --video); in a window "
                        "the panel is shown anyway and Tab hides or shows it (needs the extra 'panel': imgui-bundle)")
    p.add_argument("--out", type=Path, default=None, help="write each tick as DIR/frame_00000.png")
    p.add_argument("--dump-weights", type=Path, default=None, metavar="FILE.npy",
                   help="save the rig weights of every tick, (n_ticks, n_shapes) float32, at exit")
    p.add_argument("--size", default="1280x720", help="image size WIDTHxHEIGHT (default 1280x720)")
    p.add_argument("--fps", type=float, default=60.0,
                   help="ticks per second (default 60); with --draw arrival, the redraw rate without new frames")
    p.add_argument("--draw", choices=("arrival", "tick"), default="arrival",
                   help="'arrival' (default): draw as soon as a new frame arrives (lowest latency); "
                        "'tick': draw on a fixed --fps grid")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--path", choices=("auto", "gpu", "cpu"), default="auto", help="deformation path")
    add_render_arguments(p)
    p.add_argument("--receiver", choices=RECEIVERS, default="process",
                   help="where datagrams are decoded: 'process' (default: a child process, never competing with "
                        "the frame loop for the GIL) or 'thread' (a thread of this process)")
    add_stage_arguments(p)
    p.set_defaults(func=run_command)


@dataclass
class LiveRunResult:
    """What one live run did: the loop result, the stats, the per-tick weights (only when kept: ``--dump-weights``
    or ``keep_weights``; None otherwise), the parts' counters and the panel (a closed DeskPanel, or None)."""

    loop: LoopResult
    stats: LiveStats
    weights: WeightLog | None
    counters: dict
    path: str
    address: tuple
    chain: str = ""
    panel: object = None


@dataclass
class _Options:
    """The checked options of one live run."""

    width: int
    height: int
    loop_fps: float
    idle_fps: float | None
    voice_only: bool
    host: str
    port: int
    allow: set | None
    vmc_out: tuple | None
    llf_out: tuple | None = None
    video: VideoPlan | None = None
    phone: tuple | None = None
    events_out: tuple | None = None


def _check_options(args, default_port) -> _Options:
    """Every option that can be checked before anything opens; ValueError naming the option otherwise."""
    width, height = parse_size(args.size)
    if not (args.fps > 0):
        raise ValueError(f"--fps: expected a positive number, got {args.fps}")
    if args.duration is not None and not (args.duration > 0):
        raise ValueError(f"--duration: expected a positive number of seconds, got {args.duration}")
    if getattr(args, "save_profile", False) and getattr(args, "profile", None) is None:
        raise ValueError("--save-profile: saves to --profile NAME|PATH; give one")
    voice_only = args.input == "audio"
    if voice_only and (getattr(args, "gestures", None) is None or (args.audio is None and args.audio_file is None)):
        raise ValueError("--input audio: needs --gestures GESTURES.npz and --audio [DEVICE] or --audio-file WAV")
    # draw on arrival: tick labels on a 1 kHz grid (so a replay can follow them), redraws at --fps when idle
    arrival = getattr(args, "draw", "arrival") == "arrival" and not voice_only
    loop_fps, idle_fps = (ARRIVAL_GRID_HZ, args.fps) if arrival else (args.fps, None)
    host, port = ("127.0.0.1", default_port) if args.listen is None else parse_host_port(args.listen, "--listen")
    vmc_out = parse_host_port(args.vmc_out) if args.vmc_out else None
    if getattr(args, "vmc_extra", False) and vmc_out is None:
        raise ValueError("--vmc-extra: needs --vmc-out HOST:PORT")
    if not getattr(args, "vmc_presets", True) and vmc_out is None:
        raise ValueError("--no-vmc-presets: needs --vmc-out HOST:PORT")
    if getattr(args, "face_id", None) is not None and "openseeface" not in getattr(args, "inputs", (args.input,)):
        raise ValueError(f"--face-id: only for --input openseeface (not {args.input})")
    if getattr(args, "vmc_names", None) is not None and vmc_out is None:
        raise ValueError("--vmc-names: needs --vmc-out HOST:PORT")
    llf_out = parse_host_port(args.llf_out, "--llf-out") if getattr(args, "llf_out", None) else None
    video = plan_video_from_args(args, width, height, alpha=render_options(args).transparent)
    events_out = parse_host_port(args.events_out, "--events-out") if getattr(args, "events_out", None) else None
    return _Options(width, height, loop_fps, idle_fps, voice_only, host, port, parse_allow(args.allow), vmc_out,
                    llf_out, video, _check_phone(args, host), events_out)


def _check_phone(args, host: str) -> tuple | None:
    """(ip, port) of ``--phone`` for the phone input kinds, or None; ValueError naming the option otherwise."""
    from facepuppet.runtime.inputs.kinds import INPUT_KINDS
    from facepuppet.runtime.inputs.phone import parse_phone

    text = getattr(args, "phone", None)
    if text is None:
        return None
    cls = INPUT_KINDS.get(args.input)
    if cls is None or not hasattr(cls, "phone_request"):
        kinds = [k for k, c in INPUT_KINDS.items() if hasattr(c, "phone_request")]
        raise ValueError(f"--phone: only for --input {' or '.join(kinds)} (not {args.input})")
    phone = parse_phone(text, cls.phone_port)
    if _is_loopback(host) and not ipaddress.ip_address(phone[0]).is_loopback:
        raise ValueError(f"--phone {phone[0]}: the phone's frames cannot reach {host}, where this run listens; "
                         f"listen where the phone can send, e.g. --listen 0.0.0.0:{cls.default_port} or this "
                         "machine's own LAN address")
    return phone


def _record_info(args, opts: _Options, chain=None) -> dict:
    """The header facts of ``--record``: enough for ``replay`` to rebuild the same chain (``config``: the live
    config the run starts with, as TOML, neutral included)."""
    options = ("config", "profile", "calibrate", "actor", "pair", "marker_units", "retarget", "elastic", "gestures",
               "gesture_seed", "face_id")
    mix = [{"name": m.name, "kind": m.kind, "listen": f"{m.host}:{m.port}"} for m in getattr(args, "mix_inputs", ())
           if m.kind != "audio"]
    info = {"character": str(args.character), "listen": f"{opts.host}:{opts.port}", "fps": opts.loop_fps,
            "idle_fps": opts.idle_fps, **({"inputs": list(args.input_names), "mix_sources": mix} if mix or len(
                getattr(args, "input_names", ())) > 1 else {}),
            "options": {name: None if getattr(args, name, None) is None else str(getattr(args, name))
                        for name in options}}
    if chain is not None and chain.filter is not None:
        from facepuppet.runtime.live.profiles import config_to_toml

        info["config"] = config_to_toml(chain.filter.current_config())
    return info


def _wants_panel(args) -> bool:
    """Whether this run may show the panel (a window, or ``--headless --panel``) and imgui-bundle is there."""
    if getattr(args, "headless", False) and not getattr(args, "panel", False):
        return False
    from importlib.util import find_spec

    return find_spec("imgui_bundle") is not None


def _open_recorder(args, opts: _Options, chain, late, mix_inputs, log):
    """The run's :class:`~facepuppet.runtime.recording.switch.SwitchableRecorder` (``--record`` and the panel's
    Record / Stop), or None for a run without either (no datagram ring then)."""
    from facepuppet.runtime.recording.recorder import PacketRecorder
    from facepuppet.runtime.recording.switch import SwitchableRecorder

    if args.record is None and not _wants_panel(args):
        return None
    record = Path(args.record) if args.record is not None else None  # callers in code (bench soak) pass a str
    force = bool(getattr(args, "force", False))

    def open_recorder(path: Path) -> PacketRecorder:
        info = _record_info(args, opts, chain)  # the config in force now
        if holder.ticks_seen:
            info["started_at_t"] = holder.last_t  # a recording the panel started during the run
        return PacketRecorder(path, args.input, info=info, overwrite=force and path == record)

    make_adapter = None if opts.voice_only else (
        lambda: make_input_adapter(args.input, (), log=lambda s: None, face_id=getattr(args, "face_id", None)))
    holder = SwitchableRecorder(
        open_recorder, record.parent if record is not None else Path.cwd(), make_adapter=make_adapter,
        frames_taken=lambda: getattr(late.source, "frames_taken", 0), log=log,
        pipeline=chain.filter if _wants_panel(args) else None,  # only the panel starts one mid-run
        refuse_midrun="not with several inputs (their frame counts cannot be aligned mid-run); use --record FILE"
        if mix_inputs else "")
    return holder


def _config_recorder(late):
    """The filter's ``on_config`` hook of ``--record``: each config change as a CONFIG record at its tick."""
    def hook(t: float, config) -> None:
        if late.recorder is not None:
            from facepuppet.runtime.live.profiles import config_to_toml

            late.recorder.put_config(t, config_to_toml(config))
    return hook


@dataclass(frozen=True)
class MixInput:
    """One input of a run with several besides the frame loop's own: its source name, kind and address."""

    name: str
    kind: str
    host: str = "127.0.0.1"
    port: int = 0


def split_inputs(args: argparse.Namespace) -> tuple[argparse.Namespace, list[MixInput]]:
    """The run's inputs: ``args`` with ``input`` the frame loop's own (the first tracker, or ``audio`` alone) and
    ``listen`` its address, plus ``inputs`` / ``input_names`` (every input in the order given) and
    ``mix_inputs``; and the other inputs (the mix sources). One ``--input`` gives ``args`` as it was.

    Raises
    ------
    ValueError
        naming the option: ``audio`` twice, ``markers`` with another input, a count of ``--listen`` that is
        not one per tracker (or none), two trackers on one address, a voice without ``--audio``/``--audio-file``.
    """
    from facepuppet.runtime.live.mix import source_names

    inputs = list(args.input) if isinstance(args.input, (list, tuple)) else [args.input]
    listens = list(args.listen) if isinstance(args.listen, (list, tuple)) else (
        [] if args.listen is None else [args.listen])
    out = argparse.Namespace(**vars(args))
    out.inputs, out.input_names, out.mix_inputs = tuple(inputs), source_names(inputs), ()
    trackers = [k for k in inputs if k != "audio"]
    if len(listens) > max(1, len(trackers)) or (listens and len(trackers) > 1 and len(listens) != len(trackers)):
        raise ValueError(f"--listen: {len(listens)} given for {len(trackers)} tracker input(s) "
                         f"({', '.join(trackers) or 'none'}); give one per tracker input, in the order of their "
                         "--input, or none (each on its kind's default port)")
    out.listen = listens[0] if listens else None
    if len(inputs) == 1:
        out.input = inputs[0]
        return out, []
    if inputs.count("audio") > 1:
        raise ValueError("--input audio: given twice; the voice is one input")
    if "markers" in inputs:
        raise ValueError("--input markers: not with other inputs (the marker solve takes one marker stream)")
    if not trackers:
        raise ValueError("--input: several inputs need at least one tracker")
    if "audio" in inputs and args.audio is None and args.audio_file is None:
        raise ValueError("--input audio: the voice as an input needs --audio [DEVICE] or --audio-file WAV")
    addresses = [parse_host_port(listens[i], "--listen") if listens else ("127.0.0.1", input_default_port(k))
                 for i, k in enumerate(trackers)]
    tracker_names = [n for n, k in zip(out.input_names, inputs) if k != "audio"]
    for i in range(len(addresses)):
        for j in range(i):
            if addresses[i] == addresses[j]:
                raise ValueError(f"--listen: {tracker_names[j]} and {tracker_names[i]} would both listen on "
                                 f"{addresses[i][0]}:{addresses[i][1]}; give each tracker input its own --listen")
    out.input = trackers[0]
    mix = [MixInput(n, k, *addresses[i]) for i, (n, k) in enumerate(zip(tracker_names, trackers)) if i > 0]
    if "audio" in inputs:
        mix.append(MixInput("audio", "audio"))
    out.mix_inputs = tuple(mix)
    return out, mix


def _open_mix(args, mix_inputs: list[MixInput], chain, opts: _Options, recorder, parts: list, log) -> None:
    """Start the other inputs' receivers and put the ``mix`` stage in the chain."""
    from dataclasses import replace

    from facepuppet.runtime.inputs.udp import UdpSource
    from facepuppet.runtime.inputs.udp_process import UdpProcessSource
    from facepuppet.runtime.live.mix import MixStage, VoiceMixSource, check_mix_sources, follow_config

    sources = {}
    for m in mix_inputs:
        if m.kind == "audio":
            if chain.audio is None:
                raise ValueError("--input audio: no audio level (--audio found no device); the voice input needs one")
            sources[m.name] = VoiceMixSource(chain.audio.level, chain.config.loss)
            continue
        adapter = make_input_adapter(m.kind, chain.extra_names, log=log, face_id=getattr(args, "face_id", None))
        on_packet = recorder.tagged(m.name) if recorder is not None else None
        cls = UdpProcessSource if getattr(args, "receiver", "process") == "process" else UdpSource
        src = cls(adapter, host=m.host, port=m.port, allow=opts.allow, on_packet=on_packet, watch=CALIBRATE_ADDRESS)
        src.start()
        parts.append(src)
        sources[m.name] = src
        log(f"run: listening for {m.kind} ({m.name}) on {src.address[0]}:{src.address[1]}")
    names = (args.input, *(m.name for m in mix_inputs))
    settings = chain.config.mix
    if settings.order is None:
        settings = replace(settings, order=tuple(args.input_names))
    check_mix_sources(settings, names, chain.config.path or "(defaults)")
    stage = MixStage(names, sources, settings, chain.config.timeout_s)
    chain.add_mix(stage, label="+".join(args.input_names))
    if chain.filter is not None:  # a config applied live (the panel) changes the mix's orders too
        chain.filter.on_config.append(follow_config(stage, tuple(args.input_names), log))
    log(f"mix: {len(names)} sources, order {' > '.join(settings.order)}"
        + "".join(f"; {r}: {' > '.join(o)}" for r, o in settings.regions.items())
        + (f"; {len(settings.channels)} channels with their own order" if settings.channels else ""))


def _arrival_wake(source, chain):
    """With other tracker inputs (the mix), what wakes the loop when any input has a frame (inputs.arrival);
    None: the loop's own source's ``wait_for_frame``."""
    from facepuppet.runtime.inputs.arrival import ArrivalWaiter

    trackers = [s for _, s in chain.mix.tracker_sources()] if chain.mix is not None else []
    if not trackers or not all(hasattr(s, "pending") for s in (source, *trackers)):
        return None
    return ArrivalWaiter([source, *trackers]).wait


def _open_source(args, adapter, opts: _Options, recorder):
    """The live frame source: the UDP receiver of ``--receiver``, or none for ``--input audio``."""
    from facepuppet.runtime.gestures.layer import VoiceOnlySource
    from facepuppet.runtime.inputs.udp import UdpSource
    from facepuppet.runtime.inputs.udp_process import UdpProcessSource

    if opts.voice_only:
        return VoiceOnlySource(None)
    on_packet = recorder.put if recorder is not None else None
    if getattr(args, "receiver", "process") == "process":  # datagrams come back to this process only to be recorded
        return UdpProcessSource(adapter, host=opts.host, port=opts.port, allow=opts.allow, on_packet=on_packet,
                                watch=CALIBRATE_ADDRESS)
    return UdpSource(adapter, host=opts.host, port=opts.port, allow=opts.allow, on_packet=on_packet,
                     watch=CALIBRATE_ADDRESS)


def run_live(args: argparse.Namespace, log: Callable[[str], None] = print, stop_event: threading.Event | None = None,
             on_ready: Callable[[tuple[str, int]], None] | None = None,
             hooks: Sequence[Callable[[TickInfo], None]] = (), keep_weights: bool = False,
             on_chain: Callable[[Chain], None] | None = None,
             on_panel: Callable[[object], None] | None = None) -> LiveRunResult:
    """Run a live session from parsed ``args`` (see :func:`register`) and return what it did.

    ``stop_event`` set from another thread ends the run at the next tick;
    ``on_ready(address)`` is called once the socket is bound, before the first tick;
    ``hooks`` are extra FrameLoop ``on_tick`` callables (benchmarks). Each tick's weights are kept
    (``LiveRunResult.weights``) only with ``--dump-weights`` or ``keep_weights``: a show runs for hours.
    ``on_chain(chain)`` is called once the stage chain is built (its ``filter`` takes ``apply_config``,
    its ``profile`` saves). ``on_panel(panel)`` is called with the run's DeskPanel once it is made (tests drive
    it through its ImGui IO; its ``recorder`` is the run's SwitchableRecorder).

    Raises
    ------
    ValueError, FileNotFoundError
        for bad options or files (named); OSError when the address cannot be bound;
        GLUnavailable when no OpenGL context can be made.
    """
    from facepuppet.runtime.inputs.audio import open_audio
    from facepuppet.runtime.render.blas_threads import BlasThreads
    from facepuppet.runtime.render.gl_context import create_context

    receiver = getattr(args, "receiver", "process")
    if receiver not in RECEIVERS:
        raise ValueError(f"--receiver: expected one of {RECEIVERS}, got {receiver!r}")
    args, mix_inputs = split_inputs(args)
    adapter_kind = None if args.input == "audio" else args.input
    opts = _check_options(args, input_default_port(adapter_kind))
    character = Character.load(args.character)
    picture = render_options(args)
    if character.credits:
        log(f"credits: {character.credits}")
    stop_event = stop_event or threading.Event()
    parts: list = []  # things to close, in reverse order
    signals = _sigint_sets(stop_event).__enter__()  # from here on a SIGTERM or Ctrl-C ends the run cleanly
    parts.append(signals)
    try:
        # One BLAS thread: OpenBLAS workers and llvmpipe's rasteriser threads fighting over 2 cores made
        # the CPU deformation take 100-600 ms now and then (see blas_threads); also for the path choice.
        parts.append(BlasThreads(1).__enter__())
        audio = None
        if args.audio is not None or args.audio_file is not None:
            audio = open_audio(device=args.audio, wav=args.audio_file, log=log)
            if audio is not None:
                parts.append(audio)
        late = SimpleNamespace(source=None, recorder=None)  # the filter reads the source's calibrate count later
        chain = build_chain(args, character, adapter_kind, audio_level=audio.level if audio is not None else None,
                            calibrate_requests=lambda: getattr(late.source, "watched", 0),
                            voice_only=opts.voice_only, label="voice" if opts.voice_only else args.input, log=log,
                            on_config=[_config_recorder(late)])
        adapter = None if opts.voice_only else make_input_adapter(
            args.input, chain.extra_names, log=log, marker_units=getattr(args, "marker_units", None),
            to_units=chain.marker_units, face_id=getattr(args, "face_id", None))
        recorder = late.recorder = _open_recorder(args, opts, chain, late, mix_inputs, log)
        if recorder is not None:
            parts.append(SimpleNamespace(close=recorder.close))  # close() waits for every recording's file
            if args.record is not None:
                recorder.start(Path(args.record))
        source = late.source = _open_source(args, adapter, opts, recorder)
        if opts.voice_only:
            source.duration = getattr(audio, "duration", None)
        source.start()
        parts.append(source)
        log(f"run: listening for {args.input} on {source.address[0]}:{source.address[1]}"
            + (f" (only from {', '.join(sorted(opts.allow))})" if opts.allow else ""))
        if mix_inputs:
            _open_mix(args, mix_inputs, chain, opts, recorder, parts, log)
        log(chain.describe())
        if on_chain is not None:
            on_chain(chain)
        requester = _start_phone(adapter, opts, source.address[1], log)
        if requester is not None:
            parts.append(requester)

        target = create_context(headless=True if args.headless else None, width=opts.width, height=opts.height,
                                title=f"facepuppet run ({args.input})", log=log, samples=picture.msaa,
                                transparent=picture.transparent)
        parts.append(target)
        screen = None if target.headless else target.ctx.screen
        renderer = chain.renderer(target.ctx, character, opts.width, opts.height, args.path, screen, log,
                                  **picture.renderer_kwargs(),
                                  credits=character.credits if picture.credits else None)
        parts.append(renderer)

        weights = WeightLog() if keep_weights or getattr(args, "dump_weights", None) is not None else None
        sinks = ([weights] if weights is not None else []) + ([PngSink(args.out)] if args.out is not None else [])
        if opts.video is not None:
            video = VideoSink(opts.video, opts.loop_fps)
            log(opts.video.describe(opts.loop_fps))
            if args.audio is not None and opts.video.audio is None:
                log("video: the microphone's sound is not recorded into the video (only its level is measured); "
                    "--audio-file WAV gives the video a sound track")
            parts.append(video)
            sinks.append(video)
        counters, stats, hooks = _outputs(args, opts, chain, source, recorder, parts, hooks, log, requester)
        panel = _open_panel(args, target, renderer, chain, character, stats, recorder, source, opts, log)
        if panel is not None:
            parts.append(panel)
            if on_panel is not None:
                on_panel(panel)
        elif not target.headless and chain.filter is not None:
            _bind_calibrate_key(target, chain.filter)
        loop = FrameLoop(chain.names, renderer, WallClock(), sinks=sinks, fps=opts.loop_fps, log=log,
                         target=target, stages=chain.stages, on_tick=hooks, stop=stop_event.is_set,
                         catch_up=True, idle_fps=opts.idle_fps, drive=chain.drive,
                         overlays=() if panel is None else (panel.overlay,), wake=_arrival_wake(source, chain))
        if chain.filter is not None:  # a [mapping] applied live (the panel, a recorded change) maps from then on
            chain.filter.on_config.append(follow_mapping(chain, loop, character.expressions, log))
        counters["loop"] = loop.counters
        stats.counters = _LiveCounters(source, counters, dict(chain.mix.tracker_sources()) if chain.mix else {})
        if on_ready is not None:
            on_ready(source.address)
        result = _run_loop(loop, source, args.duration, stop_event)
        counters["loop"] = result.counters
        if getattr(args, "save_profile", False) and chain.profile is not None and chain.filter is not None:
            chain.profile.save(chain.filter.current_config())
        return LiveRunResult(result, stats, weights, stats.counter_snapshot(), renderer.path, source.address,
                             chain.describe(), panel)
    except BaseException:
        for part in parts:   # a failed run leaves no half-written video
            if hasattr(part, "abort"):
                part.abort()
        raise
    finally:
        for part in reversed(parts):
            for name in ("stop", "close"):
                if hasattr(part, name):
                    getattr(part, name)()
                    break


def _open_panel(args, target, renderer, chain, character, stats, recorder, source, opts: _Options, log):
    """The operator's panel (:mod:`~facepuppet.runtime.panel`): in a window always (Tab toggles), headless only
    with ``--panel``. Without imgui-bundle a window runs without it (said once); ``--panel`` is then an error."""
    from facepuppet.runtime.panel import PanelUnavailable

    if target.headless and not getattr(args, "panel", False):
        return None
    try:
        from facepuppet.runtime.panel.desk import DeskPanel

        window_size = None
        if not target.headless:
            import glfw

            window_size = glfw.get_window_size(target.window)
        panel = DeskPanel(target.ctx, renderer.fbo, opts.width, opts.height, pipeline=chain.filter, chain=chain,
                          character=character, counters=lambda: stats.counters, stats=stats, recorder=recorder,
                          input_kind=args.input, address=f"{source.address[0]}:{source.address[1]}",
                          window_size=window_size, visible=not getattr(args, "panel_hidden", False))
    except PanelUnavailable as exc:
        if getattr(args, "panel", False):
            raise ValueError(f"--panel: {exc}") from None
        log(f"run: no panel: {exc}; the run goes on without it")
        return None
    if not target.headless:
        from facepuppet.runtime.panel.glfw_input import bind_window

        bind_window(target.window, panel,
                    on_calibrate=chain.filter.request_calibration if chain.filter is not None else None)
        log("run: the panel is shown; Tab hides or shows it")
    return panel


def _is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def _start_phone(adapter, opts: _Options, listen_port: int, log):
    """The running requester of ``--phone`` (None without it; a note when the kind needs one)."""
    from facepuppet.runtime.inputs.phone import PhoneRequester

    if not hasattr(adapter, "phone_request"):
        return None
    if opts.phone is None:
        log(f"run: no --phone: the {adapter.kind} app must be told to send here itself"
            + (" (VTube Studio's phone protocol streams only on request: give --phone IP)"
               if adapter.kind == "vtubestudio" else ""))
        return None
    host, port = opts.phone
    requester = PhoneRequester(host, port, adapter.phone_request(listen_port), adapter.phone_every_s, log=log)
    log(f"run: asking the phone at {host}:{port} to stream here (every {adapter.phone_every_s:g} s)"
        + (f"; note: iFacialMocap sends to port {adapter.default_port}, this run listens on {listen_port}"
           if adapter.kind == "ifacialmocap" and listen_port != adapter.default_port else ""))
    return requester.start()


def _outputs(args, opts: _Options, chain, source, recorder, parts: list, hooks, log,
             requester=None) -> tuple[dict, LiveStats, list]:
    """The counters the stats read, the stats, and the tick hooks: stats, VMC out, the recording."""
    counters = {"udp": source.counters}
    if requester is not None:
        counters["phone"] = requester.counters
    if chain.filter is not None:
        counters["pipeline"] = chain.filter.counters
    stats = LiveStats(counters, log=log, interval_s=1.0 if args.stats else None)
    hooks = [stats.on_tick, *hooks]
    if opts.vmc_out is not None:
        drive = chain.drive
        own = () if drive is None else tuple(p or n for n, p in zip(drive.expression_names, drive.presets))
        sender = VmcSender(opts.vmc_out[0], opts.vmc_out[1], chain.names, extra=getattr(args, "vmc_extra", False),
                           presets=getattr(args, "vmc_presets", True), expressions=own,
                           names_mode=getattr(args, "vmc_names", None) or VMC_NAMES[0],
                           status=pipeline_status(chain.filter) if chain.filter is not None else None)
        log(sender.describe())
        parts.append(sender)
        hooks.append(sender.on_tick)
        counters["vmc_out"] = sender.counters
    if opts.llf_out is not None:
        llf = LlfSender(opts.llf_out[0], opts.llf_out[1], chain.names)
        log(llf.describe())
        parts.append(llf)
        hooks.append(llf.on_tick)
        counters["llf_out"] = llf.counters
    if chain.mix is not None:
        counters["mix"] = chain.mix.counters
    if recorder is not None:
        counters["record"] = recorder.counters
        hooks.append(RecordingHook(recorder, source, chain.audio,
                                   mix_sources=[s for _, s in chain.mix.tracker_sources()] if chain.mix else ()))
    if chain.filter is not None:
        if recorder is not None:
            chain.filter.listeners.append(recorder.put_event)
        if opts.vmc_out is not None or opts.events_out is not None:
            events = TrackingEventSender([opts.events_out] if opts.events_out else [],
                                         [opts.vmc_out] if opts.vmc_out else [])
            log(events.describe())
            parts.append(events)
            chain.filter.listeners.append(events)
            counters["events_out"] = events.counters
    return counters, stats, hooks


def _run_loop(loop: FrameLoop, source, duration: float | None, stop_event: threading.Event) -> LoopResult:
    """Run the loop until ``duration``, the window closes or Ctrl-C (which sets ``stop_event``)."""
    from facepuppet.runtime.inputs.udp import UdpSource

    # A receive *thread* gives the GIL back on every recvfrom and must win it back from the busy frame
    # loop each time: a short switch interval keeps datagrams from waiting in the kernel (measured, 0.5 ms
    # vs the default 5 ms: arrival -> read p50 3 vs 7 ms, p99 16 vs 30 ms). A receive process needs none.
    switch = sys.getswitchinterval()
    if isinstance(source, UdpSource):
        sys.setswitchinterval(min(switch, THREAD_SWITCH_INTERVAL_S))
    try:
        with _sigint_sets(stop_event):
            return loop.run(source, duration=duration)
    finally:
        sys.setswitchinterval(switch)


def input_default_port(kind: str | None) -> int:
    """The default port of an input kind (0 for none)."""
    from facepuppet.runtime.inputs.kinds import INPUT_KINDS

    return 0 if kind is None else INPUT_KINDS[kind].default_port


class _LiveCounters(dict):
    """The stats' counter groups, with ``udp`` read afresh each time (UdpSource merges on access)."""

    def __init__(self, source, groups: dict, others: dict | None = None):
        super().__init__(groups)
        self._source = source
        self._others = others or {}  # the mix sources of a run with several inputs: "udp:NAME"

    def items(self):
        self["udp"] = self._source.counters
        for name, other in self._others.items():
            self[f"udp:{name}"] = other.counters
        return super().items()


class _sigint_sets:
    """Within the block (main thread only), Ctrl-C (SIGINT) and SIGTERM set ``event`` instead of ending the
    process: the loop stops at its next tick and the run closes its recording and prints its final stats."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, event: threading.Event):
        self.event = event
        self.previous: dict = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for signum in self.SIGNALS:
                self.previous[signum] = signal.signal(signum, lambda *_: self.event.set())
        return self

    def __exit__(self, *exc):
        for signum, previous in self.previous.items():
            signal.signal(signum, previous)
        self.previous = {}

    def close(self) -> None:
        self.__exit__()


def _bind_calibrate_key(target, pipeline) -> None:
    import glfw

    def on_key(window, key, scancode, action, mods):
        if key == glfw.KEY_C and action == glfw.PRESS:
            pipeline.request_calibration()

    glfw.set_key_callback(target.window, on_key)


def run_command(args: argparse.Namespace, log: Callable[[str], None] = print) -> int:
    """The ``run`` command: returns the exit code (errors are mapped to exit codes in ``cli.main``)."""
    result = run_live(args, log=log)
    loop = result.loop
    c = loop.counters
    pace = f"at {args.fps:g} fps" if getattr(args, "draw", "arrival") == "tick" or args.input == "audio" \
        else f"on arrival (idle redraw {args.fps:g} fps)"
    log(f"run: {loop.n_ticks} ticks {pace}, {result.path} path; frames received "
        f"{c['frames_received']}, stale dropped {c['stale_dropped']}, non-finite rejected "
        f"{c['nonfinite_rejected']}, late ticks "
        f"{c['late_ticks']} (skipped {c['skipped_ticks']})" + (" (window closed)" if loop.closed_by_window else ""))
    if args.stats:
        result.stats.final()
    if args.dump_weights is not None:
        from facepuppet.runtime.outputs import write_atomic

        write_atomic(args.dump_weights, lambda temp: np.save(temp, result.weights.array))
        log(f"run: wrote the weights of {loop.n_ticks} ticks to {args.dump_weights}")
    if args.out is not None:
        log(f"run: wrote {loop.n_ticks} PNGs to {args.out}")
    if args.record is not None:
        log(f"run: recorded to {args.record}")
    if getattr(args, "video", None) is not None:
        log(f"run: wrote {loop.n_ticks} video frames to {args.video}")
    return 0
