// Shared by the browser tests and the frame benchmark: a real `airroads serve` on 127.0.0.1:0,
// Debian's Chromium through playwright-core, API helpers and polling (no fixed sleeps).

import { spawn } from "node:child_process";
import { mkdirSync } from "node:fs";
import { join } from "node:path";
import { createInterface } from "node:readline";
import { chromium } from "playwright-core";

export const BIN = process.env.AIRROADS_BIN;
export const ARTIFACTS = process.env.AIRROADS_ARTIFACTS || join(import.meta.dirname, "artifacts");
const CHROMIUM = process.env.CHROMIUM || "/usr/bin/chromium";

/** Starts `airroads serve --addr 127.0.0.1:0 --ephemeral --policy pd ARGS…`; resolves with {url, stop}. */
export async function startServer(args = []) {
  if (!BIN) throw new Error("AIRROADS_BIN is not set (run scripts/browser-tests)");
  const child = spawn(BIN, ["serve", "--addr", "127.0.0.1:0", "--ephemeral", "--policy", "pd", ...args], {
    stdio: ["ignore", "pipe", "pipe"],
  });
  let stderr = "";
  child.stderr.on("data", (d) => (stderr += d));
  const url = await new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error(`airroads serve did not start in 30 s:\n${stderr}`)), 30000);
    child.on("exit", (code) => reject(new Error(`airroads serve exited with ${code}:\n${stderr}`)));
    createInterface({ input: child.stdout }).once("line", (line) => {
      clearTimeout(timer);
      const m = /^airroads serving on (http:\/\/\S+)/.exec(line);
      if (m) resolve(m[1]);
      else reject(new Error(`unexpected first line from airroads serve: ${line}`));
    });
  });
  child.stdout.resume();
  const stop = async () => {
    if (child.exitCode !== null) return;
    const exited = new Promise((r) => child.once("exit", r));
    child.kill("SIGTERM");
    await exited;
  };
  return { url, stop, stderr: () => stderr };
}

export async function launchBrowser() {
  mkdirSync(ARTIFACTS, { recursive: true });
  return chromium.launch({
    executablePath: CHROMIUM,
    headless: true,
    args: [
      "--no-sandbox",
      "--disable-gpu",
      "--disable-quic",
      "--no-first-run",
      "--disable-background-networking",
      "--disable-component-update",
      "--disable-sync",
    ],
  });
}

/** A new page on the dashboard, waiting until the first snapshot and the road are drawn. */
export async function openDashboard(browser, url) {
  const page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
  const errors = [];
  page.on("pageerror", (e) => errors.push(e.message));
  // Chromium logs every 4xx answer as "Failed to load resource"; the tests provoke some on purpose.
  page.on("console", (m) => m.type() === "error" && !/^Failed to load resource/.test(m.text()) && errors.push(m.text()));
  await page.goto(url);
  await page.waitForFunction(() => window.__airroads && window.__airroads.snapshot && window.__airroads.geometry);
  page.jsErrors = errors;
  return page;
}

export async function screenshot(page, name) {
  await page.screenshot({ path: join(ARTIFACTS, `${name}.png`) });
}

/** JSON API call; throws with the body on an unexpected status. */
export async function api(url, method, path, body, expect = [200, 201, 204]) {
  const res = await fetch(url + path, {
    method,
    // Every change says it is JSON, also without a body (the server refuses others).
    headers: body === undefined && method === "GET" ? {} : { "Content-Type": "application/json" },
    body: body === undefined ? undefined : JSON.stringify(body),
  });
  const text = await res.text();
  if (!expect.includes(res.status)) throw new Error(`${method} ${path}: HTTP ${res.status}: ${text}`);
  return text ? JSON.parse(text) : null;
}

/** Polls `f` (async) until it returns a truthy value; fails with `what` and the last value. */
export async function until(what, f, timeoutMs = 20000, everyMs = 100) {
  const end = Date.now() + timeoutMs;
  let last;
  for (;;) {
    last = await f();
    if (last) return last;
    if (Date.now() > end) throw new Error(`timed out after ${timeoutMs} ms waiting for ${what}; last: ${JSON.stringify(last)}`);
    await new Promise((r) => setTimeout(r, everyMs));
  }
}

/** Page coordinates of world point (x, y) in the dashboard's current view. */
export const pagePoint = (page, x, y) => page.evaluate(([x, y]) => window.__airroads.pagePoint(x, y), [x, y]);

/** A real mouse click at world point (x, y). */
export async function clickWorld(page, x, y, modifiers = []) {
  const [px, py] = await pagePoint(page, x, y);
  for (const m of modifiers) await page.keyboard.down(m);
  await page.mouse.click(px, py);
  for (const m of modifiers) await page.keyboard.up(m);
}
