"""The picture quality a command draws at: full for pictures kept, fitted to the frame budget when live.

What a frame costs is mostly its fragments, and multisampling multiplies
them: on Mesa's software rasteriser (llvmpipe), 4x MSAA takes the ICT head's
draw at 640x480 from 7.7 to 19 ms (``bench render``, passes_ms), more than a
60 Hz frame by itself, while on a real GPU it costs a fraction of a
millisecond. The blended layers and the label cost little beside it. So:

* ``full``: MSAA at ``--msaa`` (default 4), whatever it costs. Pictures that
  are kept (``--out``, ``--video``, contact sheets) are drawn so.
* ``fast``: MSAA off.
* ``auto`` (the default): full when the pictures are kept; live, MSAA off on
  a software rasteriser, and off on a GPU whose measured draw takes more
  than half the frame budget, at construction or later in the run
  (:mod:`~facepuppet.runtime.live.draw_budget`). The command says once what
  it lowered and how to keep it.

An explicit ``--msaa N`` always wins.
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
    """The samples to draw with and, when lowered from what was asked, the line that says why."""

    msaa: int
    note: str = ""


def choose_msaa(msaa: int | None, quality: str, gl_renderer: str | None, live: bool) -> Quality:
    """The MSAA samples for ``--msaa`` (None: not given), ``--quality``, the context's renderer and whether the
    frames are live (shown or sent as they happen, not kept as files)."""
    if quality not in QUALITIES:
        raise ValueError(f"quality: expected one of {QUALITIES}, got {quality!r}")
    if msaa is not None:
        return Quality(int(msaa))
    if quality == "fast":
        return Quality(0)
    if quality == "full" or not live:
        return Quality(DEFAULT_MSAA)
    if is_software(gl_renderer):
        return Quality(0, f"picture quality auto: {gl_renderer} is a software rasteriser, where {DEFAULT_MSAA}x "
                          f"MSAA costs more than the rest of the draw: MSAA off to keep the frame budget "
                          f"(--quality full or --msaa {DEFAULT_MSAA} keeps it)")
    return Quality(DEFAULT_MSAA)


def budget_note(draw_ms: float, budget_ms: float, samples: int, when: str = "the first frames") -> str:
    """The line saying MSAA is turned off, when a draw of ``draw_ms`` (the median of ``when``, at ``samples``)
    takes more than the live share of a frame of ``budget_ms``; "" when it fits."""
    if samples <= 0 or draw_ms <= BUDGET_SHARE * budget_ms:
        return ""
    return (f"picture quality auto: {samples}x MSAA frames took {draw_ms:.1f} ms to draw ({when}), more than "
            f"{BUDGET_SHARE:.0%} of the {budget_ms:.1f} ms frame budget: MSAA off (--quality full or "
            f"--msaa {samples} keeps it)")
