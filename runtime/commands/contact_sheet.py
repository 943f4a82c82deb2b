"""``facepuppet contact-sheet``: every expression shape at weight 1, labelled, in one PNG.

A character with VRM expressions gets a cell per expression too (its binds at expression weight 1,
labelled ``[Blink]``), after its shapes; ``--no-expressions`` leaves them out. A character whose
licence asks for attribution (``Character.credits``) gets it as a footer under the grid.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.model.character import Character
from facepuppet.runtime.render.images import contact_sheet, save_png, with_footer

if TYPE_CHECKING:
    import moderngl


def parse_cell(text: str) -> tuple[int, int]:
    """``"320x320"`` -> (320, 320); argparse type."""
    try:
        w, h = (int(p) for p in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 320x320, got {text!r}") from None
    if w <= 0 or h <= 0:
        raise argparse.ArgumentTypeError(f"cell size must be positive, got {text!r}")
    return w, h


def render_shapes(ctx: moderngl.Context, character: Character, cell: tuple[int, int] = (320, 320),
                  path: str = "auto", log: Callable[[str], None] = print,
                  framing: str = "face", expressions: bool = True,
                  **picture: object) -> list[tuple[str, np.ndarray]]:
    """Neutral, then each shape at weight 1, then (``expressions``) each VRM expression at weight 1.

    ``picture``: more FaceRenderer options (background, transparent, msaa).

    Returns
    -------
    list of (label, ndarray of shape (cell_h, cell_w, 3) (RGBA (…, 4) when transparent), uint8)
    """
    from facepuppet.runtime.render.renderer import FaceRenderer

    renderer = FaceRenderer(ctx, character, cell[0], cell[1], path=path, log=log, framing=framing, **picture)
    try:
        frames = []
        weights = np.zeros(character.n_shapes, dtype=np.float32)
        renderer.draw(weights)
        frames.append(("neutral", renderer.read_pixels()))
        for s, name in enumerate(character.shape_names):
            weights[:] = 0.0
            weights[s] = 1.0
            renderer.draw(weights)
            frames.append((name, renderer.read_pixels()))
        if expressions and character.expressions is not None:
            binds = character.expressions.dense(character.n_shapes)
            for e, name in enumerate(character.expressions.names):
                renderer.draw(np.clip(binds[e], 0.0, 1.0))
                frames.append((f"[{name}]", renderer.read_pixels()))
        return frames
    finally:
        renderer.close()


def run(args: argparse.Namespace) -> int:
    from facepuppet.runtime.render.gl_context import create_context
    from facepuppet.runtime.render.options import render_options

    character = Character.load(character_argument(args))
    picture = render_options(args).renderer_kwargs()
    if character.credits:
        print(f"credits: {character.credits}")
    target = create_context(headless=True)
    try:
        frames = render_shapes(target.ctx, character, args.cell, args.path, expressions=args.expressions,
                               **picture)
    finally:
        target.close()
    columns = args.columns or max(1, math.ceil(math.sqrt(len(frames) * 16 / 9 * args.cell[1] / args.cell[0])))
    sheet = contact_sheet(frames, columns)
    if character.credits:
        sheet = with_footer(sheet, character.credits)
    out = save_png(args.output, sheet)
    n_expr = len(frames) - 1 - character.n_shapes
    print(f"wrote {out}: {len(frames)} cells ({character.n_shapes} shapes"
          + (f", {n_expr} expressions" if n_expr else "") + f" + neutral), {columns} columns")
    return 0


def character_argument(args: argparse.Namespace) -> str:
    """The character file, given as the positional argument or as ``-c`` (exactly one of them)."""
    given = [x for x in (args.character, args.character_option) if x is not None]
    if len(given) != 1:
        raise SystemExit("contact-sheet: give the character once, as CHARACTER or -c CHARACTER"
                         + (f" (got {given[0]!r} and {given[1]!r})" if given else ""))
    return given[0]


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "contact-sheet", help="render every expression shape at weight 1 into one labelled PNG grid"
    )
    parser.add_argument("character", nargs="?", help="character tables file (.npz)")
    # -c as every other command that takes a character spells it
    parser.add_argument("-c", "--character", dest="character_option", metavar="CHARACTER",
                        help="the same, as an option")
    parser.add_argument("-o", "--output", required=True, help="PNG file to write")
    parser.add_argument("--cell", type=parse_cell, default=(320, 320), help="cell size WIDTHxHEIGHT (320x320)")
    parser.add_argument("--columns", type=int, default=0, help="grid columns (default: about 16:9)")
    parser.add_argument("--path", choices=("auto", "gpu", "cpu"), default="auto", help="deformation path")
    parser.add_argument("--expressions", action=argparse.BooleanOptionalAction, default=True,
                        help="a cell per VRM expression after the shapes (default on, for characters that have them)")
    from facepuppet.runtime.render.options import add_render_arguments

    add_render_arguments(parser, framing="face", credits=False)
    parser.set_defaults(func=run)
