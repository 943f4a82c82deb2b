"""The Record section: Record (a file name, or blank for ``facepuppet-YYYYmmdd-HHMMSS.fps`` next to the
``--record`` file or in the current folder) and Stop, the file and its size on disk (``run``'s
:class:`~facepuppet.runtime.recording.switch.SwitchableRecorder`: each recording replays like ``--record``'s);
a plain ``--record`` recorder is only shown."""

from __future__ import annotations

from typing import TYPE_CHECKING

from facepuppet.runtime.live.profiles import config_to_toml
from facepuppet.runtime.panel.apply import config_in_force

if TYPE_CHECKING:
    from facepuppet.runtime.live.pipeline import LivePipeline
    from facepuppet.runtime.panel.status import InputStatus
    from facepuppet.runtime.panel.ui import Ui
    from facepuppet.runtime.recording.recorder import PacketRecorder
    from facepuppet.runtime.recording.switch import SwitchableRecorder


class RecordControls:
    """What the Record section keeps between frames (the name typed), and its buttons' work.

    Parameters
    ----------
    status : InputStatus, whose numbers hold the recording's file and size (refreshed with the status, and at
        once after a start or stop)

    Attributes
    ----------
    name : str, the Record field (blank: a name from the date and time)
    """

    def __init__(self, status: InputStatus) -> None:
        self.status = status
        self.name = ""

    def section(self, ui: Ui, rec: SwitchableRecorder | PacketRecorder | None, pipeline: LivePipeline | None) -> None:
        """The section; a button pressed is done at once (:meth:`action`)."""
        imgui = ui.imgui
        if not imgui.collapsing_header("Record", imgui.TreeNodeFlags_.default_open):
            return
        shown = self.status.numbers.get("record")
        recording = bool(getattr(rec, "recording", rec is not None))
        if shown is None:
            imgui.text("not recording" if rec is not None else "record: off (--record FILE)")
        else:
            size = "-" if shown[1] is None else f"{shown[1] / 1e6:.2f} MB"
            imgui.text_wrapped(f"{'recording' if recording else 'stopped'}: {shown[0]} ({size})")
        if not hasattr(rec, "start"):
            return
        action = None
        imgui.push_id("record")  # the button "Record" is not the header "Record"
        if recording:
            if imgui.button("Stop"):
                action = "stop"
            ui.remember("record.stop")
        else:
            if imgui.button("Record"):
                action = "start"
            ui.remember("record.start")
            imgui.same_line()
            imgui.set_next_item_width(-1)
            _, self.name = imgui.input_text_with_hint("##record_name", "file (default: facepuppet-DATE-TIME)",
                                                      self.name)
            ui.remember("record.name")
        imgui.pop_id()
        if rec.message and not (recording and rec.message == f"recording to {rec.path}"):  # not the line above again
            imgui.text_wrapped(rec.message)
        if action is not None:
            self.action(action, rec, pipeline)

    def action(self, action: str, rec: SwitchableRecorder, pipeline: LivePipeline | None) -> None:
        """``start`` a recording (to :attr:`name`, blank: the default name; the config in force its first
        CONFIG) or ``stop`` it; a failure is in the recorder's message and loses nothing."""
        if action == "stop":
            rec.stop()
        elif action == "start":
            text = None
            if pipeline is not None:
                text = config_to_toml(config_in_force(pipeline))
            try:
                rec.start(self.name, config_text=text)
            except (OSError, ValueError):
                pass  # said in rec.message, shown under the buttons
        else:
            raise ValueError(f"record action: expected start or stop, got {action!r}")
        self.status.refresh_record()  # the new file and its size at once
