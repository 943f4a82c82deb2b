"""A contact sheet of a perfect-sync character's cloned shapes, each at weight 1, rendered on its face (GL)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image

from facepuppet.runtime.live.loop import FrameLoop, RecordedClock
from facepuppet.runtime.live.stages import build_chain
from facepuppet.runtime.mapping.channels import canonical
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.recording.replay_source import DEFAULT_MAX_GAP_S, ReplaySource, open_recording
from facepuppet.runtime.render.images import contact_sheet, save_png, with_footer
from facepuppet.runtime.session.options import StageOptions

if TYPE_CHECKING:
    import moderngl


def shape_images(character: Character, names: Sequence[str], ctx: moderngl.Context,
                 size: tuple[int, int] = (240, 240)) -> list[tuple[str, np.ndarray]]:
    """[(label, (h, w, 3) uint8)]: the neutral, then each named shape at weight 1, all cropped to the square
    around every pixel any of them changes (grown by a third), so that small features fill the cells."""
    from facepuppet.runtime.render.renderer import FaceRenderer  # GL: the renderer imports moderngl

    zoom = 4
    renderer = FaceRenderer(ctx, character, size[0] * zoom, size[1] * zoom, framing="face", log=lambda line: None)
    try:
        frames = []
        for name in (None, *names):
            w = np.zeros(character.n_shapes, np.float32)
            if name is not None:
                w[character.shape_names.index(name)] = 1.0
            renderer.draw(w)
            renderer.finish()
            frames.append(("neutral" if name is None else name, renderer.read_pixels()))
    finally:
        renderer.close()
    base = frames[0][1].astype(np.int16)
    changed = np.zeros(base.shape[:2], bool)
    for _, f in frames[1:]:
        changed |= np.abs(f.astype(np.int16) - base).max(axis=2) > 12
    h, w = changed.shape
    if changed.any():
        ys, xs = np.nonzero(changed)
        centre = np.array([(xs.min() + xs.max()) / 2, (ys.min() + ys.max()) / 2])
        half = max(xs.max() - xs.min(), ys.max() - ys.min()) / 2 * 1.33 + 8
    else:
        centre, half = np.array([w / 2, h / 2]), min(w, h) / 2
    half = min(half, w / 2, h / 2)
    cx, cy = float(np.clip(centre[0], half, w - half)), float(np.clip(centre[1], half, h - half))
    box = tuple(int(round(v)) for v in (cx - half, cy - half, cx + half, cy + half))
    return [(label, np.asarray(Image.fromarray(f).crop(box).resize(size, Image.LANCZOS))) for label, f in frames]


def shape_sheet(character: Character, names: Sequence[str], path: str | os.PathLike, columns: int = 8,
                ctx: moderngl.Context | None = None) -> Path:
    """Contact sheet PNG of the neutral and the named shapes; returns its path (a standalone EGL context when
    ``ctx`` is None; GLUnavailable when there is none)."""
    own = ctx is None
    if own:
        import moderngl

        from facepuppet.runtime.render.gl_context import GLUnavailable  # GL: importing it loads moderngl

        try:
            ctx = moderngl.create_standalone_context(backend="egl", require=330)
        except Exception as exc:
            raise GLUnavailable(f"no headless EGL OpenGL 3.3 context for the contact sheet ({exc})") from None
    try:
        sheet = contact_sheet(shape_images(character, names, ctx), columns)
        return save_png(path, with_footer(sheet, character.credits) if character.credits else sheet)
    finally:
        if own:
            ctx.release()


#: The ARKit channels a VRM's presets cannot show (brows, cheeks, mouth corners, lip rolls and presses,
#: squints, sneers, the jaw sideways): the moments of a take are picked where they and the mouth/eyes move most.
PRESET_BLIND = ("browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft", "browOuterUpRight",
                "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "mouthSmileLeft", "mouthSmileRight",
                "mouthFrownLeft", "mouthFrownRight", "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft",
                "mouthStretchRight", "mouthRollLower", "mouthRollUpper", "mouthPressLeft", "mouthPressRight",
                "mouthLeft", "mouthRight", "eyeSquintLeft", "eyeSquintRight", "noseSneerLeft", "noseSneerRight",
                "jawLeft", "jawRight")
ACTIVE = (*PRESET_BLIND, "jawOpen", "eyeBlinkLeft", "eyeBlinkRight", "mouthFunnel", "mouthPucker")


def take_moments(frames: Sequence, n: int = 8) -> list[int]:
    """Indices of ``n`` frames spread over a take: in each of ``n`` equal spans of its time, the frame where the
    channels of :data:`ACTIVE` (what the presets cannot show, the jaw, the blinks) add up highest."""
    if not frames:
        raise ValueError("take_moments: the take has no frames")
    wanted = {canonical(k) for k in ACTIVE}
    scores = np.zeros(len(frames))
    for i, f in enumerate(frames):
        if f.channels is None or f.weights is None:
            continue
        keep = np.array([canonical(c) in wanted for c in f.channels], bool)
        scores[i] = float(np.nansum(np.clip(np.asarray(f.weights, np.float64)[keep], 0.0, 1.0)))
    times = np.array([f.t for f in frames], np.float64)
    edges = np.linspace(times[0], times[-1], n + 1)
    picked = []
    for a, b in zip(edges[:-1], edges[1:]):
        span = np.flatnonzero((times >= a) & (times <= b))
        span = [i for i in span if i not in picked]
        if span:
            picked.append(int(max(span, key=lambda i: scores[i])))
    return picked


class _GrabSink:
    """Keep the image of each tick the loop draws (only the few ticks of a side-by-side are drawn)."""

    def __init__(self) -> None:
        self.images: list[np.ndarray] = []

    def __call__(self, info) -> None:
        self.images.append(np.array(info.renderer.read_pixels(), copy=True))


def replay_images(character: Character, take: str | os.PathLike, ticks: Sequence[int], fps: float,
                  ctx: moderngl.Context, size: tuple[int, int],
                  camera_from: Character | None = None, path: str = "auto") -> tuple[list[np.ndarray], str]:
    """The images ``facepuppet replay TAKE -c CHARACTER --headless`` draws at the given ticks (the same frame
    source, stage chain, channel map and renderer; no filter stage, as replay of a CSV by default), framed on
    the face of ``camera_from`` (default: ``character``) so two characters are seen from one camera; and the
    deformation path they were drawn on (``path``; "auto": the faster, as replay chooses)."""
    quiet = lambda line: None  # noqa: E731
    source = ReplaySource(open_recording(take), max_gap=DEFAULT_MAX_GAP_S)
    chain = build_chain(StageOptions(), character, None, filtered=False, label="replay", log=quiet)
    renderer = chain.renderer(ctx, character, size[0], size[1], path, None, quiet, framing="face")
    if camera_from is not None and camera_from is not character:
        from facepuppet.runtime.render.renderer import FaceRenderer  # GL: the renderer imports moderngl

        probe = FaceRenderer(ctx, camera_from, size[0], size[1], framing="face", log=quiet)
        renderer.camera = probe.camera  # the same view of the same head (both are one mesh, one pose)
        probe.close()
    grab = _GrabSink()
    try:
        FrameLoop(chain.names, renderer, RecordedClock(), observers=[grab], fps=fps, log=quiet, stages=chain.stages,
                  mapper=chain.mapper).run(source, ticks=list(ticks))
    finally:
        renderer.close()
    return grab.images, renderer.path


def take_side_by_side(original: Character, synced: Character, take: str | os.PathLike,
                      path: str | os.PathLike, moments: int = 8, ctx: moderngl.Context | None = None,
                      size: tuple[int, int] = (240, 240), fps: float = 60.0) -> Path:
    """PNG of a Live Link Face take replayed at ``moments`` times on two characters, one row each: top, the
    ``original`` through its VRM presets (the default ARKit→VRM mapping), bottom, ``synced`` (its perfect-sync
    clone) by the ARKit names onto its ARKit shapes (a character without VRM presets: top, its own shapes by
    name, labelled "as imported"); each cell labelled with the take time. Both rows are
    drawn by the replay's own chain and seen from one camera (the synced character's face framing).
    Returns the path; GLUnavailable without a headless EGL context."""
    frames = open_recording(take)
    picked = take_moments(frames, moments)
    ticks = sorted({int(np.ceil(frames[i].t * fps - 1e-9)) for i in picked})
    own = ctx is None
    if own:
        ctx = _standalone()
    try:
        zoom = 2
        big = (size[0] * zoom, size[1] * zoom)
        # both rows on one deformation path: the two paths may differ by a pixel where an edge crosses one,
        # and the rows are compared by eye (and by the tests: one character in both rows gives one picture)
        top, drawn_on = replay_images(original, take, ticks, fps, ctx, big, camera_from=synced)
        rows = [top, replay_images(synced, take, ticks, fps, ctx, big, camera_from=synced, path=drawn_on)[0]]
    finally:
        if own:
            ctx.release()
    cells = []
    presets = original.expressions is not None and any(original.expressions.presets)
    for label, images in zip(("VRM presets" if presets else "as imported", "perfect sync"), rows):
        for k, image in zip(ticks, images):
            small = np.asarray(Image.fromarray(image).resize(size, Image.LANCZOS))
            cells.append((f"{label} {k / fps:.2f} s", small))
    sheet = contact_sheet(cells, len(ticks))
    credits = synced.credits or original.credits  # the attribution the character's licence asks for
    return save_png(path, with_footer(sheet, credits) if credits else sheet)


def _standalone() -> moderngl.Context:
    import moderngl

    from facepuppet.runtime.render.gl_context import GLUnavailable  # GL: importing it loads moderngl

    try:
        return moderngl.create_standalone_context(backend="egl", require=330)
    except Exception as exc:
        raise GLUnavailable(f"no headless EGL OpenGL 3.3 context for the pictures ({exc})") from None
