// The dashboard: wires the API client, the /ws stream, the canvas renderer, the road editor and the
// margin plot; draws on animation frames only when something changed.

import { Api } from "./api.js";
import { Stream } from "./stream.js";
import { Camera, bounds } from "./camera.js";
import { RoadEditor } from "./editor.js";
import { Trails } from "./trails.js";
import { MarginPlot } from "./plot.js";
import { STATUS_COLOURS, drawBox, drawEditor, drawFleet, drawReservations, drawRoad } from "./render.js";
import { showDetails } from "./details.js";
import { insideAny, roadPolygons } from "./geometry.js";
import { attachInput } from "./input.js";
import { bindControls, showMessage } from "./controls.js";

const $ = (id) => document.getElementById(id);

const HELP = {
  select: "Click a UAV to select it (shift: add/remove, shift-drag: box), then click the road to send it there. Drag to pan, wheel to zoom, Delete removes, Esc clears.",
  add: "Click the road to add a UAV with the chosen policy.",
  edit: "Drag a vertex (a joint moves both segments), click a segment to select it. Draw: click two points per edge; each new segment starts at the last exit edge. A network: Junction places one, Road from… starts a road at a junction's side or a road's end, and while drawing a click on a side attaches the road's end there. Ctrl-Z / Ctrl-Shift-Z undo/redo, Apply sends the road.",
};

export class App {
  constructor() {
    this.canvas = $("view");
    this.ctx = this.canvas.getContext("2d");
    this.camera = new Camera();
    this.editor = new RoadEditor();
    this.editorLoaded = false;
    this.trails = new Trails();
    this.plot = new MarginPlot($("plot"));
    this.selection = new Set();
    /** id → `GET /api/uavs/{id}` of the selected UAVs shown in the details (fields the stream lacks). */
    this.details = new Map();
    /** The selection last sent to Rerun (ids joined by newlines), and whether Rerun is logging. */
    this.rerunSent = "";
    this.rerunActive = false;
    this.mode = "select";
    this.drawing = false;
    this.editTool = null;
    this.snapshot = null;
    this.geometry = null;
    this.geometryFetch = null;
    this.fitted = false;
    this.box = null;
    this.mouse = null;
    this.dirty = true;
    this.tickSamples = [];
    this.perf = { frames: 0, draws: 0, drawMs: [] };
    this.api = new Api((again) => this.askToken(again));
    this.stream = new Stream((ok) => {
      $("conn").textContent = ok ? "live" : "disconnected";
      $("conn").className = ok ? "ok" : "bad";
    });
    new ResizeObserver(() => this.resize()).observe(this.canvas);
    this.resize();
    attachInput(this);
    bindControls(this);
    this.setMode("select");
    this.pollMetrics();
    setInterval(() => this.pollMetrics(), 1000);
    setInterval(() => this.refreshDetails(), 500);
    requestAnimationFrame((t) => this.frame(t));
  }

  resize() {
    const dpr = window.devicePixelRatio || 1;
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    this.canvas.width = Math.max(1, Math.round(w * dpr));
    this.canvas.height = Math.max(1, Math.round(h * dpr));
    this.camera.resize(w, h);
    this.dirty = true;
  }

  frame(now) {
    this.perf.frames++;
    const snap = this.stream.take();
    if (snap) this.onSnapshot(snap, now);
    if (this.dirty) {
      const t0 = performance.now();
      this.draw();
      const ms = performance.now() - t0;
      const d = this.perf.drawMs;
      d.push(ms);
      if (d.length > 2000) d.splice(0, d.length - 2000);
      this.perf.draws++;
      this.dirty = false;
    }
    requestAnimationFrame((t) => this.frame(t));
  }

  onSnapshot(snap, now) {
    this.snapshot = snap;
    this.trails.push(snap);
    this.plot.push(snap);
    if (!this.geometry || this.geometry.version !== snap.road_version) this.refreshGeometry();
    if (this.selection.size) {
      const ids = new Set(snap.uavs.map((u) => u.id));
      for (const id of this.selection) if (!ids.has(id)) this.selection.delete(id);
    }
    const s = this.tickSamples;
    s.push([now, snap.tick]);
    while (s.length > 2 && s[0][0] < now - 2000) s.shift();
    this.updateHeader(snap);
    showDetails($("details"), snap, this.selection, this.details);
    this.syncRerunSelection();
    this.dirty = true;
  }

  updateHeader(snap) {
    const s = this.tickSamples;
    const [t0, k0] = s[0], [t1, k1] = s[s.length - 1];
    const fmt = (v, d = 3) => (v === null || v === undefined ? "–" : v.toFixed(d));
    $("tick").textContent = snap.tick;
    $("rate").textContent = t1 > t0 ? (((k1 - k0) * 1000) / (t1 - t0)).toFixed(1) : "–";
    $("count").textContent = snap.uavs.length;
    $("mcoll").textContent = fmt(snap.min_collision_margin_m);
    $("mroad").textContent = fmt(snap.min_road_margin_m);
    $("dc").textContent = snap.d_c;
    $("ds").textContent = snap.d_s;
    $("paused-flag").hidden = !snap.paused;
    $("pause").textContent = snap.paused ? "Resume" : "Pause";
    this.updateLegend(snap);
  }

  /** The status colours in use, with how many UAVs have each (e.g. a lost Crazyflie stands out). */
  updateLegend(snap) {
    const counts = new Map();
    for (const u of snap.uavs) counts.set(u.status, (counts.get(u.status) || 0) + 1);
    const key = [...counts].map(([s, n]) => `${s}:${n}`).join(",");
    if (key === this.legendKey) return;
    this.legendKey = key;
    const legend = $("legend");
    legend.replaceChildren(
      ...Object.keys(STATUS_COLOURS)
        .filter((s) => counts.has(s))
        .map((s) => {
          const row = document.createElement("span");
          row.dataset.status = s;
          const dot = document.createElement("i");
          dot.style.background = STATUS_COLOURS[s];
          row.append(dot, `${s.replace("_", " ")} ${counts.get(s)}`);
          return row;
        }),
    );
  }

  /** Fetches what the stream does not carry for the UAVs in the details panel (at most 4). */
  async refreshDetails() {
    const ids = [...this.selection].slice(0, 4);
    for (const id of this.details.keys()) if (!this.selection.has(id)) this.details.delete(id);
    if (!ids.length || this.detailsFetching) return;
    this.detailsFetching = true;
    try {
      const answers = await Promise.all(ids.map((id) => this.api.uav(id).catch(() => null)));
      answers.forEach((u, k) => u && this.details.set(ids[k], u));
    } finally {
      this.detailsFetching = false;
    }
  }

  /**
   * With a Rerun sink running, sends the selection (its first 64) whenever it changed, so that the
   * selected UAVs keep their own entities when the fleet is logged as one batch. Sent once per
   * change, whatever the answer (a token refused is not asked for: this is view state).
   */
  syncRerunSelection() {
    if (!this.rerunActive || this.rerunSending) return;
    const ids = [...this.selection].slice(0, 64);
    const key = ids.join("\n");
    if (key === this.rerunSent) return;
    this.rerunSending = true;
    this.api
      .rerunSelection(ids)
      .catch(() => {})
      .finally(() => {
        this.rerunSent = key;
        this.rerunSending = false;
      });
  }

  async pollMetrics() {
    try {
      const m = await this.api.metrics();
      $("p50").textContent = (m.tick.p50_us / 1000).toFixed(2);
      $("p99").textContent = (m.tick.p99_us / 1000).toFixed(2);
      this.rerunActive = Boolean(m.rerun && m.rerun.active);
    } catch {
      // The connection state shows in the header already.
    }
  }

  /** Fetches the road geometry; one request at a time, again if the version moved meanwhile. */
  refreshGeometry() {
    if (this.geometryFetch) return this.geometryFetch;
    this.geometryFetch = this.api
      .geometry()
      .then((g) => {
        this.geometry = g;
        if (!this.fitted) this.fit();
        this.dirty = true;
      })
      .catch((e) => showMessage(`road geometry: ${e.message}`, true))
      .finally(() => {
        this.geometryFetch = null;
      });
    return this.geometryFetch;
  }

  fit() {
    const pts = [];
    for (const poly of roadPolygons(this.geometry)) pts.push(...poly);
    if (this.mode === "edit") {
      for (const r of this.editor.roads) for (const e of r.edges) pts.push(...e);
      for (const j of this.editor.junctions) pts.push(...j.polygon);
    }
    if (!pts.length) return;
    this.camera.fit(bounds(pts));
    this.fitted = true;
    this.dirty = true;
  }

  setMode(mode) {
    if (mode === "edit" && this.mode !== "edit" && !this.editorLoaded && this.geometry) {
      // The editor takes a chain or a network as the server has it.
      this.editor.load(this.geometry.layout, false);
      this.editorLoaded = true;
    }
    this.mode = mode;
    if (mode !== "edit") {
      this.setDrawing(false);
      this.setEditTool(null);
    }
    for (const b of document.querySelectorAll("[data-mode]")) b.setAttribute("aria-pressed", String(b.dataset.mode === mode));
    $("edit-toolbar").hidden = mode !== "edit";
    $("help").textContent = HELP[mode];
    this.box = null;
    this.dirty = true;
  }

  setDrawing(on) {
    this.drawing = on;
    if (!on) this.editor.cancelPending();
    $("draw").setAttribute("aria-pressed", String(on));
    this.dirty = true;
  }

  /** The editor's one-click tool: "junction" (place one), "branch" (start a road at a side) or null. */
  setEditTool(tool) {
    this.editTool = tool;
    $("add-junction").setAttribute("aria-pressed", String(tool === "junction"));
    $("branch-road").setAttribute("aria-pressed", String(tool === "branch"));
    if (tool) this.setDrawing(false);
    this.dirty = true;
  }

  /** True when world point p is on the live road. */
  onRoad(p) {
    return insideAny(roadPolygons(this.geometry), p);
  }

  draw() {
    const ctx = this.ctx;
    const dpr = window.devicePixelRatio || 1;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, this.camera.width, this.camera.height);
    const editing = this.mode === "edit";
    drawRoad(ctx, this.camera, this.geometry, editing);
    if (editing) drawEditor(ctx, this.camera, this.editor, this.mouse);
    drawReservations(ctx, this.camera, this.snapshot);
    drawFleet(ctx, this.camera, this.snapshot, this.trails, this.selection);
    drawBox(ctx, this.box);
    if (this.snapshot) this.plot.draw();
  }

  askToken(again) {
    const dialog = $("token-dialog");
    $("token-prompt").textContent = again
      ? "The token was refused. Enter the server's access token:"
      : "This server needs an access token for changes:";
    $("token-input").value = "";
    dialog.returnValue = "";
    $("token-cancel").onclick = () => dialog.close("cancel");
    dialog.showModal();
    return new Promise((resolve) => {
      dialog.addEventListener(
        "close",
        () => resolve(dialog.returnValue === "ok" ? $("token-input").value.trim() || null : null),
        { once: true },
      );
    });
  }
}

const app = new App();

// For the browser tests and the console: read-only views of the app's state.
window.__airroads = {
  app,
  get snapshot() { return app.snapshot; },
  get geometry() { return app.geometry; },
  get editor() {
    const e = app.editor;
    return { segments: e.segments(), error: e.error, selected: e.selected, pending: e.pending, active: e.active, layout: e.layout() };
  },
  get selection() { return [...app.selection]; },
  get mode() { return app.mode; },
  get perf() { return app.perf; },
  /** Page coordinates (CSS pixels) of world point (x, y). */
  pagePoint(x, y) {
    const r = app.canvas.getBoundingClientRect();
    const [sx, sy] = app.camera.toScreen(x, y);
    return [r.left + sx, r.top + sy];
  },
};
