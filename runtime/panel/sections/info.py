"""The Chain, character section: the stage chain, the character's name, shape count and credits (closed at
start)."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from facepuppet.runtime.live.stages import Chain
    from facepuppet.runtime.model.character import Character
    from facepuppet.runtime.panel.ui import Ui

#: characters the panel's font (ImGui's built-in, ASCII) lacks, written as ASCII
_NOT_IN_FONT = str.maketrans({"→": "->", "—": "-", "–": "-", "×": "x", "µ": "u", "©": "(c)", "’": "'", "“": '"',
                              "”": '"'})


def ascii_text(text: str) -> str:
    """``text`` for the panel's font: arrows and dashes as ASCII, anything else outside ASCII as '?'."""
    return text.translate(_NOT_IN_FONT).encode("ascii", "replace").decode("ascii")


def info_section(ui: Ui, chain: Chain | None, character: Character | None) -> None:
    imgui = ui.imgui
    shown = imgui.collapsing_header("Chain, character")
    ui.remember("header.chain")
    if not shown:
        return
    if chain is not None:
        imgui.text_wrapped(ascii_text(chain.describe()))
        ui.remember("chain.text")
    ch = character
    if ch is not None:
        imgui.text_wrapped(ascii_text(f"character: {ch.name}, {len(ch.shape_names)} shapes"))
        ui.remember("character.text")
        if getattr(ch, "credits", None):
            imgui.text_wrapped(ascii_text(f"credits: {ch.credits}"))
