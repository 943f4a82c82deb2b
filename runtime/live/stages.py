"""The parameter spaces of ``run`` and ``replay``: what turns input frames into what is drawn.

Both commands assemble the same stages from the same options, so a recording
replayed with a live run's options draws what the live run drew:

* ``--actor ACTOR.npz --pair PAIR.npz`` (Shin & Lee, markers input): each new
  marker frame is solved to actuations s and mapped through the pair table
  to the character's weights (:class:`~.actor_retarget.ActorRetarget`)
  *before* the live pipeline (:class:`SolvedFrames`), so filtering,
  calibration and tracking loss act on the character's weights. (The pipeline
  passes weights and pose only; marker positions would not survive it.)
* ``--retarget RETARGET.npz`` (kernel PLS): the frame loop's ``retarget``
  stage, *after* the pipeline: the tracker's channels are filtered and
  calibrated in their own space, which is the space the model was trained on.
* ``--elastic ELASTIC.npz`` (Yano & Harada): the renderer's elastic path;
  the loop draws the table's channels, shapes then muscles
  (:class:`ElasticDraw`), so input channels named after muscles (VMC
  ``/VMC/Ext/Blend/Val`` with the muscle's exact name) drive contractions.

:func:`build_stages` validates the files against the character and says what
was loaded; :func:`make_input_adapter` gives an adapter that knows the extra
channel names (muscles) where the protocol can carry them (VMC).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facepuppet.runtime.frames import Frame


class SolvedFrames:
    """Frame-loop ``pipeline`` hook: a stage turns each new frame into the character's weights, then ``inner``.

    Parameters
    ----------
    stage : object with ``target_names`` (tuple of n str) and ``apply(frame) -> ndarray (n,) float32 or None``
        (e.g. :class:`~.actor_retarget.ActorRetarget`)
    inner : callable ``(frame or None, t) -> Frame or None`` or None (the live pipeline)

    A frame the stage cannot use (no head pose, no markers) counts as no new frame.
    """

    def __init__(self, stage, inner=None):
        self.stage = stage
        self.inner = inner
        self.channels = tuple(stage.target_names)

    def __call__(self, frame: Frame | None, t: float) -> Frame | None:
        if frame is not None:
            weights = self.stage.apply(frame)
            frame = None if weights is None else Frame(
                t=frame.t, source=frame.source, channels=self.channels, weights=np.asarray(weights, np.float32),
                audio_level=frame.audio_level, t_sender=frame.t_sender, number=frame.number)
        return frame if self.inner is None else self.inner(frame, t)


class PaddedRetarget:
    """A Retarget onto some of the loop's channels (by name); the others stay 0 (e.g. muscles).

    Parameters
    ----------
    inner : Retarget, with ``target_names`` all among ``names``
    names : tuple of str, the frame loop's channels
    """

    def __init__(self, inner, names):
        self.inner = inner
        self.target_names = tuple(names)
        lookup = {n: i for i, n in enumerate(self.target_names)}
        missing = [n for n in inner.target_names if n not in lookup]
        if missing:
            raise ValueError(f"retarget: its targets {missing[:4]} are not channels of the drawn character")
        self._index = np.array([lookup[n] for n in inner.target_names], dtype=np.int64)
        self._out = np.zeros(len(self.target_names), np.float32)

    def apply(self, frame: Frame) -> np.ndarray | None:
        w = self.inner.apply(frame)
        if w is None:
            return None
        self._out[self._index] = w
        return self._out


class ElasticDraw:
    """Renderer adapter of the elastic path: ``draw(values)`` with values of the table's channels.

    Parameters
    ----------
    renderer : FaceRenderer made with ``path="elastic"``
    model : ElasticModel

    Attributes
    ----------
    shape_names : tuple of str, ``model.channel_names`` (shapes then muscles): the
        frame loop's targets (the loop reads nothing else of its ``character``)
    path : str, "elastic"
    """

    def __init__(self, renderer, model):
        if renderer.path != "elastic":
            raise ValueError(f"ElasticDraw: the renderer must use the 'elastic' path, not {renderer.path!r}")
        self.renderer = renderer
        self.model = model
        self.shape_names = tuple(model.channel_names)
        self.path = "elastic"

    def draw(self, values, head_rotation=None, head_translation=None) -> None:
        """Draw channel values, ndarray (n_shapes + n_muscles,) float32: U = Σ w P + Σ c Q, then the basis."""
        self.renderer.prepare_controls(self.model.controls(values), head_rotation, head_translation)
        self.renderer.submit()

    def finish(self) -> None:
        self.renderer.finish()

    def read_pixels(self) -> np.ndarray:
        return self.renderer.read_pixels()

    def close(self) -> None:
        self.renderer.close()


@dataclass
class Stages:
    """What :func:`build_stages` assembled.

    Attributes
    ----------
    names : tuple of str, the channels the loop draws (the character's shapes, or the elastic channels)
    before : object or None, a stage run on each new frame before the pipeline (markers solve)
    retarget : Retarget or None, the frame loop's retarget stage (after the pipeline)
    elastic : ElasticModel or None
    extra_names : tuple of str, input channel names beyond the trackers' own (muscles)
    """

    names: tuple
    before: object = None
    retarget: object = None
    elastic: object = None
    extra_names: tuple = ()

    def pipeline(self, inner):
        """The frame loop's ``pipeline`` hook around ``inner`` (None: no live pipeline)."""
        return inner if self.before is None else SolvedFrames(self.before, inner)

    def renderer(self, ctx, character, width, height, path, target_fbo, log):
        """The renderer to hand the loop (an :class:`ElasticDraw` with ``--elastic``)."""
        from facepuppet.runtime.render.renderer import FaceRenderer

        if self.elastic is None:
            return FaceRenderer(ctx, character, width, height, path=path, target_fbo=target_fbo, log=log)
        r = FaceRenderer(ctx, character, width, height, path="elastic", target_fbo=target_fbo, log=log,
                         elastic=self.elastic)
        return ElasticDraw(r, self.elastic)


def add_stage_arguments(parser, markers: bool = True) -> None:
    """The parameter-space options shared by ``run`` and ``replay``."""
    if markers:
        parser.add_argument("--actor", type=Path, default=None, metavar="ACTOR.npz",
                            help="actor table (train-actor): markers input is solved to actuations s")
        parser.add_argument("--pair", type=Path, default=None, metavar="PAIR.npz",
                            help="pair table (retarget-actor): actuations s -> the character's weights")
    parser.add_argument("--retarget", type=Path, default=None, metavar="RETARGET.npz",
                        help="kernel-PLS retarget tables (fit-retarget): the source channels -> the character's "
                             "shapes, instead of matching channel names")
    parser.add_argument("--elastic", type=Path, default=None, metavar="ELASTIC.npz",
                        help="elastic tables of the character: draw through the elastic path; input channels "
                             "named after its muscles drive contractions")


def build_stages(args, character, input_kind: str | None, log=print) -> Stages:
    """Load and check the stage files named by ``args`` (``actor``, ``pair``, ``retarget``, ``elastic``).

    Raises
    ------
    ValueError
        naming the option and file when a table does not fit the character or the input,
        or when markers input lacks ``--actor``/``--pair``.
    """
    actor_path, pair_path = getattr(args, "actor", None), getattr(args, "pair", None)
    retarget_path, elastic_path = getattr(args, "retarget", None), getattr(args, "elastic", None)
    shapes = tuple(character.shape_names)
    stages = Stages(names=shapes)
    if elastic_path is not None:
        from facepuppet.runtime.elastic.model import ElasticModel

        model = ElasticModel.load(elastic_path)
        if model.n_vertices != character.n_vertices or tuple(model.shape_names) != shapes:
            raise ValueError(f"--elastic {elastic_path}: made for {model.n_vertices} vertices and "
                             f"{len(model.shape_names)} shapes, not for the character's {character.n_vertices} "
                             f"vertices and {len(shapes)} shapes in order")
        stages.elastic, stages.names, stages.extra_names = model, tuple(model.channel_names), tuple(model.muscle_names)
        log(f"elastic: {elastic_path} ({model.n_controls} control points, k={model.k}, "
            f"{len(model.muscle_names)} muscles: {', '.join(model.muscle_names) or 'none'})")
    if (actor_path is None) != (pair_path is None):
        raise ValueError("--actor and --pair go together (the actor's solve, then its pair table for this character)")
    if input_kind == "markers" and actor_path is None:
        raise ValueError("--input markers: needs --actor ACTOR.npz and --pair PAIR.npz (train-actor, retarget-actor) "
                         "to turn marker frames into the character's weights")
    if actor_path is not None:
        if input_kind not in ("markers", None):
            raise ValueError(f"--actor/--pair: only for --input markers, not {input_kind!r}")
        if retarget_path is not None:
            raise ValueError("--actor/--pair and --retarget: choose one parameter space")
        from facepuppet.runtime.actuation.actor import Actor
        from facepuppet.runtime.actuation.pair import ActorPair
        from facepuppet.runtime.actuation.stage import ActorRetarget

        pair = ActorPair.load(pair_path)
        if tuple(pair.shape_names) != shapes:
            raise ValueError(f"--pair {pair_path}: its shapes ({len(pair.shape_names)}) are not the shapes of the "
                             f"character ({len(shapes)}) in order; make it with retarget-actor for this character")
        actor = Actor.load(actor_path)
        try:
            stages.before = ActorRetarget(actor, pair)
        except ValueError as exc:
            raise ValueError(f"--actor {actor_path} / --pair {pair_path}: {exc}") from None
        log(f"actor: {actor_path} ({actor.n_markers} markers, K={actor.n_actuations}) -> pair {pair_path}")
    if retarget_path is not None:
        from facepuppet.runtime.kpls.stage import KplsRetarget

        retarget = KplsRetarget.load(retarget_path)
        if tuple(retarget.target_names) != shapes:
            raise ValueError(f"--retarget {retarget_path}: its target shapes ({len(retarget.target_names)}) "
                             f"are not the shapes of the character ({len(shapes)}) in order")
        stages.retarget = retarget if stages.names == shapes else PaddedRetarget(retarget, stages.names)
        log(f"retarget: {retarget_path} ({retarget.kernel} kernel, {len(retarget.source_names)} source "
            f"shapes -> {len(retarget.target_names)} character shapes)")
    return stages


def make_input_adapter(kind: str, extra_names=(), log=print):
    """A new adapter of ``kind`` that also carries ``extra_names`` channels where its protocol can (VMC)."""
    from facepuppet.runtime.inputs.kinds import make_adapter

    if extra_names and kind == "vmc":
        from facepuppet.runtime.inputs.vmc import VmcAdapter

        return VmcAdapter(extra_names=extra_names)
    if extra_names:
        log(f"note: --input {kind} cannot name channels {tuple(extra_names)[:3]}...; only VMC blend names reach them")
    return make_adapter(kind)
