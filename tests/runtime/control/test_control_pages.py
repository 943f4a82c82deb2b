"""``run --web``'s two pages in a real headless Chromium (the Debian package, driven by playwright-core from
node): the remote panel's Joy button changes the drawn weights on the next ticks, the view page draws the
avatar with alpha 0 in the corners, and a page of another origin cannot open the control WebSocket."""

from __future__ import annotations

import http.server
import json
import os
import shutil
import subprocess
import threading
from pathlib import Path

import pytest

from helpers.web_run import web_run

pytestmark = [pytest.mark.gl, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[3]
SCRIPT = ROOT / "tests" / "helpers" / "control_pages.js"


def _chromium_or_skip() -> tuple[str, Path]:
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed (make setup installs it): the pages are driven by playwright-core")
    if not Path("/usr/bin/chromium").exists():
        pytest.skip("/usr/bin/chromium is absent (Debian's chromium package, make setup installs it)")
    modules = ROOT / "node_modules"
    if not (modules / "playwright-core").is_dir():
        pytest.skip("node_modules/playwright-core is absent: run npm ci (make setup does)")
    return node, modules


class _OtherOrigin(http.server.BaseHTTPRequestHandler):
    def do_GET(self):  # noqa: N802 (the handler's name is http.server's)
        body = b"<!doctype html><title>another site</title><p>a page the user happens to open"
        self.send_response(200)
        self.send_header("Content-Type", "text/html")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args):
        pass


def test_the_remote_panel_and_the_view_page_in_chromium(tmp_path):
    node, modules = _chromium_or_skip()
    other = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _OtherOrigin)
    threading.Thread(target=other.serve_forever, daemon=True).start()
    try:
        with web_run(tmp_path, size="160x120") as run:
            clicked_at = len(run.ticks)
            done = subprocess.run([node, str(SCRIPT), f"http://127.0.0.1:{run.port}",
                                   f"http://127.0.0.1:{other.server_address[1]}/"],
                                  env={**os.environ, "NODE_PATH": str(modules)}, capture_output=True, text=True,
                                  timeout=240)
            assert done.returncode == 0, done.stderr
            got = json.loads(done.stdout)
            smile = run.character.shape_names.index("smile")
            drawn = [w[smile] for w in run.weights[clicked_at:]]
    finally:
        other.shutdown()
    assert got["smile_before"] == 0.0 and got["smile_after"] == pytest.approx(1.0) and got["joy_lit"]
    assert got["remote_errors"] == []
    # the drawn weights: off before the click, ramping over the 0.15 s fade, then on
    assert drawn[0] == 0.0 and drawn[-1] == pytest.approx(1.0)
    assert any(0.0 < v < 1.0 for v in drawn), "the button's 0.15 s fade shows in the drawn ticks"
    assert (got["width"], got["height"]) == (160, 120)
    assert got["corners"] == [0, 0, 0, 0] and got["max_alpha"] == 255
    assert got["view_fps"] > 0 and got["hud"].endswith("ms") and "fps" in got["hud"]
    assert got["other_origin"] == "error"
    assert run.result.counters["web"]["refused_origin"] == 1
