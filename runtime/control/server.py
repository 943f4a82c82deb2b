"""The control API's WebSocket server and its two pages (``run --web``), on an asyncio loop in a thread of its own.

One TCP port answers three things: ``GET /`` the operator's remote panel, ``GET /view`` the view page (an OBS
Browser Source), and ``/ws`` the WebSocket the pages and scripts speak JSON over (the verbs of
:mod:`~facepuppet.runtime.control.commands`). Nothing here runs on the frame loop's thread but
:meth:`ControlServer.wants_frame` and :meth:`ControlServer.offer_frame`, which look at a flag and swap one slot:
the loop never waits for a client.

**These are servers** (:mod:`~facepuppet.runtime.control.limits` holds the bounds):

* loopback unless ``--web`` names another host, which then needs a token (``?token=`` on every URL);
* the ``Host`` header of a loopback server must name it (a DNS-rebound name is refused), and a WebSocket
  upgrade whose ``Origin`` is not this server's own pages is refused with 403 before the handshake: a page
  the user happens to open elsewhere cannot drive the show through localhost (scripts send no Origin and
  are let in; with a token they must give it);
* messages over MAX_MESSAGE_BYTES close the connection (1009), a client over its rate is answered with an
  error, malformed JSON and bad commands are answered with an error naming the field and counted, and a
  client that keeps sending refused messages is closed (1008);
* every send to a client is bounded by STALL_S: a client that does not read (a stalled tab, a slow link) is
  dropped and counted; frames are never queued for a client, each gets the newest one when it is ready.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import json
import logging
import threading
import time
from collections.abc import Callable
from importlib import resources
from typing import Any
from urllib.parse import parse_qs

from facepuppet.runtime.control.commands import FRAMINGS, SHOW_VERBS, VERBS, Command, CommandError, parse_command
from facepuppet.runtime.control.limits import (
    MAX_CLIENTS,
    MAX_MESSAGE_BYTES,
    MAX_QUEUE,
    MAX_REFUSED,
    STALL_S,
    WRITE_LIMIT,
    RateLimit,
)
from facepuppet.runtime.control.options import is_loopback
from facepuppet.runtime.control.view_frames import encode, now_ms
from facepuppet.runtime.files.json_limits import JsonTextError, dumps_strict, loads_limited

logger = logging.getLogger(__name__)

PAGES = {"/": "remote.html", "/view": "view.html"}


def _page(name: str) -> bytes:
    return resources.files("facepuppet.runtime.control").joinpath("pages", name).read_bytes()


class _Client:
    """One WebSocket client: its rate, what it asked to be sent, and at what rate."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.limit = RateLimit()
        self.refused_in_a_row = 0
        self.rate = 0.0  # status + weights messages per second (subscribe)
        self.view_fps = 0.0  # view frames per second (view)
        self.sent_frame = -1
        self.wake = asyncio.Event()


class ControlServer:
    """The WebSocket server and its pages (see the module docstring).

    Parameters
    ----------
    host, port : where to listen (port 0: any free port; :attr:`address` says which)
    token : str or None, what every request must carry as ``?token=``
    submit : callable(Command) -> bool, hands a show command to the control stage (False: its inbox is full)
    answer : callable(verb) -> dict, the ``list`` and ``status`` replies and the ``weights`` of a subscription,
        built from what the frame loop last published (:class:`~facepuppet.runtime.control.show.ShowState`)
    view_fps : float, the most frames per second any view page is sent

    Attributes
    ----------
    counters : the ``web`` counter group: connections, refused (host, token, origin, busy), malformed, bad
        commands, rate-limited, oversize closes, clients dropped for not reading, view frames sent
    """

    def __init__(self, host: str, port: int, *, token: str | None, submit: Callable[[Command], bool],
                 answer: Callable[[str], dict], view_fps: float = 30.0,
                 log: Callable[[str], None] = logger.info) -> None:
        self.host, self.port = host, port
        self.token = token
        self.submit, self.answer = submit, answer
        self.view_fps = float(view_fps)
        self.log = log
        self.counters = dict.fromkeys(
            ("connections", "refused_host", "refused_token", "refused_origin", "refused_busy", "messages", "malformed",
             "bad_commands", "rate_limited", "closed_oversize", "closed_refused", "dropped_slow", "view_frames_sent",
             "view_frames_encoded"), 0)
        self.clients: set[_Client] = set()
        self.viewers = 0  # read by the frame loop's thread (an int: one load)
        self._grab_fps = self.view_fps
        self.address: tuple[str, int] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._stop: asyncio.Event | None = None
        self._raw: tuple | None = None  # the newest frame offered by the loop: (w, h, flags, k, t_ms, rgba)
        self._encoding = False
        self._frame: tuple[int, bytes] | None = None  # (sequence, encoded message)
        self._seq = 0
        self._last_grab = 0.0
        self._pages = {path: _page(name) for path, name in PAGES.items()}

    # -- lifetime ----------------------------------------------------------------------------------

    def start(self) -> tuple[str, int]:
        """Bind and serve in a thread of its own; returns (host, port). OSError when the address is taken."""
        self._thread = threading.Thread(target=self._main, name="control-web", daemon=True)
        self._thread.start()
        self._ready.wait()
        if self._error is not None:
            raise self._error
        return self.address

    def close(self) -> None:
        if self._loop is not None and self._stop is not None and self._thread is not None:
            with contextlib.suppress(RuntimeError):  # the loop already ended
                self._loop.call_soon_threadsafe(self._stop.set)
            self._thread.join(timeout=5.0)

    def _main(self) -> None:
        try:
            asyncio.run(self._serve())
        except BaseException as exc:  # the thread never raises: a failed bind is handed to start()
            if not self._ready.is_set():
                self._error = exc
                self._ready.set()
            else:
                logger.exception("control server")

    async def _serve(self) -> None:
        from websockets.asyncio.server import serve  # the ``web`` extra

        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        async with serve(self._handler, self.host, self.port, process_request=self._process_request,
                         max_size=MAX_MESSAGE_BYTES, max_queue=MAX_QUEUE, write_limit=WRITE_LIMIT,
                         compression=None, open_timeout=5.0, ping_interval=10.0, ping_timeout=10.0,
                         server_header=None) as server:
            sock = next(iter(server.sockets))
            self.address = (self.host, sock.getsockname()[1])
            self._ready.set()
            await self._stop.wait()
            for client in list(self.clients):
                client.ws.transport.abort()

    # -- the frame loop's side ---------------------------------------------------------------------

    def wants_frame(self, now_s: float) -> bool:
        """Whether a view page waits for a frame that is due at ``now_s`` (monotonic s) and the last one is
        encoded (frame loop's thread: reads two numbers)."""
        return self.viewers > 0 and not self._encoding and now_s - self._last_grab >= 1.0 / self._grab_fps

    def offer_frame(self, width: int, height: int, flags: int, k: int, rgba: Any, now_s: float) -> None:
        """Hand over the newest drawn frame (frame loop's thread; never blocks): ``rgba`` is bytes-like, C-contiguous,
        ``height * width * 4`` bytes (kept, not copied: the renderer's read gives a new buffer every time)."""
        self._last_grab = now_s
        self._raw = (width, height, flags, k, now_ms(), rgba)
        self._encoding = True
        loop = self._loop
        if loop is not None:
            with contextlib.suppress(RuntimeError):  # closing
                loop.call_soon_threadsafe(self._encode_newest)

    def _encode_newest(self) -> None:
        raw, self._raw = self._raw, None
        if raw is None:
            self._encoding = False
            return
        task = self._loop.run_in_executor(None, lambda: encode(*raw))  # zlib lets go of the GIL
        task.add_done_callback(self._encoded)

    def _encoded(self, task: asyncio.Future) -> None:
        self._encoding = False
        if task.cancelled() or task.exception() is not None:
            return
        self._seq += 1
        self._frame = (self._seq, task.result())
        self.counters["view_frames_encoded"] += 1
        for client in self.clients:
            if client.view_fps > 0:
                client.wake.set()

    # -- HTTP: the pages and the upgrade's checks ---------------------------------------------------

    def _host_ok(self, host: str | None) -> bool:
        if host is None:
            return False
        if not is_loopback(self.host):
            return True  # the token guards a LAN server; the page is reached by whatever name the LAN uses
        port = self.address[1]
        return host in (f"127.0.0.1:{port}", f"localhost:{port}", f"[::1]:{port}")

    def _token_ok(self, query: str) -> bool:
        if self.token is None:
            return True
        given = parse_qs(query).get("token", [""])[0]
        return hmac.compare_digest(given.encode(), self.token.encode())

    def _process_request(self, connection, request):
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        path, _, query = request.path.partition("?")
        hosts, origins = request.headers.get_all("Host"), request.headers.get_all("Origin")
        host = hosts[0] if len(hosts) == 1 else None  # two Host headers: which one a proxy read is unknown
        if not self._host_ok(host) or len(origins) > 1:
            self.counters["refused_host"] += 1
            return connection.respond(403, "Host refused: use the address the run printed\n")
        if not self._token_ok(query):
            self.counters["refused_token"] += 1
            return connection.respond(401, "a token is needed: ?token=TOKEN (the run printed it)\n")
        if path == "/ws":
            origin = origins[0] if origins else None
            if origin is not None and origin != f"http://{host}":
                self.counters["refused_origin"] += 1
                self.log(f"web: refused a WebSocket from Origin {origin[:80]!r} (only this server's own pages)")
                return connection.respond(403, "Origin refused\n")
            if len(self.clients) >= MAX_CLIENTS:
                self.counters["refused_busy"] += 1
                return connection.respond(503, "too many clients\n")
            return None
        body = self._pages.get(path)
        if body is None or request.headers.get("Upgrade") is not None:
            return connection.respond(404, "not found\n")
        headers = Headers([
            ("Content-Type", "text/html; charset=utf-8"), ("Content-Length", str(len(body))),
            ("Cache-Control", "no-store"), ("X-Content-Type-Options", "nosniff"), ("Referrer-Policy", "no-referrer"),
            ("Content-Security-Policy", f"default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; "
                                        f"connect-src ws://{host}; frame-ancestors 'none'")])
        return Response(200, "OK", headers, body)

    # -- WebSocket clients ---------------------------------------------------------------------------

    async def _handler(self, ws) -> None:
        from websockets.exceptions import ConnectionClosed

        client = _Client(ws)
        self.clients.add(client)
        self.counters["connections"] += 1
        pusher = asyncio.create_task(self._push(client))
        try:
            async for message in ws:
                reply = self._on_message(client, message)
                if reply is not None and not await self._send(client, dumps_strict(reply)):
                    break
                if client.refused_in_a_row > MAX_REFUSED:
                    self.counters["closed_refused"] += 1
                    await ws.close(1008, "too many refused messages")
                    break
        except ConnectionClosed as exc:
            if exc.sent is not None and exc.sent.code == 1009:  # the library closed it: a message over max_size
                self.counters["closed_oversize"] += 1
        finally:
            pusher.cancel()
            self.clients.discard(client)
            self._count_viewers()

    async def _send(self, client: _Client, message: str | bytes) -> bool:
        """Send, or drop the client when it has not read for STALL_S; False when it is gone."""
        from websockets.exceptions import ConnectionClosed

        try:
            await asyncio.wait_for(client.ws.send(message), STALL_S)
            return True
        except TimeoutError:
            self.counters["dropped_slow"] += 1
            self.log("web: dropped a client that did not read for "
                     f"{STALL_S:g} s ({client.ws.remote_address})")
            client.ws.transport.abort()
            return False
        except ConnectionClosed:
            return False

    def _on_message(self, client: _Client, message: str | bytes) -> dict | None:
        self.counters["messages"] += 1
        if not client.limit.take(time.monotonic()):
            self.counters["rate_limited"] += 1
            client.refused_in_a_row += 1
            return {"type": "error", "error": "rate limit: slow down", "id": None}
        try:
            doc = loads_limited(message, "message")
        except JsonTextError as exc:
            self.counters["malformed"] += 1
            client.refused_in_a_row += 1
            return {"type": "error", "error": f"malformed JSON: {exc.problem}", "id": None}
        try:
            command = parse_command(doc, "message")
        except CommandError as exc:
            self.counters["bad_commands"] += 1
            client.refused_in_a_row += 1
            return {"type": "error", "error": str(exc), "id": doc.get("id") if isinstance(doc, dict) else None}
        client.refused_in_a_row = 0
        return self._command(client, command)

    def _command(self, client: _Client, command: Command) -> dict:
        verb, ident = command.verb, command.id
        if verb in SHOW_VERBS:
            if not self.submit(command):
                return {"type": "error", "error": "the show is busy: try again", "id": ident}
            return {"type": "ok", "verb": verb, "id": ident, "applies": "next tick"}
        if verb == "subscribe":
            client.rate = command.args["rate"]
            client.wake.set()
            return {"type": "ok", "verb": verb, "id": ident, "rate": client.rate}
        if verb == "view":
            client.view_fps = min(command.args["fps"], self.view_fps)
            self._count_viewers()
            client.wake.set()
            return {"type": "ok", "verb": verb, "id": ident, "fps": client.view_fps}
        reply = dict(self.answer(verb))
        if verb == "list":
            reply.update(verbs=list(VERBS), framings=list(FRAMINGS))
        elif verb == "status":
            reply["web"] = dict(self.counters)
        return {**reply, "type": verb, "id": ident}

    def _count_viewers(self) -> None:
        """How many view clients there are, and the fastest one's frame rate: the frames read back."""
        rates = [c.view_fps for c in self.clients if c.view_fps > 0]
        self._grab_fps = max(rates, default=self.view_fps)
        self.viewers = len(rates)

    async def _push(self, client: _Client) -> None:
        """What a client subscribed to: status and weights at its rate, the newest view frame at its fps."""
        next_status = next_frame = 0.0
        while True:
            now = time.monotonic()
            waits = []
            if client.rate > 0:
                waits.append(next_status - now)
            if client.view_fps > 0 and self._frame is not None and self._frame[0] != client.sent_frame:
                waits.append(next_frame - now)
            timeout = max(0.0, min(waits)) if waits else None
            client.wake.clear()
            if timeout is None or timeout > 0:
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(client.wake.wait(), timeout)
            now = time.monotonic()
            if client.rate > 0 and now >= next_status:
                next_status = now + 1.0 / client.rate
                message = {**self.answer("weights"), "type": "weights"}
                if not await self._send(client, dumps_strict(message)):
                    return
            frame = self._frame
            if client.view_fps > 0 and frame is not None and frame[0] != client.sent_frame and now >= next_frame:
                next_frame = now + 1.0 / client.view_fps
                client.sent_frame = frame[0]
                if not await self._send(client, frame[1]):
                    return
                self.counters["view_frames_sent"] += 1


def describe(address: tuple[str, int], token: str | None) -> str:
    """The log line of the run's pages and ports."""
    host, port = address
    shown = f"[{host}]" if ":" in host else host
    query = f"?token={token}" if token else ""
    return (f"web: remote panel http://{shown}:{port}/{query}, OBS view http://{shown}:{port}/view{query}, "
            f"control WebSocket ws://{shown}:{port}/ws{query} and OSC udp {shown}:{port}")


def json_text(doc: dict) -> str:
    """Compact JSON (what a reply looks like on the wire); for tests and scripts."""
    return json.dumps(doc, separators=(",", ":"))
