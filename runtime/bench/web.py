"""``bench latency --web``: what ``run --web``'s view page costs the frame loop, and what a viewer sees.

Three figures:

* the view output's cost per frame on the frame loop's thread at 1280x720 (the read-back of the drawn frame,
  :func:`~facepuppet.runtime.control.view_frames.grab`; goal under 2 ms), and apart from it the compression
  the server's thread does per frame (it lets go of the GIL) and the bytes sent;
* the frame loop's p99 (end to end, CPU per tick, GPU wait) in a live run with ``--web`` and no client, then with
  :data:`CLIENTS` view clients connected at 30 fps each (real WebSocket clients in a process of their own, as
  browsers are): the clients must not move it. The clients read each frame's header and not its pixels: on a
  small machine ten clients inflating 30 frames a second each take CPU from the frame loop as any other
  program would, which says nothing of the server (``--web-decode`` inflates them too, to see that);
* the extra latency a viewer sees: from the frame's read-back to a client holding it (``--web-decode``: its
  inflated pixels).

The two runs follow one another, so a change of the machine's load between them shows as a difference too;
each carries the load average at its end.
"""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable

import numpy as np

from facepuppet.runtime.control.view_frames import HEADER, decode, encode, grab, now_ms
from facepuppet.runtime.model.character import Character

CLIENTS = 10
CLIENT_FPS = 30.0
ROUNDS = 2  # runs without and with clients, by turns


def _percentiles(values: list[float] | np.ndarray) -> dict:
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return {}
    return {"p50": float(np.percentile(v, 50)), "p99": float(np.percentile(v, 99)), "max": float(v.max()),
            "n": int(v.size)}


def view_cost(character_path: str, width: int = 1280, height: int = 720, frames: int = 120) -> dict:
    """ms per frame of the view output at ``width`` x ``height``: the read-back on the loop's thread and the
    compression on the server's, and the message's bytes (a transparent background, every shape moving)."""
    from facepuppet.runtime.render.gl_context import create_context
    from facepuppet.runtime.render.renderer import FaceRenderer

    character = Character.load(character_path)
    target = create_context(headless=True)
    try:
        renderer = FaceRenderer(target.ctx, character, width, height, transparent=True, msaa=0,
                                log=lambda _: None)
        try:
            rng = np.random.default_rng(0)
            grabs, encodes, sizes = [], [], []
            for k in range(frames):
                renderer.draw(rng.random(character.n_shapes, dtype=np.float32) * 0.5)
                renderer.finish()
                t0 = time.perf_counter()
                w, h, flags, rgba = grab(renderer)
                t1 = time.perf_counter()
                message = encode(w, h, flags, k, now_ms(), rgba)
                t2 = time.perf_counter()
                grabs.append((t1 - t0) * 1e3)
                encodes.append((t2 - t1) * 1e3)
                sizes.append(len(message))
            return {"size": f"{width}x{height}", "sent_size": f"{w}x{h}", "loop_thread_ms": _percentiles(grabs),
                    "server_thread_encode_ms": _percentiles(encodes), "bytes_p50": float(np.median(sizes))}
        finally:
            renderer.close()
    finally:
        target.close()


def free_port() -> int:
    """A port free on 127.0.0.1 for TCP and UDP at once (``--web`` takes both)."""
    for _ in range(50):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as tcp:
            tcp.bind(("127.0.0.1", 0))
            port = tcp.getsockname()[1]
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
                try:
                    udp.bind(("127.0.0.1", port))
                except OSError:
                    continue
                return port
    raise RuntimeError("bench latency --web: no port free for both TCP and UDP")


def view_clients(port: int, n: int, fps: float, lags_ms: list[float], frames: list[int],
                 inflate: bool = False) -> Callable[[], Callable]:
    """A ``started`` callable for the latency bench's phase: ``n`` view clients in a process of their own (as
    browsers are), each decoding every frame it gets as the page does and noting its lag; the callable it
    returns stops them and fills ``lags_ms`` and ``frames``."""
    def start() -> Callable[[], None]:
        proc = subprocess.Popen([sys.executable, "-m", "facepuppet.runtime.bench.web", str(port), str(n), repr(fps),
                                 "inflate" if inflate else "header"],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)

        def end() -> None:
            out, _ = proc.communicate("stop\n", timeout=60)
            try:
                got = json.loads(out.strip().splitlines()[-1])
            except (ValueError, IndexError):
                return
            lags_ms.extend(got["lags_ms"])
            frames[:] = got["frames"]
        return end
    return start


def _clients_main(port: int, n: int, fps: float, inflate: bool) -> None:
    """The clients' process: until a line on stdin, then their lags and frame counts as one JSON line."""
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect

    stop = threading.Event()
    lags: list[float] = []
    frames = [0] * n

    def client(i: int) -> None:
        try:
            with connect(f"ws://127.0.0.1:{port}/ws", max_size=64 << 20) as ws:
                ws.send(json.dumps({"verb": "view", "fps": fps}))
                while not stop.is_set():
                    try:
                        message = ws.recv(timeout=0.5)
                    except TimeoutError:
                        continue
                    if isinstance(message, bytes):
                        t_ms = decode(message)[4] if inflate else HEADER.unpack_from(message)[5]
                        lags.append(now_ms() - t_ms)
                        frames[i] += 1
        except (OSError, ConnectionClosed):
            pass

    threads = [threading.Thread(target=client, args=(i,), daemon=True) for i in range(n)]
    for t in threads:
        t.start()
    sys.stdin.readline()
    stop.set()
    for t in threads:
        t.join(5.0)
    print(json.dumps({"lags_ms": lags, "frames": frames}))


def web_phases(args: argparse.Namespace, phase: Callable[..., dict]) -> dict:
    """The figures of the module docstring; ``phase`` is the latency bench's one live run."""
    out: dict = {}
    out["view_cost"] = cost = view_cost(args.character)
    g, e = cost["loop_thread_ms"], cost["server_thread_encode_ms"]
    print(f"  web: view output at {cost['size']}: loop thread (read-back) p50 {g['p50']:.2f} ms, p99 "
          f"{g['p99']:.2f} ms (goal < 2 ms); server thread (zlib) p50 {e['p50']:.2f} ms; "
          f"{cost['bytes_p50'] / 1024:.0f} KiB per frame")
    transparent = ("--background", "transparent")
    lags: list[float] = []
    frames = [0] * CLIENTS
    idle_runs, busy_runs = [], []
    for _ in range(ROUNDS):  # by turns, so that both meet the same load
        port = free_port()
        web = ("--web", f"127.0.0.1:{port}", *transparent)
        idle_runs.append(phase(args, args.rate, args.seconds, extra_argv=web))
        port = free_port()
        got = [0] * CLIENTS
        web = ("--web", f"127.0.0.1:{port}", *transparent)
        busy_runs.append(phase(args, args.rate, args.seconds, extra_argv=web,
                               started=view_clients(port, CLIENTS, CLIENT_FPS, lags, got,
                                                    inflate=getattr(args, "web_decode", False))))
        frames = [a + b for a, b in zip(frames, got)]
    out["no_clients"], out["clients"] = idle_runs, busy_runs
    out["viewer_lag_ms"] = lag = _percentiles(lags)
    out["frames_per_client"] = frames
    out["clients_n"] = CLIENTS
    out["clients_inflate"] = bool(getattr(args, "web_decode", False))
    # the read-back runs as a loop overlay, before the GPU wait: its wait for the GPU moves from gpu_finish into
    # the tick's CPU; end to end (datagram to drawn) is the figure a viewer of the show feels
    for key in ("end_to_end_ms", "cpu_per_tick_ms", "gpu_finish_ms"):
        a = [r[key] for r in idle_runs if "p99" in r[key]]
        b = [r[key] for r in busy_runs if "p99" in r[key]]
        if a and b:
            out[f"{key}_p99_added"] = float(np.median([x["p99"] for x in b]) - np.median([x["p99"] for x in a]))
            print(f"  web: {key.replace('_ms', '')} p50/p99 ms by turns: no client "
                  + ", ".join(f"{x['p50']:.2f}/{x['p99']:.2f}" for x in a) + f"; {CLIENTS} view clients "
                  + ", ".join(f"{x['p50']:.2f}/{x['p99']:.2f}" for x in b)
                  + f" (load {busy_runs[-1].get('loadavg')})")
    if lag:
        print(f"  web: a viewer's lag (read-back to the client holding it) p50 {lag['p50']:.1f} ms, "
              f"p99 {lag['p99']:.1f} ms; frames per client {min(frames)}..{max(frames)} "
              f"over {ROUNDS} x {args.seconds:g} s")
    return out


if __name__ == "__main__":
    _clients_main(int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), sys.argv[4] == "inflate")
