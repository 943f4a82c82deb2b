"""The panel's sections, one module each: the Response of the selected channel (in the desk's window) and the
settings' sections.

A section draws its widgets through a :class:`~facepuppet.runtime.panel.ui.Ui` (ImGui, and ``ui.remember(label)``
after each widget an operator may aim at) and is given only the part of the run it shows. How it acts depends on
what it changes:

* a section that edits the config (:mod:`.response`, :mod:`.filters`, :mod:`.face`, :mod:`.tracking_loss`) is
  a function ``(ui, config_now, ...) -> LiveConfig | None``: ``config_now()`` is the config in force this frame
  (read only once its header is open), the result the edited copy (``dataclasses.replace``), which the panel
  hands to the pipeline (:meth:`~facepuppet.runtime.panel.desk.DeskPanel.apply`), or None for no change;
* a section whose buttons act on a file (:mod:`.profile`, :mod:`.record`) is a small class holding what it
  shows between frames (the name typed, the last message); its ``section`` draws and, on a button, calls its
  ``action`` (which the panel also offers: ``profile_action``, ``record_action``);
* :mod:`.calibration` calls the pipeline's own calibrate and clear, at once (its line shows the new state in
  the same frame); :mod:`.info` only shows; :mod:`.voice` (with ``--voice``) re-calibrates the vowels from the
  live voice and saves the new profile.
"""
