// Draws the road, the road editor's draft and the fleet on one canvas. Everything of one kind goes
// into one path (one stroke or fill per colour), so 1,000 UAVs cost a few thousand path segments.

import { centroid, quadPolygon } from "./geometry.js";

export const STATUS_COLOURS = {
  flying: "#2e9d4f",
  arrived: "#2f6fd6",
  braking: "#e08a1e",
  failed: "#d63131",
  stale: "#8a8a8a",
  lost: "#b0179b",
  connecting: "#b9c2cc",
  taking_off: "#7fc8a0",
  landing: "#8fb3e8",
  landed: "#5b6570",
  stopped: "#3b0d0d",
  stopping: "#961e1e",
  waiting: "#e6c619",
};
/** Single-file sections: grey while free, green while admitting from their start, blue from their end. */
const RESERVATION_COLOURS = { free: "rgba(120,120,120,0.35)", start: "rgba(46,157,79,0.45)", end: "rgba(47,111,214,0.45)" };
const LABEL_LIMIT = 250; // more UAVs on screen than this: labels only for the selected ones
// More UAVs on screen than this: trails, velocity arrows, temporary targets and goals only for the
// selected ones (at 10,000 UAVs the trails alone were 400,000 path segments per redraw, and the
// software rasteriser took longer than a frame for the arrows).
const DETAIL_LIMIT = 2000;

function polygon(ctx, cam, pts) {
  pts.forEach((p, i) => {
    const [x, y] = cam.toScreen(p[0], p[1]);
    if (i === 0) ctx.moveTo(x, y);
    else ctx.lineTo(x, y);
  });
  ctx.closePath();
}

function line(ctx, cam, a, b) {
  const [x0, y0] = cam.toScreen(a[0], a[1]);
  const [x1, y1] = cam.toScreen(b[0], b[1]);
  ctx.moveTo(x0, y0);
  ctx.lineTo(x1, y1);
}

/** A road network: its cells (junctions a shade darker, with their names), their shared edges
 * dashed, and its walls. */
function drawNetwork(ctx, cam, geometry, dim) {
  const cells = geometry.cells;
  ctx.globalAlpha = dim ? 0.35 : 1;
  for (const [kind, colour] of [["segment", "#e9edf2"], ["junction", "#dde3ea"]]) {
    ctx.fillStyle = colour;
    ctx.beginPath();
    for (const c of cells) if (c.kind === kind) polygon(ctx, cam, c.polygon);
    ctx.fill();
  }
  ctx.setLineDash([6, 5]);
  ctx.strokeStyle = "#9aa7b5";
  ctx.lineWidth = 1;
  ctx.beginPath();
  for (const c of cells) polygon(ctx, cam, c.polygon);
  ctx.stroke();
  ctx.setLineDash([]);
  drawWalls(ctx, cam, geometry);
  ctx.font = "11px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  ctx.fillStyle = "#5b6570";
  for (const c of cells) {
    if (c.kind !== "junction") continue;
    const [x, y] = cam.toScreen(...centroid(c.polygon));
    ctx.fillText(c.name, x, y);
  }
  ctx.globalAlpha = 1;
}

/** The live road's walls, solid and thick. */
function drawWalls(ctx, cam, geometry) {
  ctx.strokeStyle = "#26303b";
  ctx.lineWidth = 3;
  ctx.beginPath();
  for (const [a, b] of geometry.walls) line(ctx, cam, a, b);
  ctx.stroke();
}

/** The live road: surface, passable joint edges, walls and centre line; or a network's cells. */
export function drawRoad(ctx, cam, geometry, dim) {
  if (!geometry) return;
  if (Array.isArray(geometry.cells) && geometry.cells.length) return drawNetwork(ctx, cam, geometry, dim);
  const segs = geometry.layout.segments;
  ctx.globalAlpha = dim ? 0.35 : 1;
  ctx.fillStyle = "#e9edf2";
  ctx.beginPath();
  for (const s of segs) polygon(ctx, cam, quadPolygon(s));
  ctx.fill();
  ctx.setLineDash([6, 5]);
  ctx.strokeStyle = "#9aa7b5";
  ctx.lineWidth = 1;
  ctx.beginPath();
  for (let i = 0; i + 1 < segs.length; i++) line(ctx, cam, segs[i][0], segs[i][2]);
  ctx.stroke();
  ctx.setLineDash([2, 6]);
  ctx.strokeStyle = "#6b8cc7";
  ctx.beginPath();
  geometry.centerline.forEach((p, i) => {
    const [x, y] = cam.toScreen(p[0], p[1]);
    if (i === 0) ctx.moveTo(x, y);
    else ctx.lineTo(x, y);
  });
  ctx.stroke();
  ctx.setLineDash([]);
  drawWalls(ctx, cam, geometry);
  drawRegions(ctx, cam, segs, geometry.layout.regions);
  ctx.globalAlpha = 1;
}

/** The borders between regions (`serve --region`): a dashed line across the road, and each name. */
function drawRegions(ctx, cam, segs, regions) {
  if (!regions || regions.length === 0) return;
  ctx.strokeStyle = "#c2410c";
  ctx.lineWidth = 2;
  ctx.setLineDash([10, 6]);
  ctx.beginPath();
  for (const r of regions) {
    const last = segs[r.segments[1]];
    if (last && r.segments[1] + 1 < segs.length) line(ctx, cam, last[0], last[2]);
  }
  ctx.stroke();
  ctx.setLineDash([]);
  ctx.font = "bold 12px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  ctx.fillStyle = "#c2410c";
  for (const r of regions) {
    const middle = segs[Math.floor((r.segments[0] + r.segments[1]) / 2)];
    if (!middle) continue;
    const [x, y] = centroid(quadPolygon(middle));
    const [sx, sy] = cam.toScreen(x, y);
    ctx.fillText(r.name, sx, sy);
  }
}

/** A network draft's junctions and its roads other than the active one, with their names and the
 * server's error on a junction or another road. */
function drawNetworkDraft(ctx, cam, editor) {
  const err = editor.error;
  ctx.font = "bold 12px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  editor.junctions.forEach((j, i) => {
    const bad = err && err.junction === i;
    ctx.beginPath();
    polygon(ctx, cam, j.polygon);
    ctx.fillStyle = bad ? "rgba(214,49,49,0.35)" : "rgba(120,90,200,0.18)";
    ctx.fill();
    ctx.strokeStyle = "#6b4fc0";
    ctx.lineWidth = 2;
    ctx.stroke();
    for (const v of j.polygon) {
      const [x, y] = cam.toScreen(v[0], v[1]);
      ctx.fillStyle = "#fff";
      ctx.fillRect(x - 3, y - 3, 6, 6);
      ctx.strokeRect(x - 3, y - 3, 6, 6);
    }
    const [cx, cy] = cam.toScreen(...centroid(j.polygon));
    ctx.fillStyle = bad ? "#a11" : "#4b3590";
    ctx.fillText(j.name, cx, cy);
    if (bad) drawCallout(ctx, cx, cy + 18, `${j.name}: ${err.message}`);
  });
  editor.allSegments().forEach(({ road, name, segments }) => {
    if (road === editor.active) return;
    const bad = err && err.road === road;
    segments.forEach((s, i) => {
      ctx.beginPath();
      polygon(ctx, cam, quadPolygon(s));
      ctx.fillStyle = bad && (err.segment === null || err.segment === i) ? "rgba(214,49,49,0.35)" : "rgba(255,196,0,0.10)";
      ctx.fill();
      ctx.strokeStyle = "#b86e00";
      ctx.lineWidth = 1;
      ctx.stroke();
    });
    const middle = segments[Math.floor(segments.length / 2)];
    if (!middle) return;
    const [cx, cy] = cam.toScreen(...centroid(quadPolygon(middle)));
    ctx.fillStyle = bad ? "#a11" : "#7a5a00";
    ctx.fillText(name, cx, cy);
    if (bad) drawCallout(ctx, cx, cy + 18, `${name}${err.segment !== null ? ` segment ${err.segment}` : ""}: ${err.message}`);
  });
}

/** The editor's draft road (the active one, of a network's) with handles, segment numbers and the
 * server's error; a network's junctions and other roads under it. */
export function drawEditor(ctx, cam, editor, mouse) {
  if (editor.isNetwork()) drawNetworkDraft(ctx, cam, editor);
  const segs = editor.segments();
  // The server's error on the active road (a chain's errors name no road).
  const err = editor.error && (editor.error.road === undefined || editor.error.road === editor.active) && editor.error.junction === undefined ? editor.error : null;
  segs.forEach((s, i) => {
    ctx.beginPath();
    polygon(ctx, cam, quadPolygon(s));
    ctx.fillStyle = err && err.segment === i ? "rgba(214,49,49,0.35)" : "rgba(255,196,0,0.18)";
    ctx.fill();
    if (i === editor.selected) {
      ctx.strokeStyle = "#7a3fd1";
      ctx.lineWidth = 2;
      ctx.setLineDash([4, 3]);
      ctx.stroke();
      ctx.setLineDash([]);
    }
  });
  const e = editor.edges;
  ctx.strokeStyle = "#b86e00";
  ctx.lineWidth = 2.5;
  ctx.beginPath();
  for (let i = 0; i + 1 < e.length; i++) {
    line(ctx, cam, e[i][0], e[i + 1][0]);
    line(ctx, cam, e[i][1], e[i + 1][1]);
  }
  ctx.stroke();
  ctx.strokeStyle = "#b86e00";
  ctx.lineWidth = 1;
  ctx.setLineDash([5, 4]);
  ctx.beginPath();
  for (const [a, b] of e) line(ctx, cam, a, b);
  ctx.stroke();
  ctx.setLineDash([]);
  ctx.fillStyle = "#fff";
  ctx.strokeStyle = "#b86e00";
  ctx.lineWidth = 1.5;
  for (const edge of e)
    for (const v of edge) {
      const [x, y] = cam.toScreen(v[0], v[1]);
      ctx.fillRect(x - 4, y - 4, 8, 8);
      ctx.strokeRect(x - 4, y - 4, 8, 8);
    }
  ctx.font = "bold 13px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  segs.forEach((s, i) => {
    const [cx, cy] = centroid(s);
    const [x, y] = cam.toScreen(cx, cy);
    ctx.fillStyle = err && err.segment === i ? "#a11" : "#7a5a00";
    ctx.fillText(String(i), x, y);
  });
  if (err && err.segment !== null && err.segment < segs.length) {
    const [cx, cy] = centroid(segs[err.segment]);
    const [x, y] = cam.toScreen(cx, cy);
    drawCallout(ctx, x, y + 18, `segment ${err.segment}: ${err.message}`);
  }
  if (editor.pending) {
    const [x, y] = cam.toScreen(editor.pending[0], editor.pending[1]);
    ctx.fillStyle = "#b86e00";
    ctx.beginPath();
    ctx.arc(x, y, 5, 0, 2 * Math.PI);
    ctx.fill();
    if (mouse) {
      ctx.strokeStyle = "#b86e00";
      ctx.setLineDash([3, 3]);
      ctx.beginPath();
      ctx.moveTo(x, y);
      ctx.lineTo(mouse[0], mouse[1]);
      ctx.stroke();
      ctx.setLineDash([]);
    }
  }
}

function drawCallout(ctx, x, y, text) {
  ctx.font = "12px system-ui, sans-serif";
  const w = Math.min(ctx.measureText(text).width, 520) + 12;
  ctx.fillStyle = "rgba(161,17,17,0.92)";
  ctx.fillRect(x - w / 2, y - 10, w, 20);
  ctx.fillStyle = "#fff";
  ctx.textAlign = "center";
  ctx.fillText(text, x, y, 520);
}

/** The single-file sections as wide bands along the centre line, coloured by the end they admit from. */
export function drawReservations(ctx, cam, snapshot) {
  if (!snapshot || !snapshot.reservations) return;
  ctx.lineWidth = Math.max(4, 0.3 * cam.scale);
  ctx.lineCap = "round";
  for (const z of snapshot.reservations) {
    ctx.strokeStyle = RESERVATION_COLOURS[z.open_from || "free"];
    ctx.beginPath();
    z.path.forEach((p, i) => {
      const [x, y] = cam.toScreen(p[0], p[1]);
      if (i === 0) ctx.moveTo(x, y);
      else ctx.lineTo(x, y);
    });
    ctx.stroke();
  }
  ctx.lineCap = "butt";
}

/** Every UAV: trail, target and goal, velocity arrow, body by status, selection ring and label. */
export function drawFleet(ctx, cam, snapshot, trails, selection) {
  if (!snapshot) return;
  const uavs = snapshot.uavs;
  const w = cam.width, h = cam.height, pad = 40;
  const visible = [];
  for (const u of uavs) {
    const [x, y] = cam.toScreen(u.p[0], u.p[1]);
    if (x > -pad && y > -pad && x < w + pad && y < h + pad) visible.push([u, x, y]);
  }
  const r = Math.max(3, (snapshot.d_c / 2) * cam.scale);
  const decorated = visible.length <= DETAIL_LIMIT ? visible : visible.filter(([u]) => selection.has(u.id));

  ctx.lineWidth = 1;
  ctx.strokeStyle = "rgba(90,100,120,0.35)";
  ctx.beginPath();
  const s = cam.scale, ox = w / 2 - cam.cx * s, oy = h / 2 + cam.cy * s;
  for (const [u] of decorated)
    trails.forEach(u.id, (tx, ty, first) => {
      if (first) ctx.moveTo(tx * s + ox, oy - ty * s);
      else ctx.lineTo(tx * s + ox, oy - ty * s);
    });
  ctx.stroke();

  // Temporary targets (dot, thin line from the UAV) and goals (cross).
  ctx.strokeStyle = "rgba(122,63,209,0.35)";
  ctx.beginPath();
  for (const [u, x, y] of decorated) {
    const [tx, ty] = cam.toScreen(u.target[0], u.target[1]);
    ctx.moveTo(x, y);
    ctx.lineTo(tx, ty);
  }
  ctx.stroke();
  ctx.fillStyle = "rgba(122,63,209,0.7)";
  ctx.beginPath();
  for (const [u] of decorated) {
    const [tx, ty] = cam.toScreen(u.target[0], u.target[1]);
    ctx.rect(tx - 1.5, ty - 1.5, 3, 3);
  }
  ctx.fill();
  ctx.strokeStyle = "#7a3fd1";
  ctx.lineWidth = 1.5;
  ctx.beginPath();
  for (const [u] of decorated) {
    if (!u.goal) continue;
    const [gx, gy] = cam.toScreen(u.goal[0], u.goal[1]);
    ctx.moveTo(gx - 4, gy - 4);
    ctx.lineTo(gx + 4, gy + 4);
    ctx.moveTo(gx - 4, gy + 4);
    ctx.lineTo(gx + 4, gy - 4);
  }
  ctx.stroke();

  // Velocity arrows: the distance flown in 0.5 s.
  ctx.strokeStyle = "#1d2733";
  ctx.lineWidth = 1.2;
  ctx.beginPath();
  for (const [u, x, y] of decorated) {
    const dx = u.v[0] * 0.5 * cam.scale, dy = -u.v[1] * 0.5 * cam.scale;
    const len = Math.hypot(dx, dy);
    if (len < 2) continue;
    const ex = x + dx, ey = y + dy, ux = dx / len, uy = dy / len, hsz = Math.min(5, len / 2);
    ctx.moveTo(x, y);
    ctx.lineTo(ex, ey);
    ctx.lineTo(ex - hsz * (ux - 0.5 * uy), ey - hsz * (uy + 0.5 * ux));
    ctx.moveTo(ex, ey);
    ctx.lineTo(ex - hsz * (ux + 0.5 * uy), ey - hsz * (uy - 0.5 * ux));
  }
  ctx.stroke();

  const small = r <= 3.5; // a few pixels: squares, much cheaper to fill than arcs
  const byStatus = new Map();
  for (const v of visible) {
    const list = byStatus.get(v[0].status);
    if (list) list.push(v);
    else byStatus.set(v[0].status, [v]);
  }
  for (const [status, colour] of Object.entries(STATUS_COLOURS)) {
    const list = byStatus.get(status);
    if (!list) continue;
    ctx.fillStyle = colour;
    ctx.beginPath();
    for (const [, x, y] of list) {
      if (small) ctx.rect(x - r, y - r, 2 * r, 2 * r);
      else {
        ctx.moveTo(x + r, y);
        ctx.arc(x, y, r, 0, 2 * Math.PI);
      }
    }
    ctx.fill();
  }

  // Another region's UAVs (`serve --region`): a grey ring around each.
  ctx.strokeStyle = "rgba(60,70,85,0.8)";
  ctx.lineWidth = 1.5;
  ctx.beginPath();
  for (const [u, x, y] of visible) {
    if (!u.region) continue;
    ctx.moveTo(x + r + 1.5, y);
    ctx.arc(x, y, r + 1.5, 0, 2 * Math.PI);
  }
  ctx.stroke();

  if (selection.size) {
    ctx.strokeStyle = "#7a3fd1";
    ctx.lineWidth = 2.5;
    ctx.beginPath();
    for (const [u, x, y] of visible) {
      if (!selection.has(u.id)) continue;
      ctx.moveTo(x + r + 4, y);
      ctx.arc(x, y, r + 4, 0, 2 * Math.PI);
    }
    ctx.stroke();
  }

  ctx.font = "11px system-ui, sans-serif";
  ctx.textAlign = "left";
  ctx.textBaseline = "bottom";
  ctx.fillStyle = "#1d2733";
  const all = visible.length <= LABEL_LIMIT;
  for (const [u, x, y] of visible) if (all || selection.has(u.id)) ctx.fillText(u.id, x + r + 2, y - r);
}

/** The rubber band of a box selection, in screen pixels. */
export function drawBox(ctx, box) {
  if (!box) return;
  const [x0, y0, x1, y1] = box;
  ctx.fillStyle = "rgba(122,63,209,0.08)";
  ctx.strokeStyle = "#7a3fd1";
  ctx.lineWidth = 1;
  ctx.fillRect(x0, y0, x1 - x0, y1 - y0);
  ctx.strokeRect(x0, y0, x1 - x0, y1 - y0);
}
