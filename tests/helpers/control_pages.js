// Drives run --web's pages in a real headless Chromium (playwright-core, the Debian package's binary).
// argv: BASE_URL (http://127.0.0.1:PORT) OTHER_URL (a page of another origin) ; prints one JSON object.
"use strict";
const { chromium } = require("playwright-core");

const ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
              "--disable-component-update", "--disable-sync", "--no-first-run"];

(async () => {
  const [base, other] = process.argv.slice(2);
  const out = {};
  const browser = await chromium.launch({ executablePath: "/usr/bin/chromium", args: ARGS });
  try {
    // the remote panel: its Joy button
    const remote = await browser.newPage();
    await remote.goto(`${base}/`);
    await remote.waitForSelector('[data-expression="Joy"]', { timeout: 30000 });
    await remote.waitForFunction(() => window.remote.weights !== null, null, { timeout: 30000 });
    out.smile_before = await remote.evaluate(() => window.remote.weights.weights.smile);
    await remote.click('[data-expression="Joy"]');
    await remote.waitForFunction(() => window.remote.weights.weights.smile > 0.99, null, { timeout: 30000 })
      .catch(async (e) => {
        const state = await remote.evaluate(() => JSON.stringify({ weights: window.remote.weights, status: window.remote.status,
                                                                    errors: window.remote.errors }));
        throw new Error(`${e.message}; the page had ${state}`);
      });
    out.smile_after = await remote.evaluate(() => window.remote.weights.weights.smile);
    out.joy_lit = await remote.evaluate(() => document.querySelector('[data-expression="Joy"]').classList.contains("on"));
    out.remote_errors = await remote.evaluate(() => window.remote.errors);

    // the view page: the avatar with alpha
    const view = await browser.newPage();
    const said = [];
    view.on("console", (m) => said.push(m.text()));
    view.on("pageerror", (e) => said.push(String(e)));
    await view.goto(`${base}/view`);
    await view.waitForFunction(() => window.viewStats.frames >= 5, null, { timeout: 30000 })
      .catch(async (e) => {
        const state = await view.evaluate(() => JSON.stringify(window.viewStats));
        throw new Error(`${e.message}; the view page had ${state}, said ${JSON.stringify(said)}`);
      });
    Object.assign(out, await view.evaluate(() => {
      const c = document.getElementById("view");
      const g = c.getContext("2d");
      const all = g.getImageData(0, 0, c.width, c.height).data;
      let maxAlpha = 0;
      for (let i = 3; i < all.length; i += 4) maxAlpha = Math.max(maxAlpha, all[i]);
      const corner = (x, y) => g.getImageData(x, y, 1, 1).data[3];
      return { width: c.width, height: c.height, max_alpha: maxAlpha,
               corners: [corner(0, 0), corner(c.width - 1, 0), corner(0, c.height - 1), corner(c.width - 1, c.height - 1)],
               view_fps: window.viewStats.fps, view_lag_ms: window.viewStats.lag_ms,
               hud: document.getElementById("hud").textContent };
    }));

    // a page of another origin opening the WebSocket
    const stranger = await browser.newPage();
    await stranger.goto(other);
    const ws = base.replace("http://", "ws://") + "/ws";
    out.other_origin = await stranger.evaluate((url) => new Promise((resolve) => {
      const socket = new WebSocket(url);
      socket.onopen = () => { resolve("open"); socket.close(); };
      socket.onerror = () => resolve("error");
    }), ws);
  } finally {
    await browser.close();
  }
  process.stdout.write(JSON.stringify(out) + "\n");
})().catch((e) => { process.stderr.write(String(e && e.stack || e) + "\n"); process.exit(1); });
