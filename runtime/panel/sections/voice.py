"""The Voice section of a run with ``--voice``: what the voice's mouth comes from, and for calibrated vowels
Re-calibrate (the live voice taken as silence and each vowel in turn, :mod:`facepuppet.runtime.voice.recalibrate`),
Cancel, and Save (the new profile over the ``--voice`` file)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from facepuppet.runtime.voice.recalibrate import Recalibration
from facepuppet.runtime.voice.vowels import VowelProfile

if TYPE_CHECKING:
    from facepuppet.runtime.panel.ui import Ui
    from facepuppet.runtime.voice.stage import VoiceStage

RECALIBRATE_S = 2.0  # seconds of each take (silence, A, I, U, E, O)


class VoiceControls:
    """What the Voice section shows between frames, and its buttons' work.

    Attributes
    ----------
    recalibration : Recalibration or None, the one in progress or last finished
    seconds : float, each take's length
    message : str, what Save did
    """

    def __init__(self) -> None:
        self.recalibration: Recalibration | None = None
        self.seconds = RECALIBRATE_S
        self.message = ""

    def key(self) -> tuple:
        """What changes the section without an event on it (the settings' window is built again when it does)."""
        r = self.recalibration
        return (None if r is None else (r.phase, r.done, r.message), self.message)

    @staticmethod
    def channels_of(voice: VoiceStage | None) -> Any:
        """The live :class:`VoiceChannels` behind the stage (None: a replay's recorded channels)."""
        return getattr(getattr(voice, "source", None), "voice", None)

    def section(self, ui: Ui, voice: VoiceStage | None) -> None:
        imgui = ui.imgui
        if voice is None or not imgui.collapsing_header("Voice", imgui.TreeNodeFlags_.default_open):
            return
        channels = self.channels_of(voice)
        model = getattr(channels, "table", None)
        kind = "calibrated vowels" if isinstance(model, VowelProfile) else \
            (f"{model.model} table" if model is not None else "the recording's channels")
        imgui.text_wrapped(f"{Path(str(voice.path)).name if voice.path else '-'}: {kind}, "
                           f"{len(voice.outputs)} channels")
        ui.remember("voice.text")
        if not isinstance(model, VowelProfile):
            return
        r = self.recalibration
        if r is None or r.done:
            if imgui.button("Re-calibrate vowels"):
                self.recalibration = Recalibration(channels, self.seconds).start()
                self.message = ""
            ui.remember("voice.recalibrate")
            if r is not None and r.profile is not None and voice.path:
                imgui.same_line()
                if imgui.button("Save"):
                    self.save(r.profile, Path(str(voice.path)))
                ui.remember("voice.save")
        else:
            if imgui.button("Cancel"):
                r.cancel()
            ui.remember("voice.cancel")
        if self.recalibration is not None:
            imgui.text_wrapped(self.recalibration.message)
            ui.remember("voice.message")
        if self.message:
            imgui.text_wrapped(self.message)

    def save(self, profile: VowelProfile, path: Path) -> None:
        try:
            profile.save(path)
        except OSError as exc:
            self.message = f"not saved: {path}: {exc.strerror or exc}"
        else:
            self.message = f"saved {path}"
