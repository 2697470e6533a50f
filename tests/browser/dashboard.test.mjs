// End-to-end tests of the dashboard: a real `airroads serve` per test, Debian's Chromium, real
// clicks and keys; outcomes are checked through the REST API. Screenshots go to ARTIFACTS.

import { after, before, test } from "node:test";
import assert from "node:assert/strict";
import { execFileSync } from "node:child_process";
import { mkdtempSync, readFileSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { createServer } from "node:http";
import { createServer as createNetServer } from "node:net";
import { join } from "node:path";
import { ARTIFACTS, BIN, api, clickWorld, launchBrowser, openDashboard, pagePoint, screenshot, startServer, until } from "./harness.mjs";

const STRAIGHT = join(import.meta.dirname, "fixtures", "straight.json");
const NARROW = join(import.meta.dirname, "..", "..", "scenarios", "narrow16.json");
const DEPOT = join(import.meta.dirname, "..", "..", "scenarios", "depot.json");
let browser;

before(async () => {
  browser = await launchBrowser();
});
after(async () => {
  await browser?.close();
});

/** Runs `body(page, server)` against a fresh server and page; screenshots the page on failure. */
async function withDashboard(name, args, body) {
  const server = await startServer(args);
  const page = await openDashboard(browser, server.url);
  try {
    await body(page, server);
    assert.deepEqual(page.jsErrors, [], "no JavaScript errors in the page");
  } catch (e) {
    await screenshot(page, `${name}-failed`).catch(() => {});
    throw e;
  } finally {
    await page.close();
    await server.stop();
  }
}

const snapshot = (page) => page.evaluate(() => window.__airroads.snapshot);
const near = (a, b, tol) => Math.hypot(a[0] - b[0], a[1] - b[1]) <= tol;

test("the dashboard is served from the binary and the UAVs move on the canvas", async () => {
  await withDashboard("live", [], async (page, { url }) => {
    for (const [path, type] of [["/", "text/html"], ["/app.js", "text/javascript"], ["/style.css", "text/css"]]) {
      const res = await fetch(url + path);
      assert.equal(res.status, 200, path);
      assert.match(res.headers.get("content-type"), new RegExp(type), path);
    }
    const missing = await fetch(url + "/api/no-such-route");
    assert.equal(missing.status, 404);
    assert.equal((await missing.json()).error.code, "not_found");

    const first = await snapshot(page);
    assert.equal(first.uavs.length, 6, "the demo flies six UAVs");
    const canvasBefore = await page.evaluate(() => document.getElementById("view").toDataURL());
    const moved = await until("a UAV to move 0.5 m in the page's snapshots", async () => {
      const s = await snapshot(page);
      return s.uavs.some((u, k) => !near(u.p, first.uavs[k].p, 0.5)) && s;
    });
    assert.ok(moved.tick > first.tick);
    await until("the canvas to change", async () =>
      (await page.evaluate(() => document.getElementById("view").toDataURL())) !== canvasBefore);
    await until("the header to show the tick rate and tick time", async () => {
      const [rate, p50] = await page.evaluate(() => ["rate", "p50"].map((id) => document.getElementById(id).textContent));
      return Number(rate) > 5 && Number.isFinite(Number(p50));
    });
    await screenshot(page, "live");
  });
});

test("pause and resume from the toolbar", async () => {
  await withDashboard("pause", [], async (page, { url }) => {
    await page.click("#pause");
    await until("the fleet to hold (GET /api/state)", async () => (await api(url, "GET", "/api/state")).paused);
    await page.locator("#paused-flag").waitFor({ state: "visible" });
    await until("the button to offer Resume", async () => (await page.textContent("#pause")) === "Resume");
    await screenshot(page, "paused");
    await page.click("#pause");
    await until("the fleet to fly again", async () => !(await api(url, "GET", "/api/state")).paused);
    await page.locator("#paused-flag").waitFor({ state: "hidden" });
  });
});

/** Holds the fleet until `id` hovers, then selects it with a real click; returns its snapshot. */
async function selectHovering(page, url, id) {
  await api(url, "POST", "/api/fleet/pause");
  const uav = await until(`${id} to hover`, async () => {
    const s = await snapshot(page);
    const u = s.uavs.find((u) => u.id === id);
    return s.paused && Math.hypot(...u.v) < 0.02 && u;
  });
  await clickWorld(page, uav.p[0], uav.p[1]);
  assert.deepEqual(await page.evaluate(() => window.__airroads.selection), [id]);
  return uav;
}

test("select a UAV by clicking it, click a goal on the road, and it arrives", async () => {
  await withDashboard("goal", [], async (page, { url }) => {
    // Hold the fleet so that the UAV sits still under the pointer while it is clicked.
    await selectHovering(page, url, "uav1");
    await api(url, "POST", "/api/fleet/resume");

    // A point on the centre line, 60% along the road, away from every UAV.
    const geometry = await page.evaluate(() => window.__airroads.geometry);
    const line = geometry.centerline;
    const goal = line[Math.floor(line.length * 0.6)];
    const s = await snapshot(page);
    assert.ok(s.uavs.every((u) => !near(u.p, goal, 1)), "the goal is clear of UAVs");
    await clickWorld(page, goal[0], goal[1]);
    const set = await until("the goal of uav1 to be set (GET /api/uavs/uav1)", async () => {
      const u = await api(url, "GET", "/api/uavs/uav1");
      return u.goal && near(u.goal, goal, 0.1) && u;
    });
    assert.ok(!set.arrived);
    await screenshot(page, "goal-set");
    const arrived = await until(
      "uav1 to arrive (GET /api/state)",
      async () => {
        const u = (await api(url, "GET", "/api/state")).uavs.find((u) => u.id === "uav1");
        return u.arrived && u;
      },
      120000,
      250,
    );
    assert.ok(near(arrived.p, set.goal, 0.15), `uav1 at ${arrived.p}, goal ${set.goal}`);
    await screenshot(page, "goal-arrived");
  });
});

test("10,000 UAVs loaded over REST are drawn from the binary stream; one is selected and sent to a goal", async () => {
  // The trunk scenario of `airroads bench scale`: 10,000 UAVs along a 12 km two-way road.
  const dir = mkdtempSync(join(tmpdir(), "airroads-trunk-"));
  execFileSync(BIN, ["bench", "scale", "--uavs", "10000", "--ticks", "1", "--write-scenarios", dir], { stdio: "ignore" });
  const scenario = JSON.parse(readFileSync(join(dir, "trunk10000.json"), "utf8"));
  assert.equal(scenario.uavs.length, 10000);
  await withDashboard("ten-thousand", ["--max-uavs", "10000"], async (page, { url }) => {
    await api(url, "POST", "/api/scenario", scenario);
    const drawn = await until("the page to hold 10,000 UAVs from the binary stream and the new road", () =>
      page.evaluate(() => {
        const w = window.__airroads;
        const ok = w.snapshot.uavs.length === 10000 && w.app.stream.rosterVersion > 0 && w.geometry.version === w.snapshot.road_version;
        return ok && w.perf.drawMs.length;
      }), 120000, 250);
    await until("the canvas to be drawn again with them", () => page.evaluate((n) => window.__airroads.perf.drawMs.length > n, drawn));
    await page.click("#fit");
    await screenshot(page, "ten-thousand");

    // Hold the fleet, zoom in on a UAV in the middle of the road with the wheel, and click it.
    const id = scenario.uavs[5000].id;
    await api(url, "POST", "/api/fleet/pause");
    const where = () => page.evaluate((id) => {
      const s = window.__airroads.snapshot;
      const u = s.uavs.find((u) => u.id === id);
      return s.paused && Math.hypot(...u.v) < 0.02 && u.p;
    }, id);
    let p = await until(`${id} to hover`, where, 60000, 250);
    const scale = () => page.evaluate(() => window.__airroads.app.camera.scale);
    for (let k = 0; k < 20 && (await scale()) < 15; k++) {
      const [px, py] = await pagePoint(page, p[0], p[1]);
      await page.mouse.move(px, py);
      await page.mouse.wheel(0, -300);
      await until("the wheel to zoom", async () => (await scale()) > 0);
    }
    assert.ok((await scale()) >= 15, "zoomed in to 15 pixels per metre or more");
    p = await where();
    await clickWorld(page, p[0], p[1]);
    assert.deepEqual(await page.evaluate(() => window.__airroads.selection), [id]);

    // A goal on the centre line, in view, 2-20 m from it and at least 1 m from every UAV.
    const goal = await page.evaluate(([p]) => {
      const { app, snapshot } = window.__airroads;
      const seen = (q) => {
        const [x, y] = app.camera.toScreen(q[0], q[1]);
        return x > 50 && y > 50 && x < app.canvas.clientWidth - 50 && y < app.canvas.clientHeight - 50;
      };
      const free = (q) => snapshot.uavs.every((u) => Math.hypot(u.p[0] - q[0], u.p[1] - q[1]) >= 1);
      const far = (q) => Math.hypot(q[0] - p[0], q[1] - p[1]);
      // Points every 0.5 m along the centre line (its vertices alone are tens of metres apart here,
      // and whether the few near the UAV are free depends on where the fleet happened to stop).
      const line = app.geometry.centerline;
      const along = line.flatMap((a, i) => {
        const b = line[i + 1];
        if (!b) return [a];
        const steps = Math.max(1, Math.ceil(Math.hypot(b[0] - a[0], b[1] - a[1]) / 0.5));
        return Array.from({ length: steps }, (_, k) => [a[0] + (b[0] - a[0]) * k / steps, a[1] + (b[1] - a[1]) * k / steps]);
      });
      const candidates = along.filter((q) => far(q) >= 2 && far(q) <= 20 && seen(q) && free(q));
      const near20 = along.filter((q) => far(q) <= 20);
      return candidates.sort((a, b) => far(a) - far(b))[0] || JSON.stringify({ n: near20.length, seen: near20.filter(seen).length, free: near20.filter(free).length, scale: app.camera.scale, w: app.canvas.clientWidth, h: app.canvas.clientHeight, p });
    }, [p]);
    assert.ok(Array.isArray(goal), `a free point on the centre line near the UAV: ${goal}`);
    await clickWorld(page, goal[0], goal[1]);
    const set = await until(`the goal of ${id} to be set (GET /api/uavs/${id})`, async () => {
      const u = await api(url, "GET", `/api/uavs/${id}`);
      return u.goal && near(u.goal, goal, 0.1) && u;
    });
    assert.ok(!set.arrived);
    await api(url, "POST", "/api/fleet/resume");
    const arrived = await until(`${id} to arrive (GET /api/uavs/${id})`, async () => {
      const u = await api(url, "GET", `/api/uavs/${id}`);
      return u.arrived && u;
    }, 180000, 500);
    // Arrived UAVs step D_c aside for neighbours that pass (docs/traffic.md).
    assert.ok(near(arrived.p, set.goal, 0.1 + 0.3), `${id} at ${arrived.p}, goal ${set.goal}`);
    await screenshot(page, "ten-thousand-arrived");

    // The road editor at that size: drag a joint vertex of the UAV's segment 0.5 m outwards (the road
    // widens, safe for every UAV) and apply; the server checks the new road against all 10,000.
    await page.click("#mode-edit");
    await page.waitForFunction((n) => window.__airroads.editor.segments.length === n, scenario.segments.length);
    // The joint vertex nearest the middle of the view.
    const [from, to] = await page.evaluate(() => {
      const { app, editor } = window.__airroads;
      const { cx, cy } = app.camera;
      const joints = editor.segments.slice(0, -1).map(([p1, , p3]) => [p1, p3]);
      const [p1, p3] = joints.reduce((a, b) => (Math.hypot(b[0][0] - cx, b[0][1] - cy) < Math.hypot(a[0][0] - cx, a[0][1] - cy) ? b : a));
      const out = [p1[0] - p3[0], p1[1] - p3[1]];
      const n = Math.hypot(...out);
      return [p1, [p1[0] + (0.5 * out[0]) / n, p1[1] + (0.5 * out[1]) / n]];
    });
    const version = (await api(url, "GET", "/api/state")).road_version;
    const [sx, sy] = await pagePoint(page, from[0], from[1]);
    const [tx, ty] = await pagePoint(page, to[0], to[1]);
    const box = await page.locator("#view").boundingBox();
    assert.ok(sx > box.x && sy > box.y && sx < box.x + box.width && sy < box.y + box.height, "the vertex is in view");
    await page.mouse.move(sx, sy);
    await page.mouse.down();
    await page.mouse.move(tx, ty, { steps: 5 });
    await page.mouse.up();
    await page.click("#apply");
    await page.locator("#message", { hasText: "road applied" }).waitFor({ timeout: 60000 });
    const road = await api(url, "GET", "/api/road");
    assert.ok(road.segments.some((q) => near(q[0], to, 0.05)), `the moved vertex ${to} is in the applied road`);
    const count = await until("the new road version in the page", () =>
      page.evaluate((v) => { const s = window.__airroads.snapshot; return s.road_version > v && s.uavs.length; }, version));
    assert.equal(count, 10000);
    await screenshot(page, "ten-thousand-road-applied");
  });
});

test("UAVs held by a traffic rule show as waiting: legend, reservation band and the reason in the details", async () => {
  await withDashboard("waiting", ["--scenario", NARROW], async (page, { url }) => {
    // Eight UAVs from each side meet at a 0.9 m section: one side waits for its turn.
    const held = await until(
      "a UAV to wait for the single-file section (GET /api/state)",
      async () => {
        const s = await api(url, "GET", "/api/state");
        const open = s.reservations.length === 1 && s.reservations[0].open_from !== null;
        const queue = s.uavs.filter((u) => u.status === "waiting" && u.wait_reason === "single_file");
        return open && queue.length >= 2 && queue;
      },
      60000,
      100,
    );
    await page.locator('#legend [data-status="waiting"]').waitFor();
    // The last in its queue waits longest: select it (the fleet holds while it is clicked), fly on,
    // and its details give the reason.
    const last = held.reduce((a, b) => (Math.abs(a.p[0]) > Math.abs(b.p[0]) ? a : b));
    await selectHovering(page, url, last.id);
    await api(url, "POST", "/api/fleet/resume");
    const reason = page.locator(`#details section[data-uav="${last.id}"] dd[data-field="reason"]`);
    await reason.waitFor({ timeout: 15000 });
    assert.match(await reason.textContent(), /^single_file: waits for its turn/);
    await screenshot(page, "waiting");
  });
});

test("a Crazyflie whose link fails shows the link's error in its details", async () => {
  await withDashboard("link-error", [], async (page, { url }) => {
    // No Crazyradio here: the radio link of a UAV added over REST cannot open, and says why.
    const line = (await page.evaluate(() => window.__airroads.geometry)).centerline;
    const spot = line[Math.floor(line.length * 0.9)];
    const body = { id: "cf9", position: spot, link: "radio://0/80/2M/E7E7E7E7E9" };
    await api(url, "POST", "/api/uavs", body);
    const cf9 = await until("cf9's link error (GET /api/uavs/cf9)", async () => {
      const u = await api(url, "GET", "/api/uavs/cf9");
      return typeof u.link_error === "string" && u;
    });
    await selectHovering(page, url, "cf9");
    const shown = page.locator('#details section[data-uav="cf9"] dd[data-field="link error"]');
    await shown.waitFor({ timeout: 15000 });
    assert.equal(await shown.textContent(), cf9.link_error);
    const metrics = await api(url, "GET", "/api/metrics");
    assert.equal(metrics.links.with_error, 1);
    assert.equal(metrics.links.errors[0].id, "cf9");
    await screenshot(page, "link-error");
  });
});

test("with Rerun logging a batched fleet, the dashboard's selection becomes Rerun's", async () => {
  const rrd = join(ARTIFACTS, "selection.rrd");
  await withDashboard("rerun-selection", ["--rerun", `save=${rrd}`, "--rerun-batch-above", "2"], async (page, { url }) => {
    await until("the Rerun sink to report (GET /api/metrics)", async () => {
      const m = await api(url, "GET", "/api/metrics");
      return m.rerun.active && m.rerun.batched;
    });
    await selectHovering(page, url, "uav2");
    const sent = await until("uav2 in Rerun's selection (GET /api/rerun/selection)", async () => {
      const s = await api(url, "GET", "/api/rerun/selection");
      return s.ids.length === 1 && s.ids[0] === "uav2" && s;
    });
    assert.deepEqual(sent.ids, ["uav2"]);
    await page.keyboard.press("Escape");
    await until("an empty selection sent to Rerun", async () => (await api(url, "GET", "/api/rerun/selection")).ids.length === 0);
  });
});

test("a road network is drawn cell by cell; a click on a junction adds a UAV there", async () => {
  await withDashboard("network", ["--scenario", DEPOT], async (page, { url }) => {
    // Held, so that no UAV flies into the junction before the click.
    await api(url, "POST", "/api/fleet/pause");
    const geometry = await until("the network's geometry in the page", async () => {
      const g = await page.evaluate(() => window.__airroads.geometry);
      return g && Array.isArray(g.cells) && g.cells.length === 31 && g;
    });
    const fork = geometry.cells.find((c) => c.kind === "junction" && c.name === "fork");
    const centre = [fork.polygon.reduce((a, p) => a + p[0], 0) / 4, fork.polygon.reduce((a, p) => a + p[1], 0) / 4];
    // The junction is painted: its centre is not the page's background.
    const [px, py] = await pagePoint(page, centre[0], centre[1]);
    const painted = await page.evaluate(([x, y]) => {
      const canvas = document.getElementById("view");
      const rect = canvas.getBoundingClientRect();
      const dpr = window.devicePixelRatio || 1;
      const d = canvas.getContext("2d").getImageData((x - rect.left) * dpr, (y - rect.top) * dpr, 1, 1).data;
      return [d[0], d[1], d[2], d[3]];
    }, [px, py]);
    assert.ok(painted[3] > 0, `nothing drawn at the fork's centre: ${painted}`);
    await screenshot(page, "network");
    await page.click("#mode-add");
    await clickWorld(page, centre[0], centre[1]);
    const added = await until("a seventeenth UAV (GET /api/uavs)", async () => {
      const uavs = await api(url, "GET", "/api/uavs");
      return uavs.length === 17 && uavs[16];
    });
    assert.ok(near(added.p, centre, 0.3), `added at ${added.p}, clicked ${centre}`);
    // The editor takes the live network as it is: every road and junction.
    await page.click("#mode-edit");
    const layout = await page.evaluate(() => window.__airroads.editor.layout);
    assert.equal(layout.roads.length, geometry.layout.roads.length);
    assert.deepEqual(layout.junctions, geometry.layout.junctions);
    assert.deepEqual(layout.roads.map((r) => r.segments), geometry.layout.roads.map((r) => r.segments));
  });
});

test("add a UAV by clicking, give it a policy, remove it", async () => {
  await withDashboard("add", [], async (page, { url }) => {
    await page.click("#mode-add");
    const geometry = await page.evaluate(() => window.__airroads.geometry);
    const line = geometry.centerline;
    const spot = line[Math.floor(line.length * 0.8)];
    await clickWorld(page, spot[0], spot[1]);
    const added = await until("a seventh UAV (GET /api/uavs)", async () => {
      const uavs = await api(url, "GET", "/api/uavs");
      return uavs.length === 7 && uavs[6];
    });
    assert.ok(near(added.p, spot, 0.2));
    await until(`the new UAV ${added.id} to be selected`, async () =>
      (await page.evaluate(() => window.__airroads.selection)).join() === added.id);
    const policies = await api(url, "GET", "/api/policies");
    const other = policies.policies.find((p) => p !== added.policy);
    if (other) {
      await page.selectOption("#policy", other);
      await page.click("#set-policy");
      await until(`the policy ${other}`, async () => (await api(url, "GET", `/api/uavs/${added.id}`)).policy === other);
    }
    await page.click("#remove");
    await until("the UAV to be removed", async () => (await api(url, "GET", "/api/uavs")).length === 6);
  });
});

/** Loads the straight one-UAV scenario through the file input and enters the road editor. */
async function straightRoadInEditor(page, url) {
  await page.setInputFiles("#scenario-file", STRAIGHT);
  await until("the scenario to load", async () => (await api(url, "GET", "/api/uavs")).length === 1);
  await page.waitForFunction(() => window.__airroads.geometry.layout.segments.length === 1);
  await page.click("#fit");
  await page.click("#mode-edit");
  await page.click("#new-road");
}

/** Clicks the points of a road: the first two make the entry edge, then two per segment. */
async function drawPoints(page, points) {
  for (const [x, y] of points) await clickWorld(page, x, y);
}

test("draw a road, drag a vertex, undo/redo, apply it", async () => {
  await withDashboard("road", [], async (page, { url }) => {
    await straightRoadInEditor(page, url);
    await drawPoints(page, [[0, -4], [0, 4], [10, -4], [10, 4], [16, -2], [13, 5]]);
    let editor = await page.evaluate(() => window.__airroads.editor);
    assert.equal(editor.segments.length, 2);
    const tol = await page.evaluate(() => 1.5 / window.__airroads.app.camera.scale);
    assert.ok(near(editor.segments[1][0], [16, -2], tol) && near(editor.segments[1][2], [13, 5], tol));

    // Drag the far left vertex to (14, 4.5), undo, redo.
    const [sx, sy] = await page.evaluate(() => window.__airroads.pagePoint(13, 5));
    const [tx, ty] = await page.evaluate(() => window.__airroads.pagePoint(14, 4.5));
    await page.click("#draw"); // leave drawing: drags move vertices
    await page.mouse.move(sx, sy);
    await page.mouse.down();
    await page.mouse.move(tx, ty, { steps: 5 });
    await page.mouse.up();
    editor = await page.evaluate(() => window.__airroads.editor);
    assert.ok(near(editor.segments[1][2], [14, 4.5], tol), `dragged to ${editor.segments[1][2]}`);
    await page.keyboard.press("Control+z");
    editor = await page.evaluate(() => window.__airroads.editor);
    assert.ok(near(editor.segments[1][2], [13, 5], tol), "undo restores the vertex");
    await page.keyboard.press("Control+Shift+z");
    editor = await page.evaluate(() => window.__airroads.editor);
    assert.ok(near(editor.segments[1][2], [14, 4.5], tol), "redo moves it again");

    await page.click("#apply");
    await page.locator("#message", { hasText: "road applied" }).waitFor();
    const road = await api(url, "GET", "/api/road");
    assert.deepEqual(road.segments, editor.segments, "the server has the drawn road");
    assert.deepEqual(road.segments[0][0], road.segments[1][1], "joins are seamless");
    assert.deepEqual(road.segments[0][2], road.segments[1][3], "joins are seamless");
    await page.waitForFunction(() => window.__airroads.geometry.layout.segments.length === 2);
    await screenshot(page, "road-applied");
  });
});

test("an invalid road is refused and the offending segment is shown", async () => {
  await withDashboard("invalid-road", [], async (page, { url }) => {
    await straightRoadInEditor(page, url);
    const before = await api(url, "GET", "/api/road");
    // Segment 1 is not convex: its far edge folds in towards the entry edge.
    await drawPoints(page, [[0, -4], [0, 4], [8, -4], [8, 4], [16, -4], [9, 0.5]]);
    await page.click("#apply");
    const message = page.locator("#message.error");
    await message.waitFor();
    const text = await message.textContent();
    assert.match(text, /422 invalid_road/);
    assert.match(text, /segment 1: .*not strictly convex/);
    const editor = await page.evaluate(() => window.__airroads.editor);
    assert.equal(editor.error.segment, 1, "segment 1 is highlighted");
    assert.deepEqual(await api(url, "GET", "/api/road"), before, "the server's road is unchanged");
    await screenshot(page, "road-invalid");
  });
});

test("build a road network: a junction, roads from its sides, a broken one shown, apply, and a UAV flies through the junction", async () => {
  await withDashboard("network", [], async (page, { url }) => {
    await straightRoadInEditor(page, url);
    // A 3 m junction at (10, 0), then a road from its east, west and north sides, drawn two points
    // per edge from the side clicked.
    await page.click("#add-junction");
    await clickWorld(page, 10, 0);
    const roads = [
      [[11.5, 0.2], [[19, -1.5], [19, 1.5]]],
      [[8.5, -0.2], [[1, -1.5], [1, 1.5]]],
      [[10.2, 1.5], [[8.5, 4.5], [11.5, 4.5]]],
    ];
    for (const [side, points] of roads) {
      await page.click("#branch-road");
      await clickWorld(page, ...side);
      await drawPoints(page, points);
    }
    let editor = await page.evaluate(() => window.__airroads.editor);
    assert.equal(editor.layout.junctions.length, 1);
    assert.equal(editor.layout.roads.length, 3, JSON.stringify(editor.layout));
    // Each road starts exactly on its junction's side.
    const square = editor.layout.junctions[0].polygon;
    for (const road of editor.layout.roads) {
      const [, p2, , p4] = road.segments[0];
      assert.ok(square.some((v) => near(v, p2, 1e-9)) && square.some((v) => near(v, p4, 1e-9)), JSON.stringify(road));
    }
    await screenshot(page, "network-drawn");

    // A fourth road from the south side whose segment folds in towards the junction (not convex):
    // refused, and that road shown.
    const before = await api(url, "GET", "/api/road");
    await page.click("#branch-road");
    await clickWorld(page, 9.8, -1.5);
    await drawPoints(page, [[8.5, -4.5], [10.5, -1.9]]);
    await page.click("#apply");
    const message = page.locator("#message.error");
    await message.waitFor();
    assert.match(await message.textContent(), /422 invalid_road.*roads\[3\]/);
    editor = await page.evaluate(() => window.__airroads.editor);
    assert.equal(editor.error.road, editor.active, "the broken road is the one highlighted");
    assert.deepEqual(await api(url, "GET", "/api/road"), before, "the server's road is unchanged");
    await screenshot(page, "network-invalid");
    await page.keyboard.press("Control+z");
    await page.keyboard.press("Control+z");

    await page.click("#apply");
    await page.locator("#message", { hasText: "road applied" }).waitFor();
    const road = await api(url, "GET", "/api/road");
    assert.equal(road.roads.length, 3, JSON.stringify(road));
    assert.equal(road.junctions.length, 1);

    // A UAV on the east road sent to the north one turns through the junction.
    await api(url, "POST", "/api/uavs", { id: "flyer", position: [17, 0.75], goal: [10.6, 3.5] }, [201]);
    await page.click("#mode-select");
    const arrived = await until(
      "flyer to arrive through the junction (GET /api/state)",
      async () => {
        const u = (await api(url, "GET", "/api/state")).uavs.find((u) => u.id === "flyer");
        return u && u.arrived && u;
      },
      120000,
      250,
    );
    assert.ok(near(arrived.p, [10.6, 3.5], 0.15), `flyer at ${arrived.p}`);
    const metrics = await api(url, "GET", "/api/metrics");
    assert.ok(metrics.min_collision_margin_m === null || metrics.min_collision_margin_m >= 0.3 - 1e-6);
    await screenshot(page, "network-flown");
  });
});

test("the access token is asked for once and sent with changes", async () => {
  await withDashboard("token", ["--token", "s3cret-t0ken-for-tests"], async (page, { url }) => {
    await page.click("#pause");
    await page.locator("#token-dialog").waitFor({ state: "visible" });
    await page.fill("#token-input", "s3cret-t0ken-for-tests");
    await page.click("#token-dialog button[value=ok]");
    await until("the fleet to hold", async () => (await api(url, "GET", "/api/state")).paused);
    await until("the button to offer Resume", async () => (await page.textContent("#pause")) === "Resume");
    await page.click("#pause");
    await until("the fleet to fly again", async () => !(await api(url, "GET", "/api/state")).paused);
    assert.equal(await page.locator("#token-dialog").isVisible(), false, "asked only once");
    assert.equal(await page.evaluate(() => sessionStorage.getItem("airroads.token")), "s3cret-t0ken-for-tests");
  });
});

test("insert and delete segments, export the layout and import it again", async () => {
  await withDashboard("segments", [], async (page, { url }) => {
    await page.setInputFiles("#scenario-file", STRAIGHT);
    await until("the scenario to load", async () => (await api(url, "GET", "/api/uavs")).length === 1);
    await page.waitForFunction(() => window.__airroads.geometry.layout.segments.length === 1);
    await page.click("#fit");
    await page.click("#mode-edit");
    await page.waitForFunction(() => window.__airroads.editor.segments.length === 1);
    const editorSegments = async () => (await page.evaluate(() => window.__airroads.editor)).segments;

    // Select the straight segment by clicking inside it and split it in two at x = 10.
    await clickWorld(page, 5, 2);
    await page.click("#insert");
    let segments = await editorSegments();
    assert.equal(segments.length, 2, "insert splits the segment");
    assert.deepEqual([segments[0][0], segments[0][2]], [[10, -5], [10, 5]], "split at the middle of the walls");
    assert.deepEqual([segments[1][1], segments[1][3]], [[10, -5], [10, 5]], "the join is seamless");

    // Export: the browser downloads the layout JSON.
    const [download] = await Promise.all([page.waitForEvent("download"), page.click("#export")]);
    const exported = join(ARTIFACTS, "road-export.json");
    await download.saveAs(exported);
    const layout = JSON.parse(readFileSync(exported, "utf8"));
    assert.deepEqual(layout.segments, segments, "the export is the editor's layout");

    // Delete the far segment, then import the export: both segments are back.
    await clickWorld(page, 15, 2);
    await page.click("#delete-seg");
    segments = await editorSegments();
    assert.equal(segments.length, 1, "delete removes the selected segment");
    assert.deepEqual([segments[0][0], segments[0][2]], [[10, -5], [10, 5]], "the road now ends at x = 10");
    await page.setInputFiles("#import-file", exported);
    await page.locator("#message", { hasText: "imported 2 segments" }).waitFor();
    assert.deepEqual(await editorSegments(), layout.segments, "import restores the exported layout");

    await page.click("#apply");
    await page.locator("#message", { hasText: "road applied" }).waitFor();
    assert.deepEqual((await api(url, "GET", "/api/road")).segments, layout.segments, "the server has the imported road");
    await screenshot(page, "segments-imported");
  });
});

test("land a selected UAV, then the emergency stop cuts every UAV", async () => {
  await withDashboard("land", [], async (page, { url }) => {
    await selectHovering(page, url, "uav2");
    await page.click("#land");
    await until("uav2 to land (GET /api/uavs/uav2)", async () => {
      const u = await api(url, "GET", "/api/uavs/uav2");
      return u.phase === "landed" && u.status === "landed";
    });
    const others = (await api(url, "GET", "/api/state")).uavs.filter((u) => u.id !== "uav2");
    assert.ok(others.every((u) => u.phase === "flying"), "only the selected UAV lands");
    await page.locator('#legend [data-status="landed"]', { hasText: "landed 1" }).waitFor();

    page.once("dialog", (d) => d.accept());
    await page.click("#estop");
    await until("every UAV to be stopped", async () =>
      (await api(url, "GET", "/api/state")).uavs.every((u) => u.phase === "stopped" || u.id === "uav2"));
    await page.locator('#legend [data-status="stopped"]').waitFor();
    await screenshot(page, "stopped");
  });
});

test("a page on another origin cannot command the fleet or open the stream", async () => {
  const server = await startServer([]);
  // The attacker's page, served from another origin (another port of the same machine).
  const target = server.url;
  const evil = `<!doctype html><body>
<iframe name="sink"></iframe>
<form id="form" method="POST" action="${target}/api/fleet/stop" enctype="text/plain" target="sink"><input name="x" value="y"></form>
<script>
  window.results = {};
  for (const path of ["/api/fleet/stop", "/api/fleet/pause", "/api/fleet/land"]) {
    fetch("${target}" + path, { method: "POST", mode: "no-cors", headers: { "Content-Type": "text/plain" }, body: "{}" })
      .then(() => (window.results[path] = "sent"), (e) => (window.results[path] = String(e)));
  }
  fetch("${target}/api/uavs/uav1/goal", { method: "PUT", headers: { "Content-Type": "application/json" }, body: '{"goal": [1, 1]}' })
    .then((r) => (window.results.put = r.status), (e) => (window.results.put = "blocked"));
  const ws = new WebSocket("${target.replace("http", "ws")}/ws");
  ws.onopen = () => (window.results.ws = "open");
  ws.onerror = () => (window.results.ws = "refused");
  setTimeout(() => document.getElementById("form").submit(), 500);
</script></body>`;
  const site = createServer((req, res) => {
    res.writeHead(200, { "Content-Type": "text/html" });
    res.end(evil);
  });
  await new Promise((resolve) => site.listen(0, "127.0.0.1", resolve));
  const page = await browser.newPage();
  try {
    const before = await api(server.url, "GET", "/api/state");
    await page.goto(`http://127.0.0.1:${site.address().port}/`);
    await until("the page's requests to settle", async () =>
      page.evaluate(() => window.results && window.results.ws && window.results.put !== undefined).catch(() => false));
    const results = await page.evaluate(() => window.results).catch(() => ({}));
    assert.equal(results.ws, "refused", "the foreign page's WebSocket is refused");
    assert.equal(results.put, "blocked", "a JSON change needs a preflight the server never grants");
    // Give the form post time to land, then check that nothing changed.
    await new Promise((r) => setTimeout(r, 1500));
    const after = await api(server.url, "GET", "/api/state");
    assert.equal(after.paused, false, "not paused");
    assert.ok(after.uavs.every((u) => u.phase === "flying"), "nothing stopped or landing");
    const uav1 = after.uavs.find((u) => u.id === "uav1");
    assert.deepEqual(uav1.goal, before.uavs.find((u) => u.id === "uav1").goal, "goal unchanged");
    const audit = await api(server.url, "GET", "/api/audit?limit=100");
    const refused = audit.entries.filter((e) => e.outcome === "origin_not_allowed");
    assert.ok(refused.length >= 3, `the refused requests are in the audit log: ${JSON.stringify(audit.entries)}`);
  } finally {
    await page.close();
    site.close();
    await server.stop();
  }
});

test("the dashboard cannot be framed by another origin", async () => {
  const server = await startServer([]);
  const site = createServer((req, res) => {
    res.writeHead(200, { "Content-Type": "text/html" });
    res.end(`<!doctype html><iframe id="frame" src="${server.url}/"></iframe>`);
  });
  await new Promise((resolve) => site.listen(0, "127.0.0.1", resolve));
  const page = await browser.newPage();
  try {
    await page.goto(`http://127.0.0.1:${site.address().port}/`);
    await new Promise((r) => setTimeout(r, 1500));
    const frame = page.frames().find((f) => f !== page.mainFrame());
    const framed = frame ? await frame.evaluate(() => !!document.querySelector("canvas")).catch(() => false) : false;
    assert.equal(framed, false, "the dashboard did not render inside a foreign frame");
  } finally {
    await page.close();
    site.close();
    await server.stop();
  }
});

test("with regions, one region's dashboard shows every region's UAVs and the border, and commands them all", async () => {
  // Two regions over Zenoh on loopback; the dashboard is opened on the west's server only.
  const dir = mkdtempSync(join(tmpdir(), "airroads-regions-"));
  const scenario = join(dir, "regions.json");
  // A straight road x = 0..40, 6 m wide, in 8 segments: the west 0-3, the east 4-7.
  const n = 8;
  const segments = Array.from({ length: n }, (_, k) => [[5 * k + 5, -3], [5 * k, -3], [5 * k + 5, 3], [5 * k, 3]]);
  const half = Math.floor(n / 2);
  const centre = (k) => {
    const s = segments[k];
    return [(s[0][0] + s[1][0] + s[2][0] + s[3][0]) / 4, (s[0][1] + s[1][1] + s[2][1] + s[3][1]) / 4];
  };
  const [w, e] = [centre(0), centre(n - 1)];
  writeFileSync(scenario, JSON.stringify({
    name: "regions", segments,
    regions: [{ name: "west", segments: [0, half - 1] }, { name: "east", segments: [half, n - 1] }],
    uavs: [{ id: "w1", start: w, goal: w }, { id: "e1", start: e, goal: e }],
  }));
  const port = await new Promise((resolve) => {
    const probe = createNetServer().listen(0, "127.0.0.1", () => {
      const { port } = probe.address();
      probe.close(() => resolve(port));
    });
  });
  // The region network as deployed: TLS with the deployment's certificates (`airroads certs`).
  const certs = join(dir, "certs");
  execFileSync(BIN, ["certs", "--out", certs, "--road", scenario, "--roles", "primary"]);
  const tls = (name) => ["--zenoh-ca", join(certs, "ca.pem"), "--zenoh-cert", join(certs, `${name}.primary.pem`),
    "--zenoh-key", join(certs, `${name}.primary.key`)];
  const endpoint = `tls/127.0.0.1:${port}`;
  const west = await startServer(["--scenario", scenario, "--region", "west", "--zenoh-listen", endpoint, ...tls("west")]);
  const east = await startServer(["--scenario", scenario, "--region", "east", "--zenoh-connect", endpoint, ...tls("east")]);
  const page = await openDashboard(browser, west.url);
  try {
    const s = await until("the east's UAV on the west's dashboard", async () => {
      const s = await snapshot(page);
      return s.uavs.some((u) => u.id === "e1" && u.region === "east") && s;
    });
    assert.deepEqual(s.uavs.map((u) => u.id).sort(), ["e1", "w1"]);
    assert.deepEqual(s.regions.map((r) => r.name), ["east"]);
    // The border between the regions is drawn across the road (dashed, in the regions' colour).
    const border = segments[half - 1];
    const [a, b] = [await pagePoint(page, ...border[0]), await pagePoint(page, ...border[2])];
    const drawn = await page.evaluate(([a, b]) => {
      const canvas = document.getElementById("view");
      const r = canvas.getBoundingClientRect();
      const ctx = canvas.getContext("2d");
      const k = canvas.width / r.width;
      let hits = 0;
      for (let t = 0.05; t <= 0.95; t += 0.01) {
        const x = (a[0] + (b[0] - a[0]) * t - r.left) * k, y = (a[1] + (b[1] - a[1]) * t - r.top) * k;
        const [red, green, blue] = ctx.getImageData(Math.round(x), Math.round(y), 1, 1).data;
        if (red > 150 && green < 110 && blue < 60) hits++;
      }
      return hits;
    }, [a, b]);
    assert.ok(drawn >= 10, `the border is drawn (${drawn} orange samples along it)`);
    await screenshot(page, "regions");
    // Select the east's UAV by clicking it and send it to a goal: the east applies it.
    await api(west.url, "POST", "/api/fleet/pause");
    const e1 = (await snapshot(page)).uavs.find((u) => u.id === "e1");
    await clickWorld(page, e1.p[0], e1.p[1]);
    assert.deepEqual(await page.evaluate(() => window.__airroads.selection), ["e1"]);
    const goal = centre(n - 2);
    await clickWorld(page, goal[0], goal[1]);
    const set = await until("the east to have e1's new goal", async () => {
      const u = await api(east.url, "GET", "/api/uavs/e1?scope=region");
      return u.goal && near(u.goal, goal, 0.1) && u;
    });
    assert.ok(set.goal);
    assert.deepEqual(page.jsErrors, [], "no JavaScript errors in the page");
  } catch (err) {
    await screenshot(page, "regions-failed").catch(() => {});
    throw err;
  } finally {
    await page.close();
    await east.stop();
    await west.stop();
  }
});
