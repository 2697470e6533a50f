// Pointer and keyboard input on the canvas: pan (drag), zoom (wheel), selection (click, shift-click,
// shift-drag box), goals and new UAVs (click), and the road editor (vertex drag, draw, undo/redo).

import { segmentAt } from "./geometry.js";
import { addUav, removeSelected, sendGoals } from "./controls.js";

const DRAG_PX = 4;
const HIT_PX = 10;

/** The UAV drawn nearest to screen point (sx, sy), within the hit radius, or null. */
function uavAt(app, sx, sy) {
  const snap = app.snapshot;
  if (!snap) return null;
  const r = Math.max(HIT_PX, (snap.d_c / 2) * app.camera.scale);
  let best = null, bestD = r * r;
  for (const u of snap.uavs) {
    const [x, y] = app.camera.toScreen(u.p[0], u.p[1]);
    const d = (x - sx) ** 2 + (y - sy) ** 2;
    if (d <= bestD) {
      bestD = d;
      best = u.id;
    }
  }
  return best;
}

function local(app, ev) {
  const r = app.canvas.getBoundingClientRect();
  return [ev.clientX - r.left, ev.clientY - r.top];
}

function click(app, sx, sy, shift) {
  const p = app.camera.toWorld(sx, sy);
  if (app.mode === "add") return addUav(app, p);
  if (app.mode === "edit") {
    const editor = app.editor;
    const tol = HIT_PX / app.camera.scale;
    if (app.editTool === "junction") {
      editor.addJunction(p);
      app.setEditTool(null);
    } else if (app.editTool === "branch") {
      // A road starts at the junction side or road end clicked.
      if (editor.startRoad(p, tol)) {
        app.setEditTool(null);
        app.setDrawing(true);
      }
    } else if (app.drawing) {
      // Between two edges, a click on a junction's side or another road's end attaches this road's
      // end to it.
      if (editor.pending || !editor.edges.length || !editor.attachEnd(p, tol)) editor.addPoint(p);
    } else if (editor.activateAt(p, segmentAt) < 0) {
      editor.selected = -1;
    }
    editor.version++;
    return;
  }
  const id = uavAt(app, sx, sy);
  if (id !== null) {
    if (!shift) app.selection.clear();
    if (shift && app.selection.has(id)) app.selection.delete(id);
    else app.selection.add(id);
  } else if (app.selection.size && app.onRoad(p)) {
    sendGoals(app, p);
  } else if (!shift) {
    app.selection.clear();
  }
}

function selectBox(app, [x0, y0, x1, y1]) {
  if (!app.snapshot) return;
  for (const u of app.snapshot.uavs) {
    const [x, y] = app.camera.toScreen(u.p[0], u.p[1]);
    if (x >= x0 && x <= x1 && y >= y0 && y <= y1) app.selection.add(u.id);
  }
}

export function attachInput(app) {
  const canvas = app.canvas;
  let down = null; // {x, y, shift, dragging, kind, vertex}

  canvas.addEventListener("pointerdown", (ev) => {
    if (ev.button !== 0 && ev.button !== 1) return;
    canvas.setPointerCapture(ev.pointerId);
    const [x, y] = local(app, ev);
    let vertex = null;
    if (app.mode === "edit" && ev.button === 0) {
      vertex = app.editor.vertexAt(app.camera.toWorld(x, y), HIT_PX / app.camera.scale);
    }
    down = { x, y, lastX: x, lastY: y, shift: ev.shiftKey, button: ev.button, dragging: false, vertex };
  });

  canvas.addEventListener("pointermove", (ev) => {
    const [x, y] = local(app, ev);
    app.mouse = [x, y];
    if (app.mode === "edit" && app.editor.pending) app.dirty = true;
    if (!down) return;
    if (!down.dragging && Math.hypot(x - down.x, y - down.y) >= DRAG_PX) {
      down.dragging = true;
      if (down.vertex && !app.drawing) {
        down.kind = "vertex";
        app.editor.commit();
      } else if (down.shift && app.mode === "select" && down.button === 0) down.kind = "box";
      else down.kind = "pan";
    }
    if (!down.dragging) return;
    if (down.kind === "vertex") app.editor.moveVertex(down.vertex, app.camera.toWorld(x, y));
    else if (down.kind === "box") {
      app.box = [Math.min(down.x, x), Math.min(down.y, y), Math.max(down.x, x), Math.max(down.y, y)];
    } else app.camera.panBy(x - down.lastX, y - down.lastY);
    down.lastX = x;
    down.lastY = y;
    app.dirty = true;
  });

  const end = (ev) => {
    if (!down) return;
    const d = down;
    down = null;
    if (ev.type === "pointercancel") {
      app.box = null;
    } else if (!d.dragging && d.button === 0) {
      click(app, d.x, d.y, d.shift);
    } else if (d.kind === "box") {
      selectBox(app, app.box);
      app.box = null;
    }
    app.dirty = true;
  };
  canvas.addEventListener("pointerup", end);
  canvas.addEventListener("pointercancel", end);
  canvas.addEventListener("pointerleave", () => {
    app.mouse = null;
  });

  canvas.addEventListener(
    "wheel",
    (ev) => {
      ev.preventDefault();
      const [x, y] = local(app, ev);
      app.camera.zoomAt(x, y, Math.exp(-ev.deltaY * 0.0015));
      app.dirty = true;
    },
    { passive: false },
  );

  window.addEventListener("keydown", (ev) => {
    const tag = document.activeElement && document.activeElement.tagName;
    if (tag === "INPUT" || tag === "SELECT" || tag === "TEXTAREA") return;
    const mod = ev.ctrlKey || ev.metaKey;
    const key = ev.key.toLowerCase();
    if (app.mode === "edit" && mod && (key === "z" || key === "y")) {
      ev.preventDefault();
      if (key === "y" || ev.shiftKey) app.editor.redo();
      else app.editor.undo();
    } else if (ev.key === "Escape") {
      if (app.mode === "edit") app.setDrawing(false);
      else app.selection.clear();
    } else if (ev.key === "Delete" || ev.key === "Backspace") {
      if (app.mode === "edit") app.editor.remove(app.editor.selected);
      else removeSelected(app);
    } else return;
    app.dirty = true;
  });
}
