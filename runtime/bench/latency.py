"""``facepuppet bench latency``: tracker-to-pixels latency of a headless live run over loopback.

A separate sender *process* streams VMC frames (every ARKit channel in
PascalCase plus the Head bone, split into bundles under 1,500 bytes with
Apply last, i.e. what :class:`~facepuppet.runtime.live.vmc_out.VmcSender` sends)
at ``--rate`` Hz for ``--seconds`` to a headless ``run`` in this process,
rendering the character at ``--size``. Reported:

* receive -> GPU finished latency of each drawn frame (p50 / p99 / max, ms),
  and the per-stage split (:mod:`~facepuppet.runtime.live.stats`);
* the CPU stages of the frame loop (snapshot, pipeline + map) p99;
* the map step alone (``map_step``: channels onto the character's shapes, through its VRM expressions when it
  has them; :mod:`~facepuppet.runtime.mapping.expressions`), timed apart over ``MAP_SAMPLES`` applications of
  random values on the VMC input's channel layout: p50 / p99 / max in microseconds;
* receive is the kernel's arrival stamp of the datagram (SO_TIMESTAMPNS), so
  time a datagram waits before the receiver reads it counts; ``--receiver``
  picks the run's receiver (child process, the default, or thread);
* frames sent, datagrams received, frames dropped as stale (the newest wins),
  UDP losses (sent - received);
* with ``--flood``: ``--flood-factor`` x the rate for ``--flood-seconds``;
  latency of the newest frame per second and resident memory (RSS) sampled
  every second, which must stay flat.

``--input KIND`` picks the protocol the sender speaks and the run listens for
(:data:`~facepuppet.runtime.bench.senders.SENDERS`: ``vmc``, the default, ``openseeface``, or a phone kind
the sender process plays; :mod:`~facepuppet.runtime.bench.senders`). Before the live phase the bench also
measures the decode cost per datagram of that kind (``decode_us``). The loss figures count each kind's
datagrams per frame.
"""

from __future__ import annotations

import argparse
import math
import os
import socket
import subprocess
import sys
import threading
import time
from dataclasses import replace

import numpy as np

from facepuppet.runtime.bench.live_pictures import add_arguments as add_live_picture_arguments
from facepuppet.runtime.bench.live_pictures import live_picture_phases
from facepuppet.runtime.bench.registry import load_average, peak_rss_mb, register_bench, session_log
from facepuppet.runtime.bench.render import pass_costs
from facepuppet.runtime.bench.senders import SENDERS, decode_cost
from facepuppet.runtime.bench.web import web_phases
from facepuppet.runtime.commands.options import parse_size
from facepuppet.runtime.commands.run import plan_from_argv, run_live
from facepuppet.runtime.inputs.vmc import VmcAdapter
from facepuppet.runtime.mapping.channels import ChannelMap
from facepuppet.runtime.mapping.expressions import make_drive
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.render.quality import QUALITIES
from facepuppet.runtime.session.options import PanelOptions

_PAGE_MB = os.sysconf("SC_PAGE_SIZE") / 2**20 if hasattr(os, "sysconf") else 4096 / 2**20


def rss_mb() -> float:
    """Current resident memory of this process, MiB (Linux /proc; peak RSS elsewhere)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * _PAGE_MB
    except OSError:
        return peak_rss_mb()


def _phase(args, rate: float, seconds: float, panel: str | None = None, extra_argv: tuple = (),
           edit_plan=None, on_result=None, started=None) -> dict:
    """One sender process at ``rate`` for ``seconds`` against one headless live run; ``extra_argv``: more of
    run's options, ``edit_plan(plan)``: the plan changed, ``on_result(result)``: a dict of more figures,
    ``started()``: called once the run listens, returns a callable that ends what it started."""

    kind = getattr(args, "input", "vmc")
    probe = SENDERS[kind]("127.0.0.1", 9)  # datagrams per frame (VMC: status + the blend bundles); sends nothing
    per_frame = probe.per_frame
    probe.close()

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    procs = []
    phone = None
    if getattr(SENDERS[kind], "plays_phone", False):  # the phone must be there before the run asks it
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "facepuppet.runtime.bench.senders", "--send", "127.0.0.1", str(port),
             repr(rate), repr(seconds), kind], stdout=subprocess.PIPE, stdin=subprocess.PIPE, text=True))
        first = procs[0].stdout.readline().split()
        if len(first) != 2 or first[0] != "phone":
            procs[0].kill()
            procs[0].wait()
            raise RuntimeError(f"bench latency: the {kind} phone sender did not start ({first!r})")
        phone = f"127.0.0.1:{first[1]}"
    # the run stops shortly after the sender process ends (its start-up time varies with load);
    # the duration is only a safety net
    argv = ["-c", str(args.character), "--input", kind, "--listen", f"127.0.0.1:{port}", "--headless",
            "--size", args.size, "--fps", repr(float(args.fps)), "--duration", repr(3 * seconds + 60),
            "--path", args.path, "--receiver", getattr(args, "receiver", "process"),
            "--draw", getattr(args, "draw", "arrival"), *(["--phone", phone] if phone else []),
            *(["--panel"] if panel is not None else []), "--quality", getattr(args, "quality", "auto"),
            *(["--msaa", str(args.msaa)] if getattr(args, "msaa", None) is not None else []), *extra_argv]
    plan = replace(plan_from_argv(argv), panel=PanelOptions(panel is not None, hidden=panel == "hidden"))
    plan = plan if edit_plan is None else edit_plan(plan)
    stop = threading.Event()
    sender_out: list[str] = []
    rss: list[tuple[float, float]] = []
    newest: list[float] = []  # end-to-end ms of each drawn new frame (for per-second maxima)
    t_start = [0.0]

    t_first_last = [math.inf, -math.inf]

    ending: list = []

    def on_ready(address):
        t_start[0] = time.monotonic()
        if started is not None:
            ending.append(started())
        if procs:  # the phone sender: go
            procs[0].stdin.write("go\n")
            procs[0].stdin.flush()
        else:
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "facepuppet.runtime.bench.senders", "--send", "127.0.0.1", str(address[1]),
                 repr(rate), repr(seconds), kind], stdout=subprocess.PIPE, text=True))

        def wait_for_sender():
            sender_out.append(procs[0].communicate()[0])
            time.sleep(0.3)  # let the last datagrams be drawn
            stop.set()

        threading.Thread(target=wait_for_sender, daemon=True).start()

    next_rss = [0.0]

    shown_panel: list = []  # the run's DeskPanel (on_panel)
    calls_ms: list[float] = []  # per tick: the panel's draw calls (llvmpipe's vertex work for the panel)
    shown_ticks: list[bool] = []  # per tick with panel="alternate": whether the panel was shown in it

    drawn_with: dict = {}

    def sample(info):
        if not drawn_with:  # the picture the run chose (the path and the samples its quality left)
            drawn_with.update(msaa=int(getattr(info.renderer, "samples", 0)), path=info.renderer.path,
                              subtle_layers=bool(getattr(info.renderer, "subtle_layers", True)),
                              gl_renderer=getattr(getattr(info.renderer, "ctx", None), "info", {}).get("GL_RENDERER"))
        if shown_panel:
            calls_ms.append(shown_panel[0].draw_calls_s * 1e3)
            if panel == "alternate":  # this tick's mode, then the other one for the next tick
                shown_ticks.append(bool(shown_panel[0].visible))
                shown_panel[0].toggle()
        now = time.monotonic()
        if now >= next_rss[0]:
            rss.append((now - t_start[0], rss_mb()))
            next_rss[0] = now + 1.0
        if info.raw is not None:
            newest.append((now - t_start[0], (info.stamps[4] - info.raw.t) * 1e3))
            t_first_last[0] = min(t_first_last[0], info.stamps[4])
            t_first_last[1] = info.stamps[4]

    try:
        result = run_live(plan, stop_event=stop, on_ready=on_ready, hooks=[sample], on_panel=shown_panel.append)
    finally:
        for end in ending:
            end()
        for proc in procs:
            proc.kill()
            proc.wait()
    frames_sent = int(sender_out[0].strip().splitlines()[-1]) if sender_out and sender_out[0].strip() else -1
    stats = result.stats
    e2e = stats.samples_ms("end_to_end")
    udp = result.counters["udp"]
    timings = result.loop.timings
    drawing_s = t_first_last[1] - t_first_last[0]
    per_second = {}
    for t, ms in newest:
        per_second[int(t)] = max(per_second.get(int(t), 0.0), ms)
    cpu = (result.loop.timer.samples("snapshot") + result.loop.timer.samples("map")
           + result.loop.timer.samples("draw_submit")) * 1e3
    extra = {} if on_result is None else on_result(result)
    if panel is not None:
        p = result.panel

        def q(sketch):
            return {"p50": sketch.quantile(0.5) * 1e3, "p99": sketch.quantile(0.99) * 1e3} if sketch.n else {}

        extra = {"panel": panel, "panel_draws": p.draw_sketch.n, "panel_cpu_ms": q(p.draw_sketch),
                 "panel_gl_submit_ms": q(p.submit_sketch), "panel_build_ms": q(p.build_sketch),
                 "panel_draw_calls_ms": q(p.calls_sketch), "panel_cpu_without_draw_calls_ms": q(p.cpu_sketch),
                 "panel_settings_builds": p.settings_builds, "panel_settings_build_ms": q(p.settings_sketch)}
        # one sample per tick in each; the loop's timer keeps the last RING ticks (a long run): the same last ticks
        n = cpu.size
        calls_ms, shown_ticks = calls_ms[len(calls_ms) - n:], shown_ticks[len(shown_ticks) - n:]
        if len(calls_ms) == n:  # the tick's CPU less the panel's draw calls
            extra["cpu_per_tick_less_panel_draw_calls_ms"] = _percentiles(cpu - np.asarray(calls_ms))
        gpu = result.loop.timer.samples("gpu_finish") * 1e3
        if panel == "alternate" and len(shown_ticks) == n == gpu.size:
            on = np.asarray(shown_ticks)
            less = cpu - np.asarray(calls_ms)
            extra["interleaved"] = {
                "ticks_shown": int(on.sum()), "ticks_hidden": int((~on).sum()),
                "cpu_per_tick_ms": {"shown": _percentiles(cpu[on]), "hidden": _percentiles(cpu[~on])},
                "cpu_per_tick_less_panel_draw_calls_ms": {"shown": _percentiles(less[on]),
                                                          "hidden": _percentiles(less[~on])},
                "gpu_finish_ms": {"shown": _percentiles(gpu[on]), "hidden": _percentiles(gpu[~on])}}
    return {
        **extra,
        "cpu_per_tick_ms": _percentiles(cpu),
        "gpu_finish_ms": _percentiles(result.loop.timer.samples("gpu_finish") * 1e3),
        "rate_hz": rate,
        "seconds": seconds,
        "frames_sent": frames_sent,
        "input": kind,
        "datagrams_sent": frames_sent * per_frame,
        "datagrams_received": udp["packets"],
        "udp_lost": frames_sent * per_frame - udp["packets"],
        "frames_decoded": udp.get("frames", None),
        "frames_drawn": int(e2e.size),
        "ticks": result.loop.n_ticks,
        "new_frames_drawn_per_s": float(e2e.size / drawing_s) if drawing_s > 0 else math.nan,
        "receiver": plan.inputs.receiver,
        "draw": plan.pacing.draw,
        "waited_over_1ms": udp.get("waited_over_1ms", None),
        "stale_dropped": result.loop.counters["stale_dropped"],
        "late_ticks": result.loop.counters["late_ticks"],
        "skipped_ticks": result.loop.counters["skipped_ticks"],
        "end_to_end_ms": _percentiles(e2e),
        "stages_ms": stats.latency(),
        "cpu_stage_p99_ms": {"snapshot": timings["snapshot"]["p99_ms"], "pipeline_map": timings["map"]["p99_ms"],
                             "draw_submit": timings["draw_submit"]["p99_ms"]},
        "cpu_before_draw_p99_ms": float(np.percentile(
            result.loop.timer.samples("snapshot") + result.loop.timer.samples("map"), 99) * 1e3),
        "newest_frame_max_ms_per_second": [per_second[k] for k in sorted(per_second)],
        "rss_mb_per_second": [round(m, 1) for _, m in rss],
        "render_path": result.path,
        "msaa": drawn_with.get("msaa"),
        "subtle_layers": drawn_with.get("subtle_layers"),
        "gl_renderer": drawn_with.get("gl_renderer"),
        "loadavg": load_average(),
    }


MAP_SAMPLES = 5000


def map_step_cost(character_path: str | os.PathLike, n: int = MAP_SAMPLES, seed: int = 0) -> dict:
    """Cost of the frame loop's map step for this character and the VMC input's channels (µs per frame)."""

    character = Character.load(character_path)
    drive = make_drive(character.shape_names, character.expressions)
    channels = VmcAdapter(extra_names=() if drive is None else drive.receive_names()).channels
    cmap = ChannelMap.build(channels, character.shape_names) if drive is None else drive.build(channels)
    values = np.random.default_rng(seed).random((n, len(channels)), dtype=np.float32)
    values[:, len(channels) // 2:][values[:, len(channels) // 2:] < 0.3] = np.nan  # some channels not sent
    out = np.zeros(character.n_shapes, np.float32)
    ns = np.empty(n)
    clock = time.perf_counter_ns
    for i in range(n):
        t0 = clock()
        cmap.apply(values[i], out=out)
        ns[i] = clock() - t0
    us = ns / 1e3
    p50, p99 = np.percentile(us, [50, 99])
    return {"map": type(cmap).__name__, "channels": len(channels), "shapes": character.n_shapes,
            "expressions": character.n_expressions, "n": n, "p50_us": float(p50), "p99_us": float(p99),
            "max_us": float(us.max())}


def _percentiles(ms: np.ndarray) -> dict:
    if ms.size == 0:
        return {"n": 0}
    p50, p99 = np.percentile(ms, [50, 99])
    return {"n": int(ms.size), "p50": float(p50), "p99": float(p99), "max": float(ms.max())}


def bench_latency(args: argparse.Namespace) -> dict:
    kind = getattr(args, "input", "vmc")
    results = {"character": str(args.character), "size": args.size, "fps": args.fps,
               "draw": getattr(args, "draw", "arrival"), "input": kind}
    results["decode_us"] = d = decode_cost(kind)
    print(f"latency bench [{kind}]: decode {d['datagrams']} datagrams ({d['bytes']} bytes), "
          f"handle() p50 {d['p50_us']:.1f} us, "
          f"p99 {d['p99_us']:.1f} us, max {d['max_us']:.1f} us; per frame ({d['datagrams_per_frame']} datagrams) "
          f"p50 {d['per_frame_p50_us']:.1f} us, p99 {d['per_frame_p99_us']:.1f} us")
    with session_log(args.verbose):
        results["nominal"] = _phase(args, args.rate, args.seconds)
    _print("nominal", results["nominal"])
    nominal = results["nominal"]
    if nominal.get("msaa") is not None:
        width, height = parse_size(args.size)
        passes = results["passes_ms"] = pass_costs(args.character, width, height, nominal["render_path"],
                                                   nominal["msaa"], subtle_layers=nominal["subtle_layers"])
        print(f"  draw passes ({passes['path']} path, MSAA {passes['msaa']}x, subtle eye layers "
              f"{'on' if passes['subtle_layers'] else 'off'}) median ms: " + ", ".join(
            f"{name} {v['median']:.2f}" for name, v in passes.items() if isinstance(v, dict)))
    m = results["map_step"] = map_step_cost(args.character)
    print(f"  map step alone ({m['map']}, {m['channels']} channels -> {m['shapes']} shapes, "
          f"{m['expressions']} expressions): p50 {m['p50_us']:.1f} µs, p99 {m['p99_us']:.1f} µs over {m['n']}")
    if getattr(args, "panel", False):
        with session_log(args.verbose):
            _panel_phases(args, results)
    if getattr(args, "web", False):
        with session_log(args.verbose):
            results["web"] = web_phases(args, _phase)
    if getattr(args, "virtual_camera", False) or getattr(args, "stream", False):
        with session_log(args.verbose):
            live_picture_phases(args, results, _phase)
    if args.flood:
        with session_log(args.verbose):
            results["flood"] = _phase(args, args.rate * args.flood_factor, args.flood_seconds)
        _print("flood", results["flood"])
        rss = results["flood"]["rss_mb_per_second"]
        if len(rss) > 2:
            results["flood"]["rss_growth_mb"] = rss[-1] - rss[1]
    return results


def _panel_phases(args, results: dict) -> None:
    """``--panel``: one run whose ticks alternate the panel shown and hidden (Tab every tick), so that both
    modes meet the same load; what the panel adds per tick on the CPU (snapshot + stages + map + draw
    submit, the panel's build and submit included: p50/p99 of the shown ticks less those of the hidden
    ones) and in the GPU wait (on llvmpipe the rasterising of the panel's triangles happens there). Every
    shown tick builds an ImGui frame (the one before was hidden), so this is the panel's dearest case;
    a run showing it throughout reuses the last frame on ticks closer than 1/REBUILD_HZ."""
    results["panel_alternate"] = r = _phase(args, args.rate, args.seconds, panel="alternate")
    _print("panel alternating shown/hidden", r)
    inter = r.get("interleaved")
    if inter is None:
        print("  panel: the ticks and the samples did not line up; no interleaved figures")
        return
    added = {key: {q: inter[key]["shown"][q] - inter[key]["hidden"][q] for q in ("p50", "p99")}
             for key in ("cpu_per_tick_ms", "gpu_finish_ms", "cpu_per_tick_less_panel_draw_calls_ms")
             if "p50" in inter[key]["shown"] and "p50" in inter[key]["hidden"]}
    results["panel_added_ms"] = added
    hidden = {k: v["hidden"] for k, v in inter.items() if isinstance(v, dict)}
    shown = {**{k: v["shown"] for k, v in inter.items() if isinstance(v, dict)},
             **{k: r[k] for k in r if k.startswith("panel_")}}
    pc = shown.get("panel_cpu_ms", {})
    for key, label in (("cpu_per_tick_ms", "CPU per tick"), ("gpu_finish_ms", "GPU wait (llvmpipe draw)")):
        h, s = hidden[key], shown[key]
        if "p50" in h and "p50" in s:
            print(f"  panel: {label} ms p50/p99 hidden {h['p50']:.3f}/{h['p99']:.3f}, shown {s['p50']:.3f}/"
                  f"{s['p99']:.3f}, added {added[key]['p50']:+.3f}/{added[key]['p99']:+.3f}")
    if "p50" in pc:
        gl = shown["panel_gl_submit_ms"]
        print(f"  panel: its own build + submit on the CPU p50 {pc['p50']:.3f} ms, p99 {pc['p99']:.3f} ms "
              f"over {shown['panel_draws']} draws; of which the GL submit p50 "
              f"{gl['p50']:.3f} ms, p99 {gl['p99']:.3f} ms")
        b, c, w = shown["panel_build_ms"], shown["panel_draw_calls_ms"], shown["panel_cpu_without_draw_calls_ms"]
        print(f"  panel: ImGui frame p50/p99 {b['p50']:.3f}/{b['p99']:.3f} ms; draw calls (llvmpipe's vertex work and "
              f"binning, reported apart) {c['p50']:.3f}/{c['p99']:.3f} ms; all but the draw calls "
              f"{w['p50']:.3f}/{w['p99']:.3f} ms")
    less = added.get("cpu_per_tick_less_panel_draw_calls_ms")
    if less is not None:
        print(f"  panel: CPU per tick added, the panel's draw calls (llvmpipe) left out: p50 {less['p50']:+.3f} ms, "
              f"p99 {less['p99']:+.3f} ms")


def _print(name: str, r: dict) -> None:
    e = r["end_to_end_ms"]
    print(f"latency bench [{name}]: {r['frames_sent']} frames at {r['rate_hz']:g} Hz for {r['seconds']:g} s; "
          f"datagrams received {r['datagrams_received']}/{r['datagrams_sent']}, stale dropped {r['stale_dropped']}, "
          f"frames drawn {r['frames_drawn']} ({r['new_frames_drawn_per_s']:.1f}/s, {r['render_path']} path, "
          f"{r['receiver']} receiver, draw on {r['draw']}); read >1 ms after arrival {r['waited_over_1ms']}; "
          f"loadavg {r['loadavg']}")
    print(f"  receive -> GPU finished ms: p50 {e.get('p50', math.nan):.2f}  p99 {e.get('p99', math.nan):.2f}  "
          f"max {e.get('max', math.nan):.2f}; CPU before draw p99 {r['cpu_before_draw_p99_ms']:.3f} ms "
          f"(snapshot {r['cpu_stage_p99_ms']['snapshot']:.3f}, "
          f"pipeline+map {r['cpu_stage_p99_ms']['pipeline_map']:.3f})")
    st = r["stages_ms"]
    print("  stages p50/p99 ms: " + ", ".join(
        f"{name} {st[name].get('p50_ms', math.nan):.2f}/{st[name].get('p99_ms', math.nan):.2f}"
        for name in ("receive_snap", "solve_map", "draw_submit", "gpu_finish") if name in st))
    rss = r["rss_mb_per_second"]
    if rss:
        print(f"  RSS MiB first/last/max: {rss[0]:.1f}/{rss[-1]:.1f}/{max(rss):.1f}")


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-c", "--character", required=True,
                        help="character .npz (the ICT head for the issue's numbers)")
    parser.add_argument("--input", choices=tuple(SENDERS), default="vmc",
                        help="the protocol sent and listened for (vmc, the default, openseeface, or a phone "
                             "kind, ifacialmocap / vtubestudio, played by the sender process)")
    parser.add_argument("--rate", type=float, default=120.0, help="frames per second sent (120)")
    parser.add_argument("--seconds", type=float, default=30.0, help="seconds of sending (30)")
    parser.add_argument("--size", default="640x480", help="render size (640x480)")
    parser.add_argument("--fps", type=float, default=60.0,
                        help="frame loop ticks per second (60); with --draw arrival the idle redraw rate")
    parser.add_argument("--draw", choices=("arrival", "tick"), default="arrival",
                        help="the run's drawing: on arrival of each frame (default) or on the --fps grid")
    parser.add_argument("--path", choices=("auto", "gpu", "cpu"), default="auto", help="deformation path")
    parser.add_argument("--quality", choices=QUALITIES, default="auto",
                        help="the run's --quality (auto, as run's default)")
    parser.add_argument("--msaa", type=int, default=None, help="the run's --msaa (default: as --quality decides)")
    parser.add_argument("--receiver", choices=("process", "thread"), default="process",
                        help="the run's receiver: a child process (default) or a thread")
    parser.add_argument("--panel", action="store_true",
                        help="then the same run with the operator's panel shown and hidden on alternate ticks: CPU "
                             "ms per tick p50/p99 of each, what the panel adds, and the GPU wait (the panel's draw "
                             "on llvmpipe)")
    parser.add_argument("--web", action="store_true",
                        help="then run --web: the view page's cost per frame at 1280x720 and the frame loop's p99 "
                             "with 0 and 10 view clients connected")
    parser.add_argument("--web-decode", action="store_true",
                        help="with --web: the view clients inflate every frame's pixels (as a page does)")
    add_live_picture_arguments(parser)
    parser.add_argument("--flood", action="store_true", help="then flood: --flood-factor x the rate")
    parser.add_argument("--flood-factor", type=float, default=10.0, help="flood rate multiple (10)")
    parser.add_argument("--flood-seconds", type=float, default=60.0, help="seconds of flooding (60)")
    parser.add_argument("--verbose", action="store_true", help="show the run's own log")


register_bench(
    "latency",
    bench_latency,
    "receive -> frame-finished latency of a headless live run fed by a sender process (VMC, OpenSeeFace, "
    "iFacialMocap or VTube Studio; optional flood), and the decode cost per datagram",
    _add_arguments,
    comparable=True,
)
