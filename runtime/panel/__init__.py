"""The operator's panel of ``run``: a Dear ImGui window drawn over the frame through our own moderngl context.

* :mod:`~facepuppet.runtime.panel.gl`: ImGui's draw data onto moderngl (``shaders/panel.glsl``).
* :mod:`~facepuppet.runtime.panel.desk`: the panel of a run (:class:`DeskPanel`): its ImGui contexts, when each is
  built (:mod:`~facepuppet.runtime.panel.retained`), its draw; what it shows and edits in
  :mod:`~facepuppet.runtime.panel.status`, :mod:`~facepuppet.runtime.panel.channels` and
  :mod:`~facepuppet.runtime.panel.sections`, drawn through :mod:`~facepuppet.runtime.panel.ui`.
* :mod:`~facepuppet.runtime.panel.glfw_input`: a window's keyboard and mouse fed to ImGui; Tab toggles.

The GUI library is the optional extra ``panel`` (``pip install 'facepuppet[panel]'``, imgui-bundle);
:func:`load_imgui` says so clearly when it is missing, and ``run`` keeps working without it.
"""

from __future__ import annotations

from typing import Any

from facepuppet.runtime.errors import FacepuppetError

INSTALL_HINT = "pip install 'facepuppet[panel]' (imgui-bundle)"


class PanelUnavailable(FacepuppetError, RuntimeError):
    """The panel's GUI library (imgui-bundle) is not installed."""


def load_imgui() -> Any:
    """The ``imgui_bundle.imgui`` module.

    Raises
    ------
    PanelUnavailable
        when imgui-bundle is not installed (the message says how to install it).
    """
    try:
        from imgui_bundle import imgui
    except ImportError as exc:
        raise PanelUnavailable(f"the panel needs imgui-bundle, which is not installed ({exc}); {INSTALL_HINT}") \
            from None
    return imgui
