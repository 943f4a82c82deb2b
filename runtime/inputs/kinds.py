"""Registry of live input kinds: the ``--input KIND`` name -> its adapter class.

=============  =====================================  ============  =========================
kind           adapter                                default port  protocol
=============  =====================================  ============  =========================
vmc            :class:`.vmc.VmcAdapter`               39539         VMC over OSC (§1)
facecap        :class:`.facecap.FaceCapAdapter`       9000          Face Cap OSC (§3)
faceosc        :class:`.faceosc.FaceOscAdapter`       8338          FaceOSC (§4)
markers        :class:`facepuppet.runtime.inputs.markers.MarkersAdapter`   9763          /facepuppet/markers OSC
livelinkface   :class:`facepuppet.runtime.inputs.livelinkface.LiveLinkFaceAdapter`  11111  binary UDP (§5)
ifacialmocap   :class:`facepuppet.runtime.inputs.ifacialmocap.IFacialMocapAdapter`  49983  UDP text (§7)
vtubestudio    :class:`facepuppet.runtime.inputs.vtubestudio.VTubeStudioAdapter`    21412  UDP JSON (§8)
openseeface    :class:`facepuppet.runtime.inputs.openseeface.OpenSeeFaceAdapter`    11573  binary UDP (§9)
=============  =====================================  ============  =========================

(§ = PROTOCOLS.md sections.) The phone kinds (ifacialmocap, vtubestudio) also have
``phone_port``, ``phone_every_s`` and ``phone_request(listen_port)``: what ``run --phone`` sends
(:mod:`facepuppet.runtime.inputs.phone`). Every adapter has ``kind``, ``default_port``,
``counters`` and ``handle(data, t_receive) -> Frame | None``, which never raises.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.inputs.facecap import FaceCapAdapter
from facepuppet.runtime.inputs.faceosc import FaceOscAdapter
from facepuppet.runtime.inputs.ifacialmocap import IFacialMocapAdapter
from facepuppet.runtime.inputs.livelinkface import LiveLinkFaceAdapter
from facepuppet.runtime.inputs.markers import MarkersAdapter
from facepuppet.runtime.inputs.openseeface import OpenSeeFaceAdapter
from facepuppet.runtime.inputs.vmc import VmcAdapter
from facepuppet.runtime.inputs.vtubestudio import VTubeStudioAdapter

if TYPE_CHECKING:
    from facepuppet.runtime.protocols import InputAdapter

INPUT_KINDS: dict[str, type] = {
    "vmc": VmcAdapter,
    "facecap": FaceCapAdapter,
    "faceosc": FaceOscAdapter,
    "markers": MarkersAdapter,
    "livelinkface": LiveLinkFaceAdapter,
    "ifacialmocap": IFacialMocapAdapter,
    "vtubestudio": VTubeStudioAdapter,
    "openseeface": OpenSeeFaceAdapter,
}


def make_adapter(kind: str) -> InputAdapter:
    """A new adapter for input kind ``kind``.

    Raises
    ------
    UsageError (a ValueError)
        when ``kind`` is not one of :data:`INPUT_KINDS`, listing them (a kind named by an option or a
        recording; the reader of a recording says which file).
    """
    try:
        cls = INPUT_KINDS[kind]
    except (KeyError, TypeError):
        raise UsageError(f"unknown input kind {kind!r}; expected one of: {', '.join(INPUT_KINDS)}") from None
    return cls()


def default_port(kind: str) -> int:
    """The default UDP port of input kind ``kind`` (ValueError when unknown)."""
    return make_adapter(kind).default_port
