"""``bench latency --virtual-camera`` / ``--stream``: what each live picture output costs the frame loop, and
the latency it adds for a viewer, at 1280x720 (``--pictures-size``).

Three runs of ``bench latency``'s live phase (a sender process feeding a headless ``run`` over loopback), one
after the other on the same machine: the run alone, then with ``--virtual-camera``, then with ``--stream``.
For each output:

* **cost per frame in the loop** (``loop_ms``): what the frame loop's thread spends on the output each tick:
  reading the pixels back from the GPU and handing them to the output's thread
  (:mod:`~facepuppet.runtime.live.frame_handoff`); and the loop's CPU per tick and its end-to-end latency
  beside the run without outputs;
* **cost per frame in the output's thread** (``worker_ms``): the key-colour composite and the camera's write
  (pyvirtualcam's conversion to the device's format), or the H.264 encode and the send;
* **pictures dropped** because the output's thread was still busy (the loop never waits);
* **extra latency a viewer sees**: virtual camera: GPU finished -> the frame written to the device
  (``delay_ms``; a camera client reads it from there, plus its own frame pacing); stream: GPU finished -> the
  frame decoded by a receiver process on 127.0.0.1 (PyAV, FFmpeg's UDP input with ``nobuffer`` and
  ``low_delay``, the best case of a player such as OBS's Media Source, whose own buffering comes on top),
  matched by the picture's presentation time. Measured here: a frame leaves facepuppet within its encode
  (whole datagrams flushed as it is muxed), and FFmpeg's receiving side hands it on about two frame intervals
  later (the MPEG-TS demuxer ends a video PES, which has no length, when the next one starts, and the H.264
  parser ends an access unit likewise): 69 ms at 30 fps (640x360, with or without ``low_delay``); a player
  built on FFmpeg (OBS's Media Source) has that too, and a stream at a higher ``--fps`` shortens it. The
  frames drawn before the receiver had been decoding for a second (stream probing, the wait for a keyframe,
  the burst that follows) are reported apart.

Before the runs, each output's thread is timed alone (``isolated``: ``ISOLATED_FRAMES`` synthetic pictures at
the size, handed over as the loop hands them, RGBA bottom row first, one at a time, nothing else running in
this process): its cost per frame without the run's load on the same cores.

Where no v4l2loopback device can be opened (this machine), the camera's part goes through pyvirtualcam's
backend seam with a backend that takes each frame and does nothing with it: the figures are then facepuppet's
side only (read-back, composite, handoff), without the driver's conversion and copy; the result says which.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import socket
import subprocess
import sys
import time
from collections.abc import Callable

import numpy as np

from facepuppet.runtime.live.stream_out import StreamSink, plan_stream
from facepuppet.runtime.live.virtual_camera import VirtualCameraSink, plan_virtual_camera, why_unavailable
from facepuppet.runtime.render.readback import top_first

NULL_BACKEND = "facepuppet-bench-null"
RECEIVER_SETTLE_S = 1.0
ISOLATED_FRAMES = 120  # the receiver's first second: probing and the first keyframe


class NullBackend:
    """A pyvirtualcam backend that accepts every frame and keeps nothing (no device on this machine)."""

    def __init__(self, *, width: int, height: int, fps: float, fourcc: int, device: str | None,
                 **kw: object) -> None:
        self._device = device or "(no device: pyvirtualcam backend seam)"

    def send(self, frame: np.ndarray) -> None:
        pass

    def close(self) -> None:
        pass

    def device(self) -> str:
        return self._device

    def native_fourcc(self) -> int | None:
        return None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--virtual-camera", action="store_true",
                        help="then a run with --virtual-camera at --pictures-size: its cost per frame in the loop "
                             "and in its thread, frames dropped, the delay to the device (a v4l2loopback device "
                             "where one is loaded, else pyvirtualcam's backend seam with a backend that keeps "
                             "nothing)")
    parser.add_argument("--stream", action="store_true",
                        help="then a run with --stream udp://127.0.0.1:PORT at --pictures-size, decoded by a "
                             "receiver process: cost per frame in the loop and in the encoder's thread, frames "
                             "dropped, GPU finished -> decoded latency")
    parser.add_argument("--pictures-size", default="1280x720",
                        help="the render size of the --virtual-camera and --stream runs (1280x720)")


def _costs(sink) -> dict:
    return {} if sink is None else sink.costs()


def _percentiles(ms) -> dict:
    ms = np.asarray(ms, dtype=float)
    if ms.size == 0:
        return {"n": 0}
    p50, p99 = np.percentile(ms, [50, 99])
    return {"n": int(ms.size), "p50": float(p50), "p99": float(p99), "max": float(ms.max())}


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _receiver(port: int, seconds: float) -> subprocess.Popen:
    """A process decoding the stream from udp://127.0.0.1:PORT; one line ``pts perf_counter`` per frame."""
    proc = subprocess.Popen([sys.executable, "-m", "facepuppet.runtime.bench.live_pictures", "--receive",
                             str(port), repr(seconds)], stdout=subprocess.PIPE, text=True)
    first = proc.stdout.readline().strip()
    if first != "ready":
        proc.kill()
        proc.wait()
        raise RuntimeError(f"bench latency --stream: the receiver did not start ({first!r})")
    time.sleep(0.5)  # its socket is bound once av.open has started
    return proc


def receive(port: int, seconds: float) -> None:
    """The receiver process: decode until ``seconds`` pass or the stream stops for 2 s."""
    import av

    print("ready", flush=True)
    end = time.monotonic() + seconds
    url = f"udp://127.0.0.1:{port}?timeout=2000000&fifo_size=200000&overrun_nonfatal=1"
    try:
        with av.open(url, format="mpegts", timeout=30,
                     options={"fflags": "nobuffer", "flags": "low_delay", "probesize": "32768",
                              "analyzeduration": "0"}) as container:
            stream = container.streams.video[0]
            stream.thread_type = "SLICE"  # frame threads would hold frames back
            stream.codec_context.flags |= int(av.codec.context.Flags.low_delay)
            for packet in container.demux(stream):
                for frame in packet.decode():
                    print(frame.pts, repr(time.perf_counter()), flush=True)
                if time.monotonic() > end:
                    return
    except av.FFmpegError:  # the stream stopped (the timeout): done
        return


def _viewer_latency(lines: list[str], sent: list[tuple[int, float]]) -> dict:
    """GPU finished -> decoded, ms, of the frames decoded whose pts were sent; those drawn before the receiver
    had been decoding for ``RECEIVER_SETTLE_S`` apart (its start: probing, the first keyframe)."""
    stamps = dict(sent)
    decoded = []
    for line in lines:
        parts = line.split()
        if len(parts) == 2 and parts[0].lstrip("-").isdigit():
            decoded.append((int(parts[0]), float(parts[1])))
    matched = [(stamps[pts], t) for pts, t in decoded if pts in stamps]
    if not matched:
        return {"decoded": len(decoded), "matched": 0}
    start = decoded[0][1] + RECEIVER_SETTLE_S  # frames drawn once the receiver has been decoding a while
    settled = [(t - s) * 1e3 for s, t in matched if s >= start]
    first = [(t - s) * 1e3 for s, t in matched if s < start]
    return {"decoded": len(decoded), "matched": len(matched), "gpu_to_decoded_ms": _percentiles(settled),
            "first_second_ms": _percentiles(first)}


def _isolated(sink, width: int, height: int, n: int = ISOLATED_FRAMES) -> dict:
    """The sink's thread timed alone on ``n`` pictures at its size, each stored and finished as the loop's."""
    rng = np.random.default_rng(0)
    base = rng.integers(0, 200, (height, width, 4), dtype=np.uint8)
    base[..., 3] = 255
    try:
        for k in range(n):
            raw = base.copy()
            raw[:, (7 * k) % width] = 255  # a moving line: the encoder sees motion
            sink.handoff.offer(k, k / 60, time.perf_counter(), raw, top_first)
            sink.handoff.drain()
    finally:
        sink.close()
    return {"frames": n, "worker_ms": sink.handoff.costs()["worker_ms"]}


def isolated_costs(width: int, height: int, camera: bool, stream: bool, real_camera: bool) -> dict:
    """Each output's thread alone (see the module doc): ``{"virtual_camera": ..., "stream": ...}``."""
    import pyvirtualcam

    out = {}
    if camera:
        plan = plan_virtual_camera(None, width, height, 60.0, (0.0, 1.0, 0.0), False)
        cam = pyvirtualcam.Camera(width, height, 60.0, fmt=pyvirtualcam.PixelFormat.RGBA,
                                  backend=None if real_camera else NULL_BACKEND)
        out["virtual_camera"] = _isolated(VirtualCameraSink(cam, plan), width, height)
    if stream:
        port = _free_udp_port()  # nothing listens there: the datagrams go nowhere
        plan = plan_stream(f"udp://127.0.0.1:{port}", width, height, 60.0, (0.0, 0.0, 0.0), False)
        out["stream"] = _isolated(StreamSink(plan, 60.0), width, height)
    return out


def live_picture_phases(args: argparse.Namespace, results: dict, phase: Callable[..., dict]) -> None:
    """The runs without and with each output asked for (see the module doc); into ``results``."""
    import pyvirtualcam

    width, height = (int(v) for v in args.pictures_size.lower().split("x"))
    real = why_unavailable(plan_virtual_camera(None, width, height, args.fps, (0.0, 1.0, 0.0), False)) is None
    if not real:
        pyvirtualcam.register_backend(NULL_BACKEND, NullBackend)
    alone = results["pictures_isolated"] = isolated_costs(width, height, args.virtual_camera, args.stream, real)
    for name, figures in alone.items():
        w = figures["worker_ms"]
        print(f"latency bench [pictures, {name} thread alone]: {figures['frames']} frames at {width}x{height}, "
              f"ms per frame p50 {w.get('p50', math.nan):.2f}, p99 {w.get('p99', math.nan):.2f}")
    pictures = argparse.Namespace(**{**vars(args), "size": args.pictures_size})
    base = results["pictures_baseline"] = phase(pictures, args.rate, args.seconds)
    _print("alone", base, {})
    if args.virtual_camera:

        def with_camera(run_plan):
            camera = dataclasses.replace(run_plan.outputs.virtual_camera, backend=None if real else NULL_BACKEND)
            return dataclasses.replace(run_plan, outputs=dataclasses.replace(run_plan.outputs,
                                                                             virtual_camera=camera))

        r = phase(pictures, args.rate, args.seconds, extra_argv=("--virtual-camera",), edit_plan=with_camera,
                  on_result=lambda result: {"virtual_camera": _costs(result.outputs.virtual_camera)})
        r["virtual_camera"]["device"] = "v4l2loopback" if real else "none: pyvirtualcam backend seam, frames discarded"
        results["virtual_camera"] = r
        _print("--virtual-camera", r, r["virtual_camera"], base)
    if args.stream:
        port = _free_udp_port()
        receiver = _receiver(port, 3 * args.seconds + 60)
        sent: list[tuple[int, float]] = []

        def keep(result):
            sink = result.outputs.stream
            sent.extend(sink.recent if sink is not None else ())
            return {"stream": _costs(sink)}

        try:
            r = phase(pictures, args.rate, args.seconds, extra_argv=("--stream", f"udp://127.0.0.1:{port}"),
                      on_result=keep)
            out = receiver.communicate(timeout=30)[0]
        finally:
            if receiver.poll() is None:
                receiver.kill()
                receiver.wait()
        r["stream"]["viewer"] = _viewer_latency(out.splitlines(), sent)
        results["stream"] = r
        _print("--stream", r, r["stream"], base)


def _print(name: str, r: dict, output: dict, base: dict | None = None) -> None:
    def pq(d: dict) -> str:
        return f"{d.get('p50', math.nan):.2f}/{d.get('p99', math.nan):.2f}"

    line = (f"latency bench [pictures {name}]: CPU per tick ms p50/p99 {pq(r['cpu_per_tick_ms'])}, receive -> GPU "
            f"finished {pq(r['end_to_end_ms'])}, ticks {r['ticks']}")
    if base is not None:
        line += (f" (alone: {pq(base['cpu_per_tick_ms'])}, {pq(base['end_to_end_ms'])})")
    print(line)
    if output:
        print(f"  in the loop (read-back + handoff) ms p50/p99 {pq(output['loop_ms'])}; in its thread "
              f"{pq(output['worker_ms'])}; GPU finished -> sent {pq(output['delay_ms'])}; sent {output['sent']}, "
              f"dropped {output['dropped']}" + (f", failed: {output['failure']}" if output.get("failure") else ""))
        viewer = output.get("viewer")
        if viewer and "gpu_to_decoded_ms" in viewer:
            settled, starting = viewer["gpu_to_decoded_ms"], viewer["first_second_ms"]
            print(f"  viewer: GPU finished -> decoded ms p50/p99 {pq(settled)} over {settled.get('n', 0)} frames "
                  f"(receiver starting {pq(starting)}; {viewer['decoded']} decoded, {viewer['matched']} matched)")


if __name__ == "__main__":  # the receiver process of --stream
    if len(sys.argv) == 4 and sys.argv[1] == "--receive":
        receive(int(sys.argv[2]), float(sys.argv[3]))
    else:
        sys.exit("usage: python -m facepuppet.runtime.bench.live_pictures --receive PORT SECONDS")
