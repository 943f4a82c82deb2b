"""The per-frame chain of ``run`` and ``replay``: one ordered list of stages, built in one place.

:func:`build_chain` turns the options both commands share into the stages the
frame loop runs every tick, in this order (each present only when asked for):

=========  ============================================  ===================================================
stage      what it does                                  module
=========  ============================================  ===================================================
audio      samples the voice level once per tick         :class:`AudioTap` (here)
voice      samples the learned mouth once per tick       :mod:`facepuppet.runtime.voice.stage` (``--voice``)
mix        several inputs: each channel and the head     :mod:`facepuppet.runtime.live.mix` (``--input A
           from the first live source in its order       --input B``, ``[mix]`` in ``--config``)
solve      marker frame -> actuations s -> the           :mod:`facepuppet.runtime.actuation.stage`
           character's weights and head rotation         (Shin & Lee eq 5, §6.2; ``--actor``/``--pair``)
filter     One Euro filter, calibration, gain/clamp,     :mod:`facepuppet.runtime.live.pipeline`
           tracking-loss easing                          (``--config``, ``--calibrate``)
gestures   voice-driven blinks, brows, head motion       :mod:`facepuppet.runtime.gestures.layer`
                                                         (Ju & Lee, ``--gestures``)
kpls       the tracker's channels -> the character's     :class:`KplsStage` (here) over
           shapes by kernel PLS                          :mod:`facepuppet.runtime.kpls.stage` (``--retarget``)
=========  ============================================  ===================================================

then the frame loop maps the last frame's channels by name onto what the
renderer draws (``map``) and draws (``draw``; through the elastic path with
``--elastic``, :mod:`facepuppet.runtime.render.paths.elastic`). The chain is
printed at start, e.g. ``stages: markers→solve→filter→gestures→kpls→map→draw``.

Why this order: the solve turns markers into the character's weights, so the
filter, calibration and tracking loss act on weights (marker positions would not
survive them); the gestures add to the filtered face; the kernel-PLS model was
trained on the tracker's channels, so it runs on them after they are filtered and
calibrated in their own space. Every stage sees tick times only, so a replay on
recorded time computes what the live run did.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.actuation.pair import ActorPair
from facepuppet.runtime.actuation.saturation import SaturationCount
from facepuppet.runtime.actuation.stage import ActorRetarget
from facepuppet.runtime.elastic.model import ElasticModel
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.gestures.layer import gesture_layer
from facepuppet.runtime.inputs.kinds import make_adapter
from facepuppet.runtime.inputs.markers import UNIT_METRES, MarkersAdapter
from facepuppet.runtime.inputs.openseeface import OpenSeeFaceAdapter
from facepuppet.runtime.inputs.vmc import VmcAdapter
from facepuppet.runtime.kpls.stage import KplsRetarget
from facepuppet.runtime.live.bus import SessionBus
from facepuppet.runtime.live.config import LiveConfig, load_live_config
from facepuppet.runtime.live.mapper import Mapper, follow_mapping
from facepuppet.runtime.live.pipeline import LivePipeline
from facepuppet.runtime.live.profiles import Profile, parse_config_text, profile_path
from facepuppet.runtime.mapping.expressions import ExpressionDrive, expression_spellings, make_drive
from facepuppet.runtime.model.look_at import look_at_of_character
from facepuppet.runtime.voice.stage import HybridMouth, VoiceStage, with_voice

if TYPE_CHECKING:
    import moderngl

    from facepuppet.runtime.model.character import Character
    from facepuppet.runtime.protocols import InputAdapter, Renderer, Stage
    from facepuppet.runtime.session.options import StageOptions

logger = logging.getLogger(__name__)


class AudioTap:
    """The ``audio`` stage: the voice level (dBFS) sampled once per tick, for the stages after it.

    Parameters
    ----------
    level : callable taking the tick time (s) and returning dBFS (NaN: none): a microphone or a WAV
        (:func:`~facepuppet.runtime.inputs.audio.open_audio`), or the levels a recording kept

    :attr:`value` is the tick's level; :meth:`level` hands it to the stages that take a level callable
    (the filter stamps it on its frames, the gestures step on it) and the recorder keeps it, so the
    value a stage used is the value a replay gives it back.
    """

    name = "audio"

    def __init__(self, level: Callable[[float], float]) -> None:
        self.source = level
        self.value = math.nan

    def __call__(self, frame: Frame | None, t: float) -> Frame | None:
        self.value = float(self.source(t))
        return frame

    def level(self, t: float | None = None) -> float:
        """The level sampled this tick (``t`` is accepted for the level-callable interface and ignored)."""
        return self.value


class RecordedLevels:
    """The audio levels a live recording kept, one per tick time: a level callable for :class:`AudioTap`."""

    def __init__(self, levels: Iterable[tuple[float, float]]) -> None:
        self._by_t = {float(t): float(v) for t, v in levels}

    def __call__(self, t: float) -> float:
        return self._by_t.get(float(t), math.nan)

    def __len__(self) -> int:
        return len(self._by_t)


class KplsStage:
    """The ``kpls`` stage: a frame of the tracker's channels -> a frame of the character's shapes.

    Parameters
    ----------
    model : KplsRetarget (``apply(frame) -> ndarray (n_targets,) float32 or None``)
    """

    name = "kpls"

    def __init__(self, model: KplsRetarget) -> None:
        self.model = model
        self.channels = tuple(model.target_names)

    def __call__(self, frame: Frame | None, t: float) -> Frame | None:
        if frame is None:
            return None
        weights = self.model.apply(frame)
        if weights is None:
            return None
        return Frame(t=frame.t, source=frame.source, channels=self.channels, weights=weights,
                     head_rotation=frame.head_rotation, head_translation=frame.head_translation,
                     audio_level=frame.audio_level, t_sender=frame.t_sender, number=frame.number)


@dataclass
class Chain:
    """What :func:`build_chain` assembled.

    Attributes
    ----------
    input : str, what feeds the chain (the input kind, ``audio`` for voice only, or a recording's kind)
    stages : tuple of Stage, in the order the frame loop runs them
    names : tuple of str, the channels the renderer draws (the character's shapes, or the elastic channels)
    filter : LivePipeline or None, the filter stage (the window's key C requests a calibration of it)
    audio : AudioTap or None
    elastic : ElasticModel or None, the elastic path's tables
    extra_names : tuple of str, input channel names beyond the trackers' own (muscles)
    marker_units : str or None, the units the solve wants marker frames in (the actor's), None without one
    mapper : Mapper, the ``map`` step: channels onto ``names``, through the drive of a character with VRM
        expressions (or a ``[mapping]`` in ``--config``), else a ChannelMap by name (``FrameLoop(mapper=...)``;
        the panel reads the same maps)
    drive : ExpressionDrive or None, the mapper's drive in force
    config : LiveConfig, the live config the chain started with (``--config``, ``--profile`` or a recording's)
    profile : Profile or None, ``--profile``'s file (Save / Save as / Revert)
    known_channels : tuple of str, the names a config's ``[channels.NAME]`` may use (to parse a config later)
    mix : MixStage or None, the mix of a run with several inputs (:meth:`add_mix`)
    voice : VoiceStage or None, the learned mouth of ``--voice``
    """

    input: str
    stages: tuple[Stage, ...] = ()
    names: tuple[str, ...] = ()
    filter: LivePipeline | None = None
    audio: AudioTap | None = None
    elastic: ElasticModel | None = None
    extra_names: tuple[str, ...] = field(default_factory=tuple)
    marker_units: str | None = None
    mapper: Mapper | None = None
    config: Any = None
    profile: Any = None
    known_channels: tuple[str, ...] = ()
    mix: Any = None
    voice: VoiceStage | None = None

    @property
    def drive(self) -> ExpressionDrive | None:
        return self.mapper.drive if self.mapper is not None else None

    @property
    def saturation(self) -> SaturationCount | None:
        """The marker solve's count of frames at its limits, or None without a solve stage."""
        solve = next((stage for stage in self.stages if getattr(stage, "name", None) == "solve"), None)
        return None if solve is None else solve.saturation

    def add_mix(self, mix: Any, label: str | None = None) -> None:
        """Put the ``mix`` stage in the chain: after the audio tap, before every other stage; ``label`` names the
        inputs in :meth:`describe` (e.g. ``livelinkface+audio``)."""
        at = (self.audio is not None) + (self.voice is not None)
        self.stages = (*self.stages[:at], mix, *self.stages[at:])
        self.mix = mix
        if label is not None:
            self.input = label

    def describe(self) -> str:
        """``stages: vmc→filter→gestures→map→draw`` (``draw(elastic)`` on the elastic path)."""
        draw = "draw(elastic)" if self.elastic is not None else "draw"
        return "stages: " + "→".join([self.input, *(s.name for s in self.stages), "map", draw])

    def renderer(self, ctx: moderngl.Context, character: Character, width: int, height: int, path: str,
                 target_fbo: moderngl.Framebuffer | None, log: Callable[[str], None], **options: Any) -> Renderer:
        """The renderer the loop draws with (an :class:`~facepuppet.runtime.render.paths.elastic.ElasticDraw`
        with ``--elastic``); ``options`` are FaceRenderer's picture options (framing, background, ...)."""
        from facepuppet.runtime.render.renderer import FaceRenderer

        if self.elastic is None:
            return FaceRenderer(ctx, character, width, height, path=path, target_fbo=target_fbo, log=log, **options)
        from facepuppet.runtime.render.paths.elastic import ElasticDraw

        r = FaceRenderer(ctx, character, width, height, path="elastic", target_fbo=target_fbo, log=log,
                         elastic=self.elastic, **options)
        return ElasticDraw(r, self.elastic)


def build_chain(options: StageOptions, character: Character, input_kind: str | None, *,
                bus: SessionBus | None = None, filtered: bool = True,
                audio_level: Callable[[float], float] | None = None, voice_only: bool = False,
                label: str | None = None, log: Callable[[str], None] = logger.info,
                config_text: tuple[str, str] | None = None, schedule: Sequence[tuple[float, str, str]] = (),
                keep_snapshots: bool = False, voice: Any = None) -> Chain:
    """The stage chain for the stage options, checked against the character; logs what it loaded.

    Parameters
    ----------
    options : StageOptions (``--actor``, ``--pair``, ``--retarget``, ``--elastic``, ``--config``, ``--profile``,
        ``--calibrate``, ``--gestures``, ``--gesture-seed``)
    character : Character, what is drawn
    input_kind : str or None, the input kind of the frames (None: unknown, e.g. a recording of frames)
    bus : SessionBus or None, the session's: the filter stage publishes config changes and tracking events on
        it and reads its calibration requests (None: a bus of the chain's own)
    filtered : bool, include the ``filter`` stage (``run`` always; ``replay`` with ``--pipeline``)
    audio_level : callable t -> dBFS or None; adds the ``audio`` stage
    voice_only : bool, the face from the voice alone (``run --input audio``): the gestures drive it
    label : str or None, what :meth:`Chain.describe` names as the input (default ``input_kind``)
    config_text : (where, TOML text) or None, the config to start from when neither ``--config`` nor
        ``--profile`` is given (a recording's config in force)
    schedule : (tick time, TOML text, where) triples, config changes the filter applies at those ticks (a
        recording's; ``where`` names the record in messages)
    keep_snapshots : bool, the filter keeps its state before each tick (a recording may start mid-run)
    voice : the voice's channel source (``outputs``, ``channels(t)``) of ``--voice``, or None; adds the ``voice``
        stage (and ``hybrid`` after the filter with ``--voice-mode hybrid``)

    Raises
    ------
    ValueError
        naming the option and file when a table does not fit the character or the input,
        or when markers input lacks ``--actor``/``--pair``.
    """
    bus = bus if bus is not None else SessionBus()
    shapes = tuple(character.shape_names)
    chain = Chain(input=label or input_kind or "recording", names=shapes)
    elastic = _load_elastic(options.elastic, character, log) if options.elastic is not None else None
    if elastic is not None:
        chain.elastic, chain.names, chain.extra_names = elastic, tuple(elastic.channel_names), \
            tuple(elastic.muscle_names)
    solve = _load_solve(options.actor, options.pair, options.retarget, shapes, input_kind, log)
    kpls = _load_kpls(options.retarget, shapes, log) if options.retarget is not None else None
    voice_table = getattr(options, "voice", None)
    if voice_only and options.gestures is None and voice_table is None:
        raise UsageError("--input audio: needs --gestures GESTURES.npz or --voice VOICE.npz, and --audio [DEVICE] "
                         "or --audio-file WAV")
    stages = []
    if audio_level is not None:
        chain.audio = AudioTap(audio_level)
        stages.append(chain.audio)
    if voice is not None:
        chain.voice = VoiceStage(voice, make_frame=voice_only, path=str(voice_table or ""))
        stages.append(chain.voice)
        log(f"voice: {voice_table} ({len(chain.voice.outputs)} mouth channels, "
            f"{'the voice alone' if voice_only else getattr(options, 'voice_mode', 'loss')})")
    if solve is not None:
        stages.append(solve)
        chain.marker_units = solve.actor.units
    level = chain.audio.level if chain.audio is not None else None
    known = (*shapes, *chain.names, *chain.extra_names, *(kpls.model.source_names if kpls is not None else ()),
             *(chain.voice.outputs if chain.voice is not None else ()),
             *expression_spellings(character))
    chain.known_channels = known
    if options.config is not None and options.profile is not None:
        raise UsageError("--config and --profile: choose one (a profile is a config file with its neutral; "
                         "--profile PATH.toml reads any config file)")
    if options.profile is not None:
        chain.profile = Profile(profile_path(options.profile), character=Path(options.character).name if
                                options.character is not None else "", input_kind=input_kind or "",
                                known_channels=known, log=log)
        config = chain.profile.load()
    elif options.config is not None:
        config = load_live_config(options.config, known)
    elif config_text is not None:
        config = parse_config_text(config_text[1], config_text[0], known)
    else:
        config = LiveConfig()
    chain.config = config
    drive = None
    if elastic is None:  # the elastic path draws its own channels, not the character's shapes
        drive = make_drive(shapes, character.expressions, config.mapping, look_at=look_at_of_character(character))
        if drive is not None and input_kind == "vmc":
            # VMC names its channels: the avatar's expression names arrive as channels of their own
            chain.extra_names = tuple(dict.fromkeys((*chain.extra_names, *drive.receive_names())))
    elif not config.mapping.empty:
        raise UsageError(f"--config {options.config}: [mapping] drives a character's shapes and expressions; "
                         "it does not apply with --elastic")
    chain.mapper = Mapper(chain.names, drive, log=log)
    if filtered:
        changes = [(float(t), parse_config_text(text, where, known)) for t, text, where in schedule]
        chain.filter = LivePipeline(config, audio_level=level, log=log, bus=bus, schedule=changes,
                                    keep_snapshots=keep_snapshots)
        if options.calibrate:
            chain.filter.request_calibration()
        stages.append(chain.filter)
        if chain.voice is not None:  # tracking lost: mouth = "voice" is the learned mouth
            chain.filter.generator = with_voice(chain.voice)
        if elastic is None:  # a [mapping] applied live (the panel, a recorded change) maps from then on
            bus.on_config(follow_mapping(chain.mapper, character.expressions, log))
    if options.gestures is not None:
        layer = gesture_layer(options.gestures, voice_only=voice_only, log=log, level=level,
                              seed=options.gesture_seed)
        stages.append(layer)
        if chain.filter is not None:  # tracking lost: the voice / idle regions take the layer's face
            chain.filter.generator = lambda t: layer.compose(None, t)
            if chain.voice is not None:  # ... with the learned mouth over it
                chain.filter.generator = with_voice(chain.voice, chain.filter.generator)
    if chain.voice is not None and getattr(options, "voice_mode", "loss") == "hybrid" and not voice_only:
        stages.insert(stages.index(chain.filter) + 1 if chain.filter is not None else len(stages),
                      HybridMouth(chain.voice))
    if kpls is not None:
        stages.append(kpls)
    chain.stages = tuple(stages)
    return chain


def _load_elastic(path, character, log):
    model = ElasticModel.load(path)
    if model.n_vertices != character.n_vertices or tuple(model.shape_names) != tuple(character.shape_names):
        raise UsageError(f"--elastic {path}: made for {model.n_vertices} vertices and "
                         f"{len(model.shape_names)} shapes, not for the character's {character.n_vertices} "
                         f"vertices and {character.n_shapes} shapes in order")
    log(f"elastic: {path} ({model.n_controls} control points, k={model.k}, "
        f"{len(model.muscle_names)} muscles: {', '.join(model.muscle_names) or 'none'})")
    return model


def _load_solve(actor_path, pair_path, retarget_path, shapes, input_kind, log):
    """The ``solve`` stage of ``--actor``/``--pair``, or None; checks they come together and fit."""
    if (actor_path is None) != (pair_path is None):
        raise UsageError("--actor and --pair go together (the actor's solve, then its pair table for this character)")
    if input_kind == "markers" and actor_path is None:
        raise UsageError("--input markers: needs --actor ACTOR.npz and --pair PAIR.npz (train-actor, retarget-actor) "
                         "to turn marker frames into the character's weights")
    if actor_path is None:
        return None
    if input_kind not in ("markers", None):
        raise UsageError(f"--actor/--pair: only for --input markers, not {input_kind!r}")
    if retarget_path is not None:
        raise UsageError("--actor/--pair and --retarget: choose one parameter space")
    pair = ActorPair.load(pair_path)
    if tuple(pair.shape_names) != shapes:
        raise UsageError(f"--pair {pair_path}: its shapes ({len(pair.shape_names)}) are not the shapes of the "
                         f"character ({len(shapes)}) in order; make it with retarget-actor for this character")
    actor = Actor.load(actor_path)
    try:
        stage = ActorRetarget(actor, pair, log=log)
    except ValueError as exc:
        raise UsageError(f"--actor {actor_path} / --pair {pair_path}: {exc}") from None
    log(f"actor: {actor_path} ({actor.n_markers} markers, K={actor.n_actuations}) -> pair {pair_path}")
    return stage


def _load_kpls(path, shapes, log) -> KplsStage:
    model = KplsRetarget.load(path)
    if tuple(model.target_names) != shapes:
        raise UsageError(f"--retarget {path}: its target shapes ({len(model.target_names)}) "
                         f"are not the shapes of the character ({len(shapes)}) in order")
    log(f"retarget: {path} ({model.kernel} kernel, {len(model.source_names)} source "
        f"shapes -> {len(model.target_names)} character shapes)")
    return KplsStage(model)


def make_input_adapter(kind: str, extra_names: Sequence[str] = (),
                       log: Callable[[str], None] = logger.info, *, marker_units: str | None = None,
                       to_units: str | None = None, face_id: int | None = None) -> InputAdapter:
    """A new adapter of ``kind`` that also carries ``extra_names`` channels where its protocol can (VMC).

    For ``openseeface``: ``face_id`` is the face to follow (``--face-id``; None: the first of each datagram).

    For ``markers``: ``marker_units`` are the frames' units where a layout declares none
    (``--marker-units``), ``to_units`` the units the solve wants (the actor's); frames are converted.
    """
    if kind == "markers" and (marker_units is not None or to_units is not None):
        if to_units is not None and to_units not in UNIT_METRES:
            log(f"note: the actor's units {to_units!r} are not one of {', '.join(UNIT_METRES)}; "
                "marker frames are not converted")
            to_units = None
        return MarkersAdapter(units=marker_units, to_units=to_units)
    if kind == "openseeface" and face_id is not None:
        adapter = OpenSeeFaceAdapter(face_id=face_id)
        if extra_names:
            log(f"note: --input {kind} cannot name channels {tuple(extra_names)[:3]}...; "
                "only VMC blend names reach them")
        return adapter
    if extra_names and kind == "vmc":
        return VmcAdapter(extra_names=extra_names)
    if extra_names:
        log(f"note: --input {kind} cannot name channels {tuple(extra_names)[:3]}...; only VMC blend names reach them")
    return make_adapter(kind)
