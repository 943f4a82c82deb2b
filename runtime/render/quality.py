"""The picture quality a command draws at: full for pictures kept, fitted to the frame budget when live.

What a frame costs is mostly its fragments, and multisampling multiplies
them: on Mesa's software rasteriser (llvmpipe), 4x MSAA takes the ICT head's
draw at 640x480 from 7.7 to 19 ms (``bench render``, passes_ms), more than a
60 Hz frame by itself, while on a real GPU it costs a fraction of a
millisecond. Next come the subtle see-through eye layers of an OBJ rig
(:data:`~facepuppet.runtime.render.layers.SUBTLE_LAYER_KINDS`: the lids'
shadow on the eye, the wet films): drawn two-sided and blended, their
triangles cost about twice an opaque one's on a software rasteriser
(``bench render`` passes_ms, ``blended``), for a few pixels of shading in
the eyes. The lashes, which draw the eye line, are never dropped. So:

* ``full``: MSAA at ``--msaa`` (default 4) and every layer, whatever it
  costs. Pictures that are kept (``--out``, ``--video``, contact sheets) are
  drawn so.
* ``fast``: MSAA off, the subtle eye layers off.
* ``auto`` (the default): full when the pictures are kept; live, on a
  software rasteriser, MSAA and the subtle eye layers off; on a GPU, MSAA
  off when the measured draw takes more than half the frame budget, at
  construction or later in the run (:mod:`~facepuppet.runtime.live.draw_budget`).
  The command says once what it lowered and how to keep it.

An explicit ``--msaa N`` always wins for the samples.
"""

from __future__ import annotations

from dataclasses import dataclass

QUALITIES = ("auto", "full", "fast")
DEFAULT_QUALITY = "auto"
DEFAULT_MSAA = 4
#: GL_RENDERER names of rasterisers that run on the CPU (Mesa's llvmpipe and softpipe, SwiftShader, Apple's
#: and Microsoft's software renderers).
SOFTWARE_RASTERISERS = ("llvmpipe", "softpipe", "swiftshader", "software rasterizer", "software renderer",
                        "swrast", "gdi generic", "microsoft basic render")
#: Live, a draw may take at most this share of the frame budget (the rest: snapshot, map, the panel, the
#: compositor, and a margin for a loaded machine).
BUDGET_SHARE = 0.5


def is_software(gl_renderer: str | None) -> bool:
    """Whether ``GL_RENDERER`` names a software rasteriser."""
    name = (gl_renderer or "").lower()
    return any(s in name for s in SOFTWARE_RASTERISERS)


@dataclass(frozen=True)
class Quality:
    """The samples to draw with, whether the subtle eye layers are drawn and, when something was lowered
    from full quality, the line that says why."""

    msaa: int
    subtle_layers: bool = True
    note: str = ""


def choose_quality(msaa: int | None, quality: str, gl_renderer: str | None, live: bool) -> Quality:
    """The picture for ``--msaa`` (None: not given), ``--quality``, the context's renderer and whether the
    frames are live (shown or sent as they happen, not kept as files)."""
    if quality not in QUALITIES:
        raise ValueError(f"quality: expected one of {QUALITIES}, got {quality!r}")
    if quality == "fast":
        return Quality(0 if msaa is None else int(msaa), subtle_layers=False)
    if quality == "full" or not live or not is_software(gl_renderer):
        return Quality(DEFAULT_MSAA if msaa is None else int(msaa))
    if msaa is not None:  # the samples asked for; the layers still fitted to the software rasteriser
        return Quality(int(msaa), False, f"picture quality auto: {gl_renderer} is a software rasteriser: the "
                                         f"subtle eye layers (lid shadow, wet film) left out to keep the frame "
                                         f"budget (--quality full keeps them)")
    return Quality(0, False, f"picture quality auto: {gl_renderer} is a software rasteriser, where {DEFAULT_MSAA}x "
                             f"MSAA costs more than the rest of the draw: MSAA off, and the subtle eye layers "
                             f"(lid shadow, wet film) left out, to keep the frame budget (--quality full keeps "
                             f"both, --msaa {DEFAULT_MSAA} the MSAA)")


def budget_note(draw_ms: float, budget_ms: float, samples: int, when: str = "the first frames") -> str:
    """The line saying MSAA is turned off, when a draw of ``draw_ms`` (the median of ``when``, at ``samples``)
    takes more than the live share of a frame of ``budget_ms``; "" when it fits."""
    if samples <= 0 or draw_ms <= BUDGET_SHARE * budget_ms:
        return ""
    return (f"picture quality auto: {samples}x MSAA frames took {draw_ms:.1f} ms to draw ({when}), more than "
            f"{BUDGET_SHARE:.0%} of the {budget_ms:.1f} ms frame budget: MSAA off (--quality full or "
            f"--msaa {samples} keeps it)")
