// Frame-time benchmark of the dashboard with 1,000 UAVs, or BENCH_UAVS (scripts/browser-tests --bench).
// Phase "live": a real `airroads serve --scenario` with N UAVs on a long wide road, streamed over
// /ws?format=bin at whatever rate the server sustains (the server shares the machine with the
// browser). Phase "replay": the same page fed 40 consecutive binary frames recorded from that
// server, in a loop at exactly 20 Hz (a stand-in WebSocket installed before the page loads; the
// server stopped, its answers replayed), so the browser's cost at 20 Hz is measured even when the
// server cannot tick N UAVs at 20 Hz here. BENCH_SCENARIO flies a scenario file of your own instead.
// Prints median and p99 of the requestAnimationFrame interval and of the draw call, plus the
// server's tick time from GET /api/metrics.

import { mkdtempSync, readFileSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { api, launchBrowser, openDashboard, screenshot, startServer, until } from "./harness.mjs";

const WEB = join(import.meta.dirname, "..", "..", "web");
const SECONDS = Number(process.env.BENCH_SECONDS || 10);
// BENCH_SCENARIO: a scenario file to fly instead (e.g. `airroads bench scale --write-scenarios`).
const GIVEN = process.env.BENCH_SCENARIO ? JSON.parse(readFileSync(process.env.BENCH_SCENARIO, "utf8")) : null;
const N = GIVEN ? GIVEN.uavs.length : Number(process.env.BENCH_UAVS || 1000);

/**
 * 1,000 UAVs: 10 segments of 20 m x 24 m, UAVs on a 50 x 20 grid 0.6 m apart, each flying 160 m
 * down the road. More: 100 columns and a road as wide and long as the grid needs.
 */
function scenario() {
  const cols = N <= 1000 ? 50 : 100, rows = Math.ceil(N / cols);
  const half = Math.max(12, (rows * 0.6) / 2 + 3);
  const pieces = Math.max(10, Math.ceil((2 + cols * 0.6 + 165) / 20));
  const segments = [];
  for (let i = 0; i < pieces; i++) {
    const x0 = 20 * i, x1 = 20 * (i + 1);
    segments.push([[x1, -half], [x0, -half], [x1, half], [x0, half]]);
  }
  const uavs = [];
  for (let k = 0; k < N; k++) {
    const x = 2 + 0.6 * (k % cols), y = -0.3 * (rows - 1) + 0.6 * Math.floor(k / cols);
    uavs.push({ id: `u${k}`, start: [x, y], goal: [x + 160, y] });
  }
  return { name: `bench${N}`, params: { t_max: 3600 }, segments, uavs };
}

const quantile = (xs, q) => {
  const s = [...xs].sort((a, b) => a - b);
  return s.length ? s[Math.min(s.length - 1, Math.floor(q * s.length))] : NaN;
};

/** Records rAF intervals and draw times for SECONDS on `page`. */
async function measure(page) {
  const start = await page.evaluate(() => {
    const w = window.__airroads;
    window.__bench = { deltas: [], last: null, draws0: w.perf.drawMs.length, frames0: w.app.stream.frames, t0: performance.now(), tick0: w.snapshot.tick };
    const step = (t) => {
      const b = window.__bench;
      if (b.last !== null) b.deltas.push(t - b.last);
      b.last = t;
      if (!b.stop) requestAnimationFrame(step);
    };
    requestAnimationFrame(step);
    return w.perf.drawMs.length;
  });
  await new Promise((r) => setTimeout(r, SECONDS * 1000));
  return page.evaluate((start) => {
    const b = window.__bench;
    b.stop = true;
    const w = window.__airroads;
    const seconds = (performance.now() - b.t0) / 1000;
    return {
      deltas: b.deltas,
      draws: w.perf.drawMs.slice(start),
      snapshotsPerS: (w.app.stream.frames - b.frames0) / seconds,
      ticksPerS: (w.snapshot.tick - b.tick0) / seconds,
      uavs: w.snapshot.uavs.length,
    };
  }, start);
}

function report(name, r) {
  const f = (x) => x.toFixed(1);
  console.log(
    `${name.padEnd(7)} ${String(r.uavs).padStart(5)} UAVs  snapshots ${f(r.snapshotsPerS).padStart(5)}/s` +
      `  frame interval median ${f(quantile(r.deltas, 0.5))} ms p99 ${f(quantile(r.deltas, 0.99))} ms (${r.deltas.length} frames)` +
      `  draw median ${f(quantile(r.draws, 0.5))} ms p99 ${f(quantile(r.draws, 0.99))} ms (${r.draws.length} draws)`,
  );
}

/**
 * A stand-in for WebSocket that sends `first` (the roster and reservations frames) and then plays
 * `ticks` in a loop at 20 Hz; frames arrive as base64 and are sent as ArrayBuffers.
 */
function replaySocket({ first, ticks }) {
  const buffer = (b64) => Uint8Array.from(atob(b64), (c) => c.charCodeAt(0)).buffer;
  const [head, frames] = [first.map(buffer), ticks.map(buffer)];
  window.WebSocket = class {
    constructor() {
      let k = 0;
      setTimeout(() => {
        this.onopen && this.onopen();
        for (const data of head) this.onmessage && this.onmessage({ data });
      }, 0);
      setInterval(() => this.onmessage && this.onmessage({ data: frames[k++ % frames.length] }), 50);
    }
    close() {}
  };
}

/** 40 consecutive tick frames of `url`'s binary stream and the frames before them, as base64. */
function recordStream(url) {
  return new Promise((resolve) => {
    const ws = new WebSocket(`${url.replace("http", "ws")}/ws?format=bin`);
    ws.binaryType = "arraybuffer";
    const first = [], ticks = [];
    const b64 = (data) => {
      const bytes = new Uint8Array(data);
      let s = "";
      for (let i = 0; i < bytes.length; i += 0x8000) s += String.fromCharCode(...bytes.subarray(i, i + 0x8000));
      return btoa(s);
    };
    ws.onmessage = (ev) => {
      const kind = new Uint8Array(ev.data)[1];
      if (kind !== 1) {
        if (!ticks.length) first.push(b64(ev.data));
        return;
      }
      ticks.push(b64(ev.data));
      if (ticks.length === 40) {
        ws.close();
        resolve({ first, ticks });
      }
    };
  });
}

const dir = mkdtempSync(join(tmpdir(), "airroads-bench-"));
const file = join(dir, "bench1000.json");
writeFileSync(file, JSON.stringify(GIVEN || scenario()));
const server = await startServer(["--scenario", file, "--max-uavs", String(N)]);
const browser = await launchBrowser();
try {
  console.log(`dashboard frame benchmark: ${N} UAVs, ${SECONDS} s per phase, Chromium headless (software rendering), binary stream`);
  const page = await openDashboard(browser, server.url);
  await until(`${N} UAVs in the page`, () => page.evaluate((n) => window.__airroads.snapshot?.uavs.length === n, N), 120000);
  await new Promise((r) => setTimeout(r, 2000)); // warm-up (JIT, caches), not an assertion
  await api(server.url, "GET", "/api/metrics"); // reset nothing; the metrics window is the last minute
  const live = await measure(page);
  const metrics = await api(server.url, "GET", "/api/metrics");
  await screenshot(page, "bench-live");
  // Record 40 consecutive frames of the real stream (as the server sent them), to replay at 20 Hz.
  const frames = await page.evaluate(recordStream, server.url);
  await page.close();
  // The replay runs without the server (stopped, so that its 1,000-UAV loop does not compete for the
  // CPU): the page's files come from web/ and its REST reads from the answers recorded here.
  const recorded = {};
  for (const path of ["/api/road/geometry", "/api/policies", "/api/metrics"]) recorded[path] = await api(server.url, "GET", path);
  await server.stop();
  const replayPage = await browser.newPage({ viewport: { width: 1280, height: 800 } });
  await replayPage.route(`${server.url}/**`, (route) => {
    const path = new URL(route.request().url()).pathname;
    if (recorded[path]) return route.fulfill({ json: recorded[path] });
    const file = path === "/" ? "index.html" : path.slice(1);
    const type = { html: "text/html", js: "text/javascript", css: "text/css" }[file.split(".").pop()];
    return route.fulfill({ path: join(WEB, file), contentType: type });
  });
  await replayPage.addInitScript(replaySocket, frames);
  await replayPage.goto(server.url);
  await replayPage.waitForFunction((n) => window.__airroads?.snapshot?.uavs.length === n && window.__airroads.geometry, N);
  await new Promise((r) => setTimeout(r, 2000));
  const replay = await measure(replayPage);
  await screenshot(replayPage, "bench-replay");

  report("live", live);
  report("replay", replay);
  const t = metrics.tick;
  console.log(
    `server  tick p50 ${(t.p50_us / 1000).toFixed(1)} ms p99 ${(t.p99_us / 1000).toFixed(1)} ms max ${(t.max_us / 1000).toFixed(1)} ms` +
      `  (dt ${metrics.dt * 1000} ms; ${live.ticksPerS.toFixed(1)} ticks/s seen by the page; overruns ${metrics.overruns}, missed ticks ${metrics.missed_ticks})`,
  );
} finally {
  await browser.close();
  await server.stop();
}
