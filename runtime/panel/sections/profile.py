"""The Profile section of a run with ``--profile`` (``chain.profile``): the file, Save, Save as (a name or a
path), Revert, what the last of them did, and a warning when the profile was made for another character or
input (its settings then apply by channel name)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from facepuppet.runtime.errors import FacepuppetError
from facepuppet.runtime.live.profiles import read_made_for
from facepuppet.runtime.panel.apply import config_in_force

if TYPE_CHECKING:
    from facepuppet.runtime.live.config import LiveConfig
    from facepuppet.runtime.live.pipeline import LivePipeline
    from facepuppet.runtime.live.profiles import Profile
    from facepuppet.runtime.panel.ui import Ui


class ProfileControls:
    """What the Profile section shows between frames, and its buttons' work.

    Attributes
    ----------
    name : str, the Save as field (a profile name or a path to a .toml file)
    message : str, what the last Save / Save as / Revert did (or why it failed)
    warning : str, the profile was made for another character or input ("" when not)
    """

    def __init__(self) -> None:
        self.name = ""
        self.message = ""
        self.warning = ""
        self._checked: object = None  # the profile path the warning was computed for

    def check(self, profile: Profile) -> None:
        """The mismatch warning of the profile's file (read once per path and after each Save / Revert)."""
        self._checked = profile.path
        try:
            made = read_made_for(profile.path) if profile.path.exists() else {}
        except (OSError, ValueError) as exc:
            self.warning = f"cannot read {profile.path}: {exc}"
            return
        notes = [f"{what} {theirs!r} (this run: {mine!r})"
                 for what, mine in (("character", profile.character), ("input", profile.input_kind))
                 if mine and (theirs := made.get(what)) and theirs != mine]
        self.warning = ("made for " + ", ".join(notes) + "; its settings apply by channel name") if notes else ""

    def section(self, ui: Ui, profile: Profile | None, pipeline: LivePipeline,
                apply: Callable[[LiveConfig], None]) -> None:
        """The section (none without a profile); a button pressed is done at once (:meth:`action`)."""
        imgui = ui.imgui
        if profile is None or not imgui.collapsing_header("Profile", imgui.TreeNodeFlags_.default_open):
            return
        if self._checked != profile.path:
            self.check(profile)
        imgui.text_wrapped(f"{profile.path}" + ("" if profile.exists else " (not saved yet)"))
        if self.warning:
            imgui.push_style_color(imgui.Col_.text, imgui.ImVec4(1.0, 0.75, 0.2, 1.0))
            imgui.text_wrapped(f"warning: {self.warning}")
            imgui.pop_style_color()
            ui.remember("profile.warning")
        action = None
        if imgui.button("Save"):
            action = "save"
        ui.remember("profile.save")
        imgui.same_line()
        if imgui.button("Revert"):
            action = "revert"
        ui.remember("profile.revert")
        imgui.set_next_item_width(200)
        _, self.name = imgui.input_text_with_hint("##profile_name", "name or path.toml", self.name)
        ui.remember("profile.name")
        imgui.same_line()
        if imgui.button("Save as"):
            action = "save_as"
        ui.remember("profile.save_as")
        if self.message:
            imgui.text_wrapped(self.message)
        if action is not None:
            self.action(action, profile, pipeline, apply)

    def action(self, action: str, profile: Profile, pipeline: LivePipeline,
               apply: Callable[[LiveConfig], None]) -> None:
        """``save``, ``save_as`` (to :attr:`name`) or ``revert`` (the file's config handed to ``apply``) the
        profile; the outcome (or the error, which loses nothing: the config in force stays) in :attr:`message`."""
        try:
            if action == "save":
                self.message = f"saved {profile.save(config_in_force(pipeline))}"
            elif action == "save_as":
                name = self.name.strip()
                if not name:
                    self.message = "Save as: type a profile name or a path to a .toml file first"
                    return
                self.message = f"saved {profile.save_as(name, config_in_force(pipeline))}"
            elif action == "revert":
                apply(profile.revert())
                self.message = f"reverted to {profile.path}"
            else:
                raise ValueError(f"profile action: expected save, save_as or revert, got {action!r}")
        except (OSError, ValueError, FacepuppetError) as exc:
            self.message = f"{action}: failed: {exc}"
        self.check(profile)

