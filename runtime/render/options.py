"""The render options ``run``, ``replay``, ``demo`` and ``contact-sheet`` share: framing, background,
MSAA and the credits corner.

``--background transparent`` clears to alpha 0: headless frames are RGBA PNGs
(alpha 0 where nothing is drawn, for compositing over other video), and a
window asks the platform for a transparent framebuffer (glfw
``TRANSPARENT_FRAMEBUFFER``; the run says when it is not granted).
``--background R,G,B`` is a colour, 0..1 or 0..255 per channel.
``--msaa N`` multisamples (capped at what the context allows; 0 = off); without it, ``--quality``
decides (:mod:`~facepuppet.runtime.render.quality`: 4 for pictures kept, fitted to the frame budget live).
"""

from __future__ import annotations

import argparse
import re
from dataclasses import dataclass

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.render.quality import DEFAULT_MSAA, DEFAULT_QUALITY, QUALITIES, Quality, choose_quality

# "body": the camera fits every drawn vertex; "head": the vertices that follow the humanoid head bone
# (every drawn vertex for a character without one: a head rig); "face": what expressions move (contact sheets).
# (Here, not in renderer.py, so that the command line is parsed without importing moderngl.)
FRAMINGS = ("body", "head", "face")

DEFAULT_BACKGROUND = (0.16, 0.17, 0.19)


@dataclass(frozen=True)
class RenderOptions:
    """What the render options asked for.

    Attributes
    ----------
    framing : str, one of FRAMINGS
    background : tuple of 3 float, display RGB 0..1 (unused when transparent)
    transparent : bool
    msaa : int or None, samples asked for (0 = off; None: as ``quality`` decides)
    quality : str, one of QUALITIES
    credits : bool, draw the character's attribution in a corner
    """

    framing: str = "head"
    background: tuple[float, float, float] = DEFAULT_BACKGROUND
    transparent: bool = False
    msaa: int | None = None
    quality: str = DEFAULT_QUALITY
    credits: bool = False

    def renderer_kwargs(self, quality: Quality | None = None) -> dict:
        """Keyword arguments of FaceRenderer for these options (the credits text is the caller's); ``quality``:
        the picture chosen (:func:`~facepuppet.runtime.render.quality.choose_quality`), default the one of
        a picture that is kept."""
        if quality is None:
            quality = choose_quality(self.msaa, self.quality, None, live=False)
        return {"framing": self.framing, "background": self.background, "transparent": self.transparent,
                "msaa": quality.msaa, "subtle_layers": quality.subtle_layers}


def parse_background(text: str) -> tuple[tuple[float, float, float], bool]:
    """``"transparent"`` or ``"R,G,B"`` (0..1, or 0..255 when any exceeds 1) -> (colour 0..1, transparent)."""
    if text.strip().lower() == "transparent":
        return DEFAULT_BACKGROUND, True
    parts = re.split(r"\s*,\s*", text.strip())
    try:
        rgb = [float(p) for p in parts]
    except ValueError:
        rgb = []
    if len(rgb) != 3 or any(not (0 <= c <= 255) for c in rgb):
        raise UsageError(f"--background: expected 'transparent' or R,G,B (0..1 or 0..255), got {text!r}")
    scale = 255.0 if any(c > 1 for c in rgb) else 1.0
    return (rgb[0] / scale, rgb[1] / scale, rgb[2] / scale), False


def add_render_arguments(parser: argparse.ArgumentParser, framing: str = "head", credits: bool = True) -> None:
    """Add --framing, --background, --msaa (and --credits) to ``parser``."""
    group = parser.add_argument_group("picture", "how the character is framed and drawn")
    group.add_argument("--framing", choices=FRAMINGS, default=framing,
                       help="camera fits the whole body, the head (what follows the head bone; a head rig "
                            f"whole) or what the expressions move (face); default {framing}")
    group.add_argument("--background", default=None, metavar="transparent|R,G,B",
                       help="'transparent' (RGBA PNG frames with alpha 0 where nothing is drawn; a transparent "
                            "window where the platform allows) or a colour R,G,B (0..1 or 0..255)")
    group.add_argument("--msaa", type=int, default=None, metavar="N",
                       help=f"multisample anti-aliasing samples (0 = off; capped at what the OpenGL context "
                            f"allows; default: as --quality decides, {DEFAULT_MSAA} at full quality)")
    group.add_argument("--quality", choices=QUALITIES, default=DEFAULT_QUALITY,
                       help="picture quality: 'full' (MSAA and every layer, whatever it costs), 'fast' (no "
                            "MSAA, no subtle eye layers) or 'auto' (the default: full for pictures kept as "
                            "files; live, fast on a software rasteriser, and MSAA off when the draw takes more "
                            "than half the frame budget; said once)")
    if credits:
        group.add_argument("--credits", action="store_true",
                           help="draw the character's attribution (VRM meta / licence) in a corner")


def render_options(args: argparse.Namespace) -> RenderOptions:
    """RenderOptions from parsed arguments (missing options take their defaults); ValueError on bad values."""
    background, transparent = DEFAULT_BACKGROUND, False
    text = getattr(args, "background", None)
    if text is not None:
        background, transparent = parse_background(text)
    msaa = getattr(args, "msaa", None)
    if msaa is not None and int(msaa) < 0:
        raise UsageError(f"--msaa: expected 0 (off) or a number of samples, got {msaa}")
    quality = getattr(args, "quality", DEFAULT_QUALITY) or DEFAULT_QUALITY
    if quality not in QUALITIES:
        raise UsageError(f"--quality: expected one of {', '.join(QUALITIES)}, got {quality!r}")
    return RenderOptions(framing=getattr(args, "framing", "head"), background=background,
                         transparent=transparent, msaa=None if msaa is None else int(msaa), quality=quality,
                         credits=bool(getattr(args, "credits", False)))
