"""What the parts of one session tell each other while it runs, through one small bus the session owns.

Five kinds of news cross from one part to others; each has one publisher and any number of subscribers,
all known when the session is assembled:

===============  =======================================  ==============================================
news             published by                             heard by
===============  =======================================  ==============================================
config           the filter stage, when a config takes    the recorder (a CONFIG record), the mix (its
                 effect (applied live, scheduled by a     orders), the map (a ``[mapping]`` builds the
                 replay, or a captured neutral)           drive again), the panel
tracking         the filter stage: tracking lost (False)  the recorder (EVENT records), the OSC event
                 or found (True) at a tick time           sender, a replay comparing with the recording
calibration      the frame source's count of calibrate    the filter stage, which calibrates when the
requests         messages (``/facepuppet/calibrate``)     sum grows
packets          the receivers: each accepted datagram    the recorder
control          the control stage: a command applied at  the recorder (a CONTROL record)
                 a tick (an expression fired, framing)
===============  =======================================  ==============================================

Config and tracking news and the calibration count are read on the frame-loop thread; packets arrive on a
receive thread (or at the tick hook for the process receiver), so their subscribers must not block. The
bus holds the last config published (:attr:`SessionBus.config`), which is what a recording opened later
writes in its header.

Subscribing after the session has started is allowed (the panel's own listeners), but a part that must not
miss the first news subscribes while the session is assembled, before the sources start.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

ConfigListener = Callable[[float, Any], None]
TrackingListener = Callable[[float, bool], None]
PacketListener = Callable[[bytes, float, "tuple | None", "str | None"], None]
ControlListener = Callable[[float, dict], None]


class SessionBus:
    """Config changes, tracking events, calibration requests and datagrams between the parts of one session.

    Parameters
    ----------
    packets : bool, whether datagrams are wanted at all (a recording is possible): without, :meth:`packet_sink`
        is None and the receivers do not copy datagrams to this process

    Attributes
    ----------
    config : the config in force as last published (a LiveConfig), or None before the filter stage exists
    """

    def __init__(self, packets: bool = False) -> None:
        self.wants_packets = bool(packets)
        self.config: Any = None
        self._config: list[ConfigListener] = []
        self._tracking: list[TrackingListener] = []
        self._packets: list[PacketListener] = []
        self._request_counts: list[Callable[[], int]] = []
        self._control: list[ControlListener] = []

    # -- config -----------------------------------------------------------------------------------

    def on_config(self, listener: ConfigListener) -> None:
        """Call ``listener(t, config)`` each time a config takes effect at tick time ``t``."""
        self._config.append(listener)

    def publish_config(self, t: float, config: Any) -> None:
        self.config = config
        for listener in self._config:
            listener(t, config)

    # -- tracking ---------------------------------------------------------------------------------

    def on_tracking(self, listener: TrackingListener) -> None:
        """Call ``listener(t, found)`` on each tracking event (False: lost, True: found again)."""
        self._tracking.append(listener)

    def publish_tracking(self, t: float, found: bool) -> None:
        for listener in self._tracking:
            listener(t, found)

    # -- calibration requests ---------------------------------------------------------------------

    def count_requests(self, count: Callable[[], int]) -> None:
        """Add a growing count of calibration requests (a source's ``watched`` calibrate messages)."""
        self._request_counts.append(count)

    def calibration_requests(self) -> int:
        """The sum of the counts given to :meth:`count_requests` (only grows)."""
        return sum(int(count()) for count in self._request_counts)

    # -- control commands -------------------------------------------------------------------------

    def on_control(self, listener: ControlListener) -> None:
        """Call ``listener(t, command)`` for each control command applied at tick time ``t`` (a JSON object)."""
        self._control.append(listener)

    def publish_control(self, t: float, command: dict) -> None:
        for listener in self._control:
            listener(t, command)

    # -- datagrams --------------------------------------------------------------------------------

    def on_packet(self, listener: PacketListener) -> None:
        """Call ``listener(data, t_receive, sender, tag)`` for each accepted datagram (``tag``: None for the
        loop's own input, the mix source's name for another). Only with ``packets=True``."""
        if not self.wants_packets:
            raise ValueError("SessionBus.on_packet: this bus was made without packets (packets=True)")
        self._packets.append(listener)

    def packet_sink(self, tag: str | None = None) -> Callable[..., None] | None:
        """The ``on_packet`` callable a receiver is given (None when no datagrams are wanted)."""
        if not self.wants_packets:
            return None
        listeners = self._packets

        def put(data: bytes, t_receive: float, sender: tuple | None = None) -> None:
            for listener in listeners:
                listener(data, t_receive, sender, tag)
        return put
