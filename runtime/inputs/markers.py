"""facepuppet's own OSC namespace for optical marker frames (a mocap bridge sends it).

Default port 9763. Two messages, bundled or not:

``/facepuppet/markers/layout  i layout_id, s name_0, s name_1, ... s name_{n-1}``
    Declares a layout: the marker names, in blob order (1 <= n <= 1024,
    names unique and non-empty). Send it before the first frame and again
    every second or so (UDP may lose it; receivers joining late need it).
    Re-sending the same id replaces the layout. A receiver keeps the 16 most
    recently declared layouts.

``/facepuppet/markers/frame  i layout_id, i frame_number, d sender_time, b positions``
    One frame. ``sender_time`` is seconds on the sender's clock (``d``, or
    ``f``). ``positions`` is a blob of n × 3 float32 little-endian (x, y, z of
    each marker in layout order, the sender's units, typically mm), NaN for an
    occluded marker; its size must be exactly 12·n bytes.

``/facepuppet/markers/units  i layout_id, s units``
    Optional: the units of that layout's positions, ``mm``, ``cm`` or ``m``
    (send it with each layout message). Without it a frame is in the units
    of ``--marker-units`` where given, else taken to be the actor's. When the
    adapter knows the units it is to deliver (``to_units``, the actor's), it
    converts each frame into them. A units message with other units, or for
    an id it does not know yet, counts as ``malformed``; it is kept for the
    id until a new units message replaces it.

Refused (counted, no frame): a frame for an undeclared layout id, a blob of
the wrong size, wrong types or too few arguments (``malformed``); a layout or
blob of more than 1024 markers (``oversized``); an infinite coordinate
(``nonfinite``). Extra arguments are ignored.

Example with python-osc::

    layout = OscMessageBuilder("/facepuppet/markers/layout")
    layout.add_arg(1); [layout.add_arg(n) for n in ("nose", "chin")]
    frame = OscMessageBuilder("/facepuppet/markers/frame")
    frame.add_arg(1); frame.add_arg(42); frame.add_arg(time.time(), "d")
    frame.add_arg(np.asarray(points, "<f4").tobytes(), "b")

The emitted :class:`~facepuppet.runtime.frames.Frame` has ``markers`` (n, 3)
float32, ``marker_names``, ``number`` = frame_number and ``t_sender``.
"""

from __future__ import annotations

import math

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.osc import OscAdapter, as_float

LAYOUT = "/facepuppet/markers/layout"
FRAME = "/facepuppet/markers/frame"
UNITS = "/facepuppet/markers/units"
#: metres per unit of each length unit a layout may declare
UNIT_METRES = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
MAX_MARKERS = 1024
MAX_LAYOUTS = 16


class MarkersAdapter(OscAdapter):
    """Marker frames in the ``/facepuppet/markers`` namespace (see module doc).

    Parameters
    ----------
    units : str or None, the units of frames whose layout declared none (``--marker-units``); None: as delivered
    to_units : str or None, the units to deliver frames in (the actor's); None: no conversion
    """

    kind = "markers"
    default_port = 9763

    def __init__(self, units: str | None = None, to_units: str | None = None) -> None:
        super().__init__()
        for what, u in (("units", units), ("to_units", to_units)):
            if u is not None and u not in UNIT_METRES:
                raise ValueError(f"MarkersAdapter: {what} must be one of {', '.join(UNIT_METRES)}, got {u!r}")
        self.units = units
        self.to_units = to_units
        self.layouts: dict[int, tuple[str, ...]] = {}
        self.layout_units: dict[int, str] = {}

    def scale(self, layout_id: int) -> float:
        """The factor taking layout ``layout_id``'s positions into ``to_units`` (1 when either is unknown)."""
        units = self.layout_units.get(layout_id, self.units)
        if units is None or self.to_units is None:
            return 1.0
        return UNIT_METRES[units] / UNIT_METRES[self.to_units]

    def _message(self, address: str, params: list, t: float) -> None:
        if address == LAYOUT:
            self._layout(params)
        elif address == FRAME:
            self._emit(self._frame(params, t))
        elif address == UNITS:
            self._units(params)
        else:
            self._count("unknown_address")

    def _layout(self, params: list) -> None:
        if len(params) < 2 or type(params[0]) is not int:
            self._count("malformed")
            return
        names = params[1:]
        if len(names) > MAX_MARKERS:
            self._count("oversized")
            return
        if not all(type(n) is str and n for n in names) or len(set(names)) != len(names):
            self._count("malformed")
            return
        layout_id = params[0]
        self.layouts.pop(layout_id, None)
        if len(self.layouts) >= MAX_LAYOUTS:
            del self.layouts[next(iter(self.layouts))]  # the oldest declared
        self.layouts[layout_id] = tuple(names)

    def _units(self, params: list) -> None:
        if (len(params) < 2 or type(params[0]) is not int or params[0] not in self.layouts
                or params[1] not in UNIT_METRES):
            self._count("malformed")
            return
        self.layout_units.pop(params[0], None)
        if len(self.layout_units) >= MAX_LAYOUTS:
            del self.layout_units[next(iter(self.layout_units))]
        self.layout_units[params[0]] = params[1]

    def _frame(self, params: list, t: float) -> Frame | None:
        if len(params) < 4 or type(params[0]) is not int or type(params[1]) is not int:
            self._count("malformed")
            return None
        t_sender, blob = as_float(params[2]), params[3]
        if t_sender is None or type(blob) is not bytes:
            self._count("malformed")
            return None
        if len(blob) > 12 * MAX_MARKERS:
            self._count("oversized")
            return None
        names = self.layouts.get(params[0])
        if names is None or len(blob) != 12 * len(names):
            self._count("malformed")
            return None
        markers = np.frombuffer(blob, dtype="<f4").reshape(len(names), 3)
        if np.isinf(markers).any() or math.isinf(t_sender):
            self._count("nonfinite")
            return None
        factor = self.scale(params[0])
        if factor != 1.0:
            markers = markers * np.float32(factor)
        return Frame(t=t, source=self.kind, markers=markers, marker_names=names,
                     t_sender=t_sender, number=params[1])
