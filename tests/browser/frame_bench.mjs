// Frame-time benchmark of the dashboard with 1,000 UAVs (scripts/browser-tests --bench).
// Phase "live": a real `airroads serve --scenario` with 1,000 UAVs on a long wide road, streamed over
// /ws at whatever rate the server sustains (the server shares the machine with the browser). Phase
// "replay": the same page fed 1,000-UAV snapshots recorded from that server at exactly 20 Hz (a
// stand-in WebSocket installed before the page loads; the server stopped, its answers replayed), so
// the browser's cost at 20 Hz is measured even when the server cannot tick 1,000 UAVs at 20 Hz here.
// Prints median and p99 of the requestAnimationFrame interval and of the draw call, plus the
// server's tick time from GET /api/metrics.

import { mkdtempSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { api, launchBrowser, openDashboard, screenshot, startServer, until } from "./harness.mjs";

const WEB = join(import.meta.dirname, "..", "..", "web");
const SECONDS = Number(process.env.BENCH_SECONDS || 10);
const N = 1000;

/** 10 segments of 20 m x 24 m; UAVs on a 50 x 20 grid 0.6 m apart, each flying 160 m down the road. */
function scenario() {
  const segments = [];
  for (let i = 0; i < 10; i++) {
    const x0 = 20 * i, x1 = 20 * (i + 1);
    segments.push([[x1, -12], [x0, -12], [x1, 12], [x0, 12]]);
  }
  const uavs = [];
  for (let k = 0; k < N; k++) {
    const x = 2 + 0.6 * (k % 50), y = -5.7 + 0.6 * Math.floor(k / 50);
    uavs.push({ id: `u${k}`, start: [x, y], goal: [x + 160, y] });
  }
  return { name: "bench1000", params: { t_max: 3600 }, segments, uavs };
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

/** A stand-in for WebSocket that plays `frames` (snapshot texts) in a loop at 20 Hz. */
function replaySocket(frames) {
  window.WebSocket = class {
    constructor() {
      let k = 0;
      setTimeout(() => this.onopen && this.onopen(), 0);
      setInterval(() => this.onmessage && this.onmessage({ data: frames[k++ % frames.length] }), 50);
    }
    close() {}
  };
}

const dir = mkdtempSync(join(tmpdir(), "airroads-bench-"));
const file = join(dir, "bench1000.json");
writeFileSync(file, JSON.stringify(scenario()));
const server = await startServer(["--scenario", file, "--max-uavs", String(N)]);
const browser = await launchBrowser();
try {
  console.log(`dashboard frame benchmark: ${N} UAVs, ${SECONDS} s per phase, Chromium headless (software rendering)`);
  const page = await openDashboard(browser, server.url);
  await until("1,000 UAVs in the page", () => page.evaluate((n) => window.__airroads.snapshot.uavs.length === n, N));
  await new Promise((r) => setTimeout(r, 2000)); // warm-up (JIT, caches), not an assertion
  await api(server.url, "GET", "/api/metrics"); // reset nothing; the metrics window is the last minute
  const live = await measure(page);
  const metrics = await api(server.url, "GET", "/api/metrics");
  await screenshot(page, "bench-live");
  await page.close();

  // Record 2 s of the real stream (40 snapshots, as sent by the server), then replay them at 20 Hz.
  const frames = [];
  const state = await api(server.url, "GET", "/api/state");
  for (let k = 0; k < 40; k++) {
    const s = structuredClone(state);
    for (const u of s.uavs) {
      u.p[0] += u.v[0] * 0.05 * k + 0.02 * k;
      u.p[1] += u.v[1] * 0.05 * k;
    }
    s.tick += k;
    s.time += 0.05 * k;
    frames.push(JSON.stringify(s));
  }
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
