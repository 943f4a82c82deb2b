"""The option groups of the commands that play a character: ``run``, ``replay``, ``demo`` and the benchmarks.

Each group is a frozen dataclass with ``add_arguments(parser)`` (its options, one argparse group in
``--help``) and ``from_args(namespace)`` (the checked values; UsageError naming the option otherwise). The
argparse namespace is read here (and in :mod:`~facepuppet.runtime.session.input_options`, the groups of
what feeds a session) and nowhere else: a command parses, builds its groups once, and hands them
to :func:`~facepuppet.runtime.session.assemble.open_session`. A group read from a namespace that lacks some
of its options (a benchmark's or a test's) takes their defaults.

=================  ==========================================================  ===================
group              options                                                     commands
=================  ==========================================================  ===================
PictureOptions     --size, --path, --headless, --framing, --background,        run, replay, demo
                   --msaa, --credits, --no-springs
PacingOptions      --fps, --draw, --duration                                   run, replay, demo
StageOptions       --actor, --pair, --marker-units, --retarget, --elastic,     run, replay
                   --config, --profile, --calibrate, --gestures, --gesture-seed
OutputOptions      --out, --dump-weights, --video, --video-codec, --vmc-out,   run, replay (demo:
                   --vmc-extra, --vmc-presets, --vmc-names, --llf-out,         its pictures)
                   --events-out, --stats, --virtual-camera, --stream
LiveInputOptions   --input, --listen, --allow, --phone, --audio, --audio-file, run
                   --face-id, --receiver
RecordOptions      --record, --save-profile                                    run
PanelOptions       --panel                                                     run
ReplayInputOptions SESSION, --max-gap, --pipeline                              replay
=================  ==========================================================  ===================
"""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from facepuppet.runtime.commands.options import parse_host_port, parse_size
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.live.stream_out import StreamPlan, plan_stream
from facepuppet.runtime.live.video_out import VideoError, VideoPlan, plan_video
from facepuppet.runtime.live.virtual_camera import KEY_GREEN, VirtualCameraPlan, plan_virtual_camera
from facepuppet.runtime.live.vmc_out import VMC_NAMES
from facepuppet.runtime.render.options import RenderOptions, add_render_arguments, render_options

PATHS = ("auto", "gpu", "cpu")


def get(ns: argparse.Namespace, name: str, default: object = None) -> Any:
    """An option of ``ns``, or ``default`` when the namespace lacks it (a benchmark's or a test's)."""
    return getattr(ns, name, default)


def _positive(value, option: str) -> float:
    if not (isinstance(value, (int, float)) and value > 0):
        raise UsageError(f"{option}: expected a positive number, got {value}")
    return float(value)


# -- the picture ------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class PictureOptions:
    """How the character is drawn: size, deformation path, window or headless, the render options.

    Attributes
    ----------
    width, height : int, pixels
    path : str, the deformation path (``auto``, ``gpu``, ``cpu``)
    headless : bool, offscreen through EGL even where a display exists
    render : RenderOptions (framing, background, MSAA, credits)
    springs : bool, simulate the character's spring bones (``--no-springs``: rigid)
    """

    width: int = 1280
    height: int = 720
    path: str = "auto"
    headless: bool = False
    render: RenderOptions = field(default_factory=RenderOptions)
    springs: bool = True

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser, size: str = "1280x720",
                      headless_help: str = "render offscreen through EGL (no window)") -> None:
        parser.add_argument("--headless", action="store_true", help=headless_help)
        parser.add_argument("--size", default=size, help=f"image size WIDTHxHEIGHT (default {size})")
        parser.add_argument("--path", choices=PATHS, default="auto", help="deformation path")
        add_render_arguments(parser)
        parser.add_argument("--no-springs", dest="springs", action="store_false",
                            help="leave a VRM avatar's spring bones (hair, ribbons) rigid instead of simulating them")

    @classmethod
    def from_args(cls, ns: argparse.Namespace) -> PictureOptions:
        width, height = parse_size(get(ns, "size", "1280x720"))
        path = get(ns, "path", "auto")
        if path not in PATHS:
            raise UsageError(f"--path: expected one of {', '.join(PATHS)}, got {path!r}")
        render = render_options(ns)
        if get(ns, "virtual_camera") is not None and get(ns, "background") is None:  # a camera's key colour
            render = dataclasses.replace(render, background=KEY_GREEN)
        return cls(width, height, path, bool(get(ns, "headless", False)), render, bool(get(ns, "springs", True)))


# -- ticks ------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class PacingOptions:
    """When ticks happen and for how long.

    Attributes
    ----------
    fps : float or None, ticks per second (None: the command's own default, e.g. a live recording's rate)
    draw : str, ``arrival`` (draw as soon as a new frame arrives) or ``tick`` (a fixed ``fps`` grid)
    duration : float or None, seconds (None: until the source ends or the run is stopped)
    """

    fps: float | None = 60.0
    draw: str = "arrival"
    duration: float | None = None

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser, fps: float | None, fps_help: str, duration: float | None,
                      duration_help: str, draw: bool = False) -> None:
        parser.add_argument("--fps", type=float, default=fps, help=fps_help)
        if draw:
            parser.add_argument("--draw", choices=("arrival", "tick"), default="arrival",
                                help="'arrival' (default): draw as soon as a new frame arrives (lowest latency); "
                                     "'tick': draw on a fixed --fps grid")
        parser.add_argument("--duration", type=float, default=duration, help=duration_help)

    @classmethod
    def from_args(cls, ns: argparse.Namespace, fps: float | None = 60.0) -> PacingOptions:
        value = get(ns, "fps", fps)
        if value is not None:
            value = _positive(value, "--fps")
        duration = get(ns, "duration", None)
        if duration is not None and not (duration > 0):
            raise UsageError(f"--duration: expected a positive number of seconds, got {duration}")
        return cls(value, get(ns, "draw", "arrival"), None if duration is None else float(duration))


# -- the stage chain --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class StageOptions:
    """What turns input frames into what is drawn (:func:`~facepuppet.runtime.live.stages.build_chain`).

    Attributes
    ----------
    actor, pair : Path or None, the marker solve's tables (Shin & Lee)
    marker_units : str or None, units of marker frames whose layout declares none
    retarget : Path or None, kernel-PLS tables
    elastic : Path or None, the elastic path's tables
    config : Path or None, the live config (TOML)
    profile : str or None, a saved live config by name or path
    calibrate : bool, capture the neutral from the first frames
    gestures : Path or None, the gesture tables (Ju & Lee)
    gesture_seed : int
    character : Path or None, the character's file (a profile notes what it was made for)
    """

    actor: Path | None = None
    pair: Path | None = None
    marker_units: str | None = None
    retarget: Path | None = None
    elastic: Path | None = None
    config: Path | None = None
    profile: str | None = None
    calibrate: bool = False
    gestures: Path | None = None
    gesture_seed: int = 0
    character: Path | None = None

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser, markers: bool = True) -> None:
        group = parser.add_argument_group(
            "stage chain", "what turns input frames into what is drawn; the same options give the same chain in "
            "run and replay (audio, solve, filter, gestures, kpls, then map and draw)")
        if markers:
            group.add_argument("--actor", type=Path, default=None, metavar="ACTOR.npz",
                               help="actor table (train-actor): markers input is solved to actuations s")
            group.add_argument("--pair", type=Path, default=None, metavar="PAIR.npz",
                               help="pair table (retarget-actor): actuations s -> the character's weights")
            group.add_argument("--marker-units", choices=("mm", "cm", "m"), default=None,
                               help="units of marker frames whose layout declares none (/facepuppet/markers/units); "
                                    "frames are converted to the actor's units (default: taken to be the actor's)")
        group.add_argument("--retarget", type=Path, default=None, metavar="RETARGET.npz",
                           help="kernel-PLS retarget tables (fit-retarget): the source channels -> the character's "
                                "shapes, instead of matching channel names")
        group.add_argument("--elastic", type=Path, default=None, metavar="ELASTIC.npz",
                           help="elastic tables of the character: draw through the elastic path; input channels "
                                "named after its muscles drive contractions")
        group.add_argument("--config", type=Path, default=None,
                           help="TOML config: filters, per-channel response, blink linking, mirror, tracking loss")
        group.add_argument("--profile", default=None, metavar="NAME|PATH",
                           help="a saved live config, neutral included: NAME under $XDG_CONFIG_HOME/facepuppet/"
                                "profiles (~/.config/...), or a .toml path; created by its first Save; instead of "
                                "--config")
        group.add_argument("--calibrate", action="store_true",
                           help="capture the neutral pose from the first 0.5 s of frames")
        group.add_argument("--gestures", type=Path, default=None, metavar="GESTURES.npz",
                           help="gesture tables (build-gestures): add voice-driven blinks, brows and head motion")
        group.add_argument("--gesture-seed", type=int, default=0, help="seed of the gesture synthesis (default 0)")

    @classmethod
    def from_args(cls, ns: argparse.Namespace) -> StageOptions:
        config, profile = get(ns, "config"), get(ns, "profile")
        if config is not None and profile is not None:
            raise UsageError("--config and --profile: choose one (a profile is a config file with its neutral; "
                             "--profile PATH.toml reads any config file)")
        character = get(ns, "character")
        return cls(get(ns, "actor"), get(ns, "pair"), get(ns, "marker_units"), get(ns, "retarget"),
                   get(ns, "elastic"), config, profile, bool(get(ns, "calibrate", False)), get(ns, "gestures"),
                   int(get(ns, "gesture_seed", 0) or 0), None if character is None else Path(character))

    def recorded(self) -> dict:
        """The options a recording's header keeps so that ``replay`` can rebuild the chain (as text)."""
        values = {"config": self.config, "profile": self.profile, "calibrate": self.calibrate,
                  "actor": self.actor, "pair": self.pair, "marker_units": self.marker_units,
                  "retarget": self.retarget, "elastic": self.elastic, "gestures": self.gestures,
                  "gesture_seed": self.gesture_seed}
        return {name: None if value is None else str(value) for name, value in values.items()}


# -- outputs ----------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class OutputOptions:
    """What a session writes and sends besides the picture on screen; the same on ``run`` and ``replay``.

    Attributes
    ----------
    out : Path or None, a folder for one PNG per tick
    dump_weights : Path or None, the weights of every tick (.npy)
    video : VideoPlan or None (``--video``, ``--video-codec``, its sound ``--audio-file``)
    vmc_out, llf_out, events_out : (host, port) or None, where the face is sent as VMC / Live Link Face, and
        where tracking lost / found go as OSC
    vmc_extra, vmc_presets : bool; vmc_names : str (``both``, ``arkit`` or ``vrm``)
    stats : bool, the command's counters and timings (each second and at exit live; one JSON line replayed)
    virtual_camera : VirtualCameraPlan or None (``--virtual-camera [DEVICE]``)
    stream : StreamPlan or None (``--stream URL``)
    """

    out: Path | None = None
    dump_weights: Path | None = None
    video: VideoPlan | None = None
    vmc_out: tuple[str, int] | None = None
    vmc_extra: bool = False
    vmc_presets: bool = True
    vmc_names: str = VMC_NAMES[0]
    llf_out: tuple[str, int] | None = None
    events_out: tuple[str, int] | None = None
    stats: bool = False
    virtual_camera: VirtualCameraPlan | None = None
    stream: StreamPlan | None = None

    @property
    def sends(self) -> bool:
        """Whether anything is sent over the network or to a camera (a receiver expects real time)."""
        return (self.vmc_out is not None or self.llf_out is not None or self.events_out is not None
                or self.virtual_camera is not None or self.stream is not None)

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser, stats_help: str, sound_help: str | None = None) -> None:
        """The outputs; ``sound_help``: the command has no audio input of its own, ``--audio-file`` is only the
        video's sound (``run`` defines ``--audio-file`` as an input, which is the video's sound too)."""
        group = parser.add_argument_group("outputs", "what the session writes and sends, besides what is drawn")
        group.add_argument("--out", type=Path, default=None, metavar="DIR",
                           help="write each drawn tick as DIR/frame_00000.png, numbered 0, 1, 2, ... (what "
                                "ffmpeg -i DIR/frame_%%05d.png reads); DIR/frames.csv says each one's tick and time")
        group.add_argument("--dump-weights", type=Path, default=None, metavar="FILE.npy",
                           help="save the rig weights of every tick, (n_ticks, n_shapes) float32, at exit")
        group.add_argument("--video", type=Path, default=None, metavar="FILE",
                           help="encode the drawn ticks as a video: .mp4 (H.264, default), .mkv, .mov, .webm (VP9); "
                                "with --audio-file as its sound; frames with alpha as VP9 (.webm) or ProRes 4444 "
                                "(.mov)")
        group.add_argument("--video-codec", default=None, metavar="CODEC",
                           help="with --video, the FFmpeg encoder (default: the container's, e.g. libx264 for .mp4)")
        if sound_help is not None:
            group.add_argument("--audio-file", type=Path, default=None, metavar="WAV", help=sound_help)
        group.add_argument("--vmc-out", default=None, metavar="HOST:PORT",
                           help="send the face and head as VMC: the 52 ARKit shapes (perfect sync), the VRM 0.x "
                                "presets derived from them, the head bone")
        group.add_argument("--vmc-extra", action="store_true",
                           help="with --vmc-out, also send the character's channels outside ARKit (e.g. "
                                "CheekRaiserLeft)")
        group.add_argument("--vmc-presets", action=argparse.BooleanOptionalAction, default=True,
                           help="with --vmc-out, also send the VRM 0.x presets (Blink, A, I, U, E, O, ...; default "
                                "on); --no-vmc-presets for a perfect-sync avatar whose preset clips move the same "
                                "shapes")
        group.add_argument("--vmc-names", choices=VMC_NAMES, default=None,
                           help="with --vmc-out and a character with VRM expressions: 'both' (default) sends the 52 "
                                "ARKit shapes and the avatar's own expressions (VRM 0.x preset names Blink, A, Joy, "
                                "..., custom ones by name) with the values drawn; 'vrm' only the expressions; "
                                "'arkit' the 52 and the presets derived from them, as for an OBJ rig")
        group.add_argument("--llf-out", default=None, metavar="HOST:PORT",
                           help="send the face and head as Live Link Face packets (the phone's UDP format; Unreal's "
                                "Live Link listens on port 11111)")
        group.add_argument("--events-out", default=None, metavar="HOST:PORT",
                           help="send tracking lost/found as OSC /facepuppet/tracking i (1 found, 0 lost) here "
                                "(also sent to --vmc-out when given)")
        group.add_argument("--stats", action="store_true", help=stats_help)
        group.add_argument("--virtual-camera", nargs="?", const="auto", default=None, metavar="DEVICE",
                           help="also show the picture as a webcam (pyvirtualcam: v4l2loopback under Linux, e.g. "
                                "/dev/video7; default the first loopback device), at the run's frame rate, over a "
                                "green key colour unless --background names another; a missing device is said "
                                "with the command that makes it, and the run goes on")
        group.add_argument("--stream", default=None, metavar="URL",
                           help="also send the picture as a live MPEG-TS H.264 stream to udp://HOST:PORT (OBS: "
                                "Media Source, input udp://@:PORT) or srt://HOST:PORT (where FFmpeg has libsrt); "
                                "nothing listens here")

    @classmethod
    def from_args(cls, ns: argparse.Namespace, picture: PictureOptions) -> OutputOptions:
        vmc_out = parse_host_port(get(ns, "vmc_out"), "--vmc-out") if get(ns, "vmc_out") else None
        for flag, given in (("--vmc-extra", bool(get(ns, "vmc_extra", False))),
                            ("--no-vmc-presets", not get(ns, "vmc_presets", True)),
                            ("--vmc-names", get(ns, "vmc_names") is not None)):
            if given and vmc_out is None:
                raise UsageError(f"{flag}: needs --vmc-out HOST:PORT")
        llf_out = parse_host_port(get(ns, "llf_out"), "--llf-out") if get(ns, "llf_out") else None
        events_out = parse_host_port(get(ns, "events_out"), "--events-out") if get(ns, "events_out") else None
        fps, render = get(ns, "fps"), picture.render
        camera = get(ns, "virtual_camera")
        camera = None if camera is None else plan_virtual_camera(
            camera, picture.width, picture.height, fps, render.background, render.transparent)
        stream = get(ns, "stream")
        stream = None if stream is None else plan_stream(stream, picture.width, picture.height, fps,
                                                         render.background, render.transparent)
        return cls(get(ns, "out"), get(ns, "dump_weights"), _video_plan(ns, picture), vmc_out,
                   bool(get(ns, "vmc_extra", False)), bool(get(ns, "vmc_presets", True)),
                   get(ns, "vmc_names") or VMC_NAMES[0], llf_out, events_out, bool(get(ns, "stats", False)),
                   camera, stream)


def _video_plan(ns: argparse.Namespace, picture: PictureOptions) -> VideoPlan | None:
    """The checked plan of ``--video`` (None without it); refuses a stray ``--video-codec``."""
    video, codec = get(ns, "video"), get(ns, "video_codec")
    if video is None:
        if codec is not None:
            raise VideoError("--video-codec: needs --video FILE")
        return None
    return plan_video(video, picture.width, picture.height, codec=codec, alpha=picture.render.transparent,
                      audio_file=get(ns, "audio_file"))


# -- the operator's panel --------------------------------------------------------------------------------

@dataclass(frozen=True)
class PanelOptions:
    """The operator's panel: in a window always (Tab toggles it), headless only with ``--panel``.

    Attributes
    ----------
    panel : bool, ``--panel`` (headless: draw it into the frames; needed, not optional, then)
    hidden : bool, start with it hidden (the latency benchmark's alternate ticks)
    """

    panel: bool = False
    hidden: bool = False

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--panel", action="store_true",
                            help="with --headless: draw the operator's panel into the frames (--out, --video); in a "
                                 "window the panel is shown anyway and Tab hides or shows it (needs the extra "
                                 "'panel': imgui-bundle)")

    @classmethod
    def from_args(cls, ns: argparse.Namespace) -> PanelOptions:
        return cls(bool(get(ns, "panel", False)), bool(get(ns, "panel_hidden", False)))
