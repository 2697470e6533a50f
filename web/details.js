// The selected UAVs' details: what each is doing and why (a traffic rule's reason, its link, its
// margins), beside the canvas. Updated with every snapshot while something is selected.

/** How many selected UAVs get a details card (a box selection can hold thousands). */
const MAX_CARDS = 4;

const REASONS = {
  single_file: "waits for its turn at a single-file section",
  deadlock_backoff: "backs off out of a deadlocked neighbour's way",
  junction: "waits before a junction for a crossing movement to clear it",
  merge: "waits for its turn at a merge",
};

const fmt = (v, d = 2) => (v === null || v === undefined ? "–" : v.toFixed(d));

/** A Crazyflie's own report in words: its supervisor's state, battery and link quality. */
function firmwareWords(f) {
  const state = [
    f.locked && "LOCKED (reboot it)",
    f.crashed && "crashed",
    f.tumbled && "tumbled",
    f.flying && "flying",
    f.armed && "armed",
  ].filter(Boolean);
  const info = f.supervisor_info === null ? "supervisor not logged" : `supervisor ${state.join(", ") || "idle"}`;
  const battery = f.battery_v === null ? null : `battery ${fmt(f.battery_v)} V`;
  const quality = f.link_quality === null ? null : `link ${Math.round(100 * f.link_quality)} %`;
  return [info, battery, quality].filter(Boolean).join("; ");
}

function card(u) {
  const speed = Math.hypot(u.v[0], u.v[1]);
  const rows = [
    ["status", u.status.replace("_", " ")],
    ["reason", u.status === "waiting" && u.wait_reason ? `${u.wait_reason}: ${REASONS[u.wait_reason] || ""}` : null],
    ["policy", u.policy],
    ["position", `${fmt(u.p[0])}, ${fmt(u.p[1])} m`],
    ["speed", `${fmt(speed)} m/s`],
    ["goal", u.goal ? `${fmt(u.goal[0])}, ${fmt(u.goal[1])} m` : "none (hovers)"],
    ["margins", `road ${fmt(u.road_margin_m, 3)} m, collision ${fmt(u.collision_margin_m, 3)} m`],
    ["link", u.phase ? `${u.link} (${u.phase})` : u.link],
    ["link error", u.link_error ?? null],
    ["firmware", u.firmware ? firmwareWords(u.firmware) : null],
  ];
  const el = document.createElement("section");
  el.dataset.uav = u.id;
  const title = document.createElement("h3");
  title.textContent = u.id;
  const list = document.createElement("dl");
  for (const [k, v] of rows) {
    if (v === null) continue;
    const dt = document.createElement("dt");
    dt.textContent = k;
    const dd = document.createElement("dd");
    dd.textContent = v;
    dd.dataset.field = k;
    list.append(dt, dd);
  }
  el.append(title, list);
  return el;
}

/**
 * Shows the first selected UAVs of `snap` in `panel` (hidden without a selection). The stream carries
 * position, speed, status and the roster; `extra` (id → `GET /api/uavs/{id}`) adds what only the REST
 * answer has (the traffic rule's reason, margins, the link's phase and error), refreshed by the app.
 */
export function showDetails(panel, snap, selection, extra = new Map()) {
  if (!selection.size) {
    if (!panel.hidden) panel.replaceChildren();
    panel.hidden = true;
    return;
  }
  const cards = [];
  for (const u of snap.uavs) {
    if (!selection.has(u.id)) continue;
    cards.push(card({ ...extra.get(u.id), ...u }));
    if (cards.length === MAX_CARDS) break;
  }
  if (selection.size > cards.length && cards.length === MAX_CARDS) {
    const more = document.createElement("p");
    more.textContent = `and ${selection.size - cards.length} more selected`;
    cards.push(more);
  }
  panel.replaceChildren(...cards);
  panel.hidden = cards.length === 0;
}
