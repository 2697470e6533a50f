// Toolbar actions and fleet changes through the REST API; results and API errors go to the
// message area.

const $ = (id) => document.getElementById(id);
let messageTimer = null;

/** Shows `text` in the message area; errors stay until the next message, notes for 6 s. */
export function showMessage(text, error = false) {
  const el = $("message");
  el.textContent = text;
  el.className = error ? "error" : "";
  el.hidden = false;
  clearTimeout(messageTimer);
  if (!error) messageTimer = setTimeout(() => (el.hidden = true), 6000);
}

const describe = (e) => `${e.message}${e.field ? ` (${e.field})` : ""}`;

/** Runs `calls` (promises), then reports how many succeeded and the first error. */
async function report(what, calls) {
  const results = await Promise.allSettled(calls);
  const failed = results.filter((r) => r.status === "rejected");
  if (failed.length) {
    const n = results.length > 1 ? ` (${failed.length} of ${results.length} failed)` : "";
    showMessage(`${what}: ${describe(failed[0].reason)}${n}`, true);
  } else showMessage(`${what}: done`);
  return failed.length === 0;
}

/** Goals for the selection around p: one UAV gets p, several get points of a grid centred on p. */
export function sendGoals(app, p) {
  const ids = [...app.selection];
  const step = Math.max(0.5, 2 * (app.snapshot ? app.snapshot.d_c : 0.3));
  const side = Math.ceil(Math.sqrt(ids.length));
  const calls = ids.map((id, k) => {
    const gx = p[0] + ((k % side) - (side - 1) / 2) * step;
    const gy = p[1] + (Math.floor(k / side) - (side - 1) / 2) * step;
    return app.api.setGoal(id, [gx, gy]);
  });
  return report(ids.length === 1 ? `goal of ${ids[0]}` : `goals of ${ids.length} UAVs`, calls);
}

export async function addUav(app, p) {
  const ids = new Set(app.snapshot ? app.snapshot.uavs.map((u) => u.id) : []);
  let n = ids.size + 1;
  while (ids.has(`uav${n}`)) n++;
  const id = `uav${n}`;
  if (await report(`add ${id}`, [app.api.addUav(id, p, $("policy").value || undefined)])) {
    app.selection.clear();
    app.selection.add(id);
  }
}

export function removeSelected(app) {
  const ids = [...app.selection];
  if (!ids.length) return showMessage("select UAVs to remove first", true);
  return report(`remove ${ids.length} UAV(s)`, ids.map((id) => app.api.removeUav(id)));
}

function setPolicy(app) {
  const ids = [...app.selection];
  const policy = $("policy").value;
  if (!ids.length) return showMessage("select UAVs first", true);
  return report(`policy ${policy}`, ids.map((id) => app.api.setPolicy(id, policy)));
}

async function loadPolicies(app) {
  try {
    const { policies, default: def } = await app.api.policies();
    $("policy").replaceChildren(...policies.map((p) => new Option(p, p, p === def, p === def)));
  } catch (e) {
    showMessage(`policies: ${describe(e)}`, true);
  }
}

async function readFile(input) {
  const file = input.files[0];
  input.value = "";
  return file ? { name: file.name, text: await file.text() } : null;
}

async function applyRoad(app) {
  app.setDrawing(false);
  const editor = app.editor;
  try {
    const layout = editor.layout();
    const res = await app.api.putRoad(layout);
    const cleared = res.cleared_goals && res.cleared_goals.length ? `; goals cleared: ${res.cleared_goals.join(", ")}` : "";
    const note = editor.regionsNote();
    showMessage(`road applied (version ${res.version})${cleared}${note ? `; ${note}` : ""}`);
    editor.applied(layout);
    await app.refreshGeometry();
  } catch (e) {
    const details = e.details || {};
    let segment = details.segment ?? null;
    const field = e.field || "";
    const m = /^segments\[(\d+)\]/.exec(field);
    if (segment === null && m) segment = Number(m[1]);
    editor.error = { segment, message: e.message, code: e.code, status: e.status };
    // A network's errors name a road of the layout (roads without a segment are left out of it) and
    // its segment, or a junction.
    const road = /^roads\[(\d+)\](?:\.segments\[(\d+)\])?/.exec(field);
    const junction = /^junctions\[(\d+)\]/.exec(field);
    if (road) {
      const drawn = editor.roads.map((r, i) => (r.edges.length >= 2 ? i : -1)).filter((i) => i >= 0);
      editor.error.road = drawn[Number(road[1])] ?? null;
      editor.error.segment = road[2] !== undefined ? Number(road[2]) : null;
    } else if (junction) {
      editor.error.junction = Number(junction[1]);
      editor.error.segment = null;
    }
    const where = /^(regions|roads|junctions)/.test(field) ? `${field}: ` : segment !== null ? `segment ${segment}: ` : "";
    const status = e.status ? `${e.status} ${e.code}` : "network error";
    showMessage(`road not applied (${status}): ${where}${e.message}`, true);
  }
  app.dirty = true;
}

function exportRoad(app) {
  const note = app.editor.regionsNote();
  if (note) showMessage(`road exported; ${note}`);
  const blob = new Blob([JSON.stringify(app.editor.layout(), null, 1)], { type: "application/json" });
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob);
  a.download = "road.json";
  a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 1000);
}

export function bindControls(app) {
  const on = (id, f) => $(id).addEventListener("click", () => {
    f();
    app.dirty = true;
  });
  for (const b of document.querySelectorAll("[data-mode]")) on(b.id, () => app.setMode(b.dataset.mode));
  on("set-policy", () => setPolicy(app));
  on("remove", () => removeSelected(app));
  on("fit", () => app.fit());
  on("land", () => {
    const ids = [...app.selection];
    if (!ids.length) return showMessage("select UAVs to land first", true);
    return report(`land ${ids.length} UAV(s)`, ids.map((id) => app.api.land(id)));
  });
  on("land-all", () => report("land all", [app.api.landAll()]));
  on("estop", () => {
    if (confirm("Emergency stop: cut the motors of every UAV now?")) report("emergency stop", [app.api.emergencyStop()]);
  });
  on("pause", () => {
    const paused = app.snapshot && app.snapshot.paused;
    report(paused ? "resume" : "pause", [paused ? app.api.resume() : app.api.pause()]);
  });
  $("scenario-file").addEventListener("change", async (ev) => {
    const f = await readFile(ev.target);
    if (!f) return;
    try {
      const res = await app.api.loadScenario(f.text);
      showMessage(`scenario ${res.name} loaded: ${res.uavs} UAVs`);
      app.selection.clear();
      app.fitted = false;
      app.editorLoaded = false;
    } catch (e) {
      showMessage(`scenario ${f.name}: ${describe(e)}`, true);
    }
  });

  const ed = app.editor;
  on("draw", () => app.setDrawing(!app.drawing));
  on("new-road", () => {
    ed.clear();
    app.setEditTool(null);
    app.setDrawing(true);
  });
  on("add-junction", () => app.setEditTool(app.editTool === "junction" ? null : "junction"));
  on("branch-road", () => app.setEditTool(app.editTool === "branch" ? null : "branch"));
  on("insert", () => ed.insert(ed.selected) || showMessage("select a segment first", true));
  on("delete-seg", () => ed.remove(ed.selected) || showMessage("select a segment first", true));
  on("undo", () => ed.undo());
  on("redo", () => ed.redo());
  on("apply", () => applyRoad(app));
  on("revert", async () => {
    await app.refreshGeometry();
    if (app.geometry) ed.load(app.geometry.layout);
    app.dirty = true;
  });
  on("export", () => exportRoad(app));
  $("import-file").addEventListener("change", async (ev) => {
    const f = await readFile(ev.target);
    if (!f) return;
    try {
      const json = JSON.parse(f.text);
      if (!Array.isArray(json.segments) && !Array.isArray(json.roads)) throw new Error("no `segments` or `roads` array");
      const broken = ed.load(json);
      const what = json.roads ? `${json.roads.length} roads and ${(json.junctions || []).length} junctions` : `${json.segments.length} segments`;
      showMessage(`imported ${what} from ${f.name}${broken ? `; ${broken} join(s) snapped to the previous exit edge` : ""}`);
      app.fit();
    } catch (e) {
      showMessage(`import ${f.name}: ${e.message}`, true);
    }
    app.dirty = true;
  });
  loadPolicies(app);
}
