"""A real windowed ``facepuppet run`` (glfw on an X display, not --headless) with its panel driven by real X input.

Run it on an X server (Xvfb): ``DISPLAY=:N python tests/helpers/panel_window.py -c CHARACTER.npz --png OUT.png``.
A VMC sender on 127.0.0.1 feeds the run; keyboard and mouse go through the X server itself (XTest, libXtst),
so glfw receives them as from a user and the run's own callbacks (Tab toggles the panel) handle them. Step by
step, each waiting for its effect before the next (a bounded number of ticks):

1. Tab: the panel hides; Tab again: it is shown;
2. a click on the channel ``jawOpen``: the Response section edits it;
3. a click on its curve "threshold": the config in force has jawOpen's curve threshold;
4. a click on the "mirror" checkbox: the config in force mirrors;
5. a click on the "Chain, character" header: it opens
   (4 and 5 only where the window shows them: listed in ``skipped`` otherwise);

then the window's frame is saved as ``--png`` and one JSON line says what happened (``steps``: each step's
outcome, ``mirror``, ``selected``, ``visible_seen``: the panel's visibility after each Tab).
Exit 0 when every step had its effect, 1 otherwise (the JSON says which did not).
"""

from __future__ import annotations

import argparse
import ctypes
import ctypes.util
import json
import sys
import threading
import time
from pathlib import Path

XK_TAB = 0xFF09
STEP_TICKS = 400  # ticks a step may wait for its effect


class XTest:
    """Fake key presses and mouse clicks through the X server (libXtst): real X events for every client."""

    def __init__(self) -> None:
        x11 = ctypes.CDLL(ctypes.util.find_library("X11") or "libX11.so.6")
        xtst = ctypes.CDLL(ctypes.util.find_library("Xtst") or "libXtst.so.6")
        x11.XOpenDisplay.restype = ctypes.c_void_p
        x11.XOpenDisplay.argtypes = [ctypes.c_char_p]
        x11.XKeysymToKeycode.argtypes = [ctypes.c_void_p, ctypes.c_ulong]
        x11.XFlush.argtypes = [ctypes.c_void_p]
        x11.XSync.argtypes = [ctypes.c_void_p, ctypes.c_int]
        x11.XCloseDisplay.argtypes = [ctypes.c_void_p]
        x11.XSetInputFocus.argtypes = [ctypes.c_void_p, ctypes.c_ulong, ctypes.c_int, ctypes.c_ulong]
        xtst.XTestFakeKeyEvent.argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_ulong]
        xtst.XTestFakeButtonEvent.argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_ulong]
        xtst.XTestFakeMotionEvent.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_int,
                                              ctypes.c_ulong]
        self.x11, self.xtst = x11, xtst
        self.display = x11.XOpenDisplay(None)
        if not self.display:
            raise RuntimeError("XTest: cannot open the X display ($DISPLAY)")

    def key(self, keysym: int, down: bool) -> None:
        code = self.x11.XKeysymToKeycode(self.display, keysym)
        self.xtst.XTestFakeKeyEvent(self.display, code, int(down), 0)
        self.x11.XSync(self.display, 0)

    def focus_follows_pointer(self) -> None:
        """Keyboard focus to PointerRoot: keys go to the window under the pointer (with no window manager, a
        client that set the focus while its window was not yet viewable can leave it on None, and keys vanish)."""
        self.x11.XSetInputFocus(self.display, 1, 1, 0)  # PointerRoot, RevertToPointerRoot, CurrentTime
        self.x11.XSync(self.display, 0)

    def move(self, x: float, y: float) -> None:
        self.xtst.XTestFakeMotionEvent(self.display, -1, int(round(x)), int(round(y)), 0)
        self.x11.XSync(self.display, 0)

    def button(self, down: bool) -> None:
        self.xtst.XTestFakeButtonEvent(self.display, 1, int(down), 0)
        self.x11.XSync(self.display, 0)

    def close(self) -> None:
        self.x11.XCloseDisplay(self.display)


def send_vmc_forever(port: int, stop: threading.Event) -> None:
    """A face over VMC to 127.0.0.1:port at 60 frames/s: a slowly opening jaw, a blink, a smile."""
    from pythonosc.udp_client import SimpleUDPClient

    from helpers.vmc_run import send_vmc

    client = SimpleUDPClient("127.0.0.1", port)
    i = 0
    while not stop.is_set():
        phase = (i % 120) / 120
        send_vmc(client, {"JawOpen": 0.2 + 0.5 * phase, "EyeBlinkLeft": 0.8, "EyeBlinkRight": 0.1,
                          "MouthSmileLeft": 0.6, "MouthSmileRight": 0.55, "BrowInnerUp": 0.3})
        i += 1
        time.sleep(1 / 60)


class Driver:
    """The tick hook: one step of the plan at a time, each waiting (bounded) for its effect."""

    def __init__(self, stop: threading.Event, png: Path, xtest: XTest) -> None:
        self.stop, self.png, self.x = stop, png, xtest
        self.panel = None
        self.window = None
        self.steps: dict[str, bool] = {}
        self.visible_seen: list[bool] = []
        self.skipped: list[str] = []  # clicks on controls the window is too short to show
        self.plan = [("ready", None), ("tab", False), ("tab", True), ("click", "channel.jawOpen"),
                     ("click", "response.curve.threshold"),
                     ("click", "face.mirror"), ("click", "header.chain"), ("settle", None), ("shot", None)]
        self.waited = 0
        self.pending = None  # (what, check) of the step whose effect is awaited
        self.release = None  # (tick, action): the release of the last press
        self.ticks = 0

    def _screen(self, label: str) -> tuple[float, float]:
        import glfw

        x0, y0, x1, y1 = self.panel.rects[label]
        wx, wy = glfw.get_window_pos(self.window)
        return wx + (x0 + x1) / 2, wy + (y0 + y1) / 2

    def __call__(self, info) -> None:
        self.ticks += 1
        if self.release is not None:  # the release of a press, a few ticks (ImGui frames) after it
            at, action = self.release
            if self.ticks >= at:
                action()
                self.release = None
            return
        if self.pending is not None:
            name, check = self.pending
            if check():
                self.steps[name] = True
                self.pending = None
            elif self.waited >= STEP_TICKS:
                self.steps[name] = False
                self.pending = None
            else:
                self.waited += 1
                return
        if not self.plan:
            self.stop.set()
            return
        what, arg = self.plan.pop(0)
        self.waited = 0
        panel = self.panel
        if what == "ready":  # frames drawn and the panel laid out with the channel rows
            self.pending = ("ready", lambda: info.raw is not None and "channel.jawOpen" in panel.rects)
        elif what == "tab":
            self.x.key(XK_TAB, True)
            self.release = (self.ticks + 3, lambda: self.x.key(XK_TAB, False))

            def shown_as(want=arg):
                if panel.visible != want:
                    return False
                self.visible_seen.append(panel.visible)
                return True
            self.pending = (f"tab->{'shown' if arg else 'hidden'}", shown_as)
        elif what == "click":
            if arg not in panel.rects or panel.rects[arg][3] > panel.window_size[1] - 8:
                self.skipped.append(arg)  # below the panel window's bottom (one window: it scrolls)
                return
            x, y = self._screen(arg)
            self.x.move(x, y)
            self.release = (self.ticks + 3, lambda: self.x.button(False))
            self.x.button(True)
            checks = {"channel.jawOpen": lambda: panel.selected == "jawOpen",
                      "response.curve.threshold": lambda: panel.pipeline.current_config().channel("jawOpen").curve
                      == "threshold",
                      "face.mirror": lambda: panel.pipeline.current_config().mirror,
                      "header.chain": lambda: "chain.text" in panel.rects}
            self.pending = (f"click {arg}", checks[arg])
        elif what == "settle":  # a few ticks for the refreshed status lines
            self.pending = ("settle", lambda: self.waited >= 40)
        elif what == "shot":
            self._shot()
            self.steps["shot"] = self.png.exists()

    def _shot(self) -> None:
        import numpy as np
        from PIL import Image

        fbo = self.panel.fbo  # the window's own framebuffer (the back buffer, before this tick's swap)
        w, h = self.panel.width, self.panel.height
        data = fbo.read(viewport=(0, 0, w, h), components=3)
        image = np.frombuffer(data, dtype=np.uint8).reshape(h, w, 3)[::-1]
        self.png.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(image).save(self.png)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("-c", "--character", required=True)
    p.add_argument("--png", type=Path, required=True)
    p.add_argument("--size", default="1600x900")
    p.add_argument("--profile", default=None, help="a profile path for the run (shows the Profile section)")
    p.add_argument("--record", default=None, help="--record FILE for the run (shows the Record section recording)")
    p.add_argument("--duration", type=float, default=240.0)
    args = p.parse_args(argv)

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # helpers.*
    from facepuppet.runtime.commands import run

    from helpers.logs import logged
    from helpers.udp_helpers import free_udp_port

    port = free_udp_port()
    parser = argparse.ArgumentParser()
    run.register(parser.add_subparsers())
    extra = (["--profile", args.profile] if args.profile else []) + (["--record", args.record] if args.record else [])
    ns = parser.parse_args(["run", "-c", args.character, "--input", "vmc", "--listen", f"127.0.0.1:{port}",
                            "--size", args.size, "--duration", str(args.duration), "--fps", "30", *extra])
    stop = threading.Event()
    xtest = XTest()
    driver = Driver(stop, args.png, xtest)

    def on_panel(panel):
        driver.panel = panel

    def on_ready(address):
        threading.Thread(target=send_vmc_forever, args=(port, stop), daemon=True).start()

    def hook(info):
        if driver.window is None:
            import glfw

            driver.window = glfw.get_current_context()
        driver(info)

    logs: list[str] = []
    try:
        with logged(logs):
            result = run.run_live(ns, stop_event=stop, on_ready=on_ready, hooks=[hook],
                                  on_panel=on_panel)
    finally:
        stop.set()
        xtest.close()
    panel = result.panel
    config = panel.pipeline.current_config() if panel else None
    out = {"steps": driver.steps, "visible_seen": driver.visible_seen, "selected": panel.selected if panel else None,
           "mirror": bool(config.mirror) if config else None, "ticks": driver.ticks,
           "curve": config.channel("jawOpen").curve if config else None, "skipped": driver.skipped,
           "left": [w for w, _ in driver.plan], "png": str(args.png),
           "window": "run: the panel is shown" in "\n".join(logs)}
    print(json.dumps(out))
    return 0 if driver.steps and all(driver.steps.values()) and not driver.plan else 1


if __name__ == "__main__":
    raise SystemExit(main())
