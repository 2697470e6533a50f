// Decoder of the binary stream (`/ws?format=bin`, format version 1; docs/streams.md, Binary stream): roster
// and reservations frames are JSON after an 8-byte header; a tick frame is a 52-byte header and a
// 40-byte little-endian record per UAV, turned here into the snapshot objects the renderer draws.

export const VERSION = 1;
export const KIND_TICK = 1;
export const KIND_ROSTER = 2;
export const KIND_RESERVATIONS = 3;
/** Another region's states (`serve --region`; docs/regions.md, State payload). */
export const KIND_REGION = 4;
const HEADER = 52;
const RECORD = 40;
/** Status byte → name, in the server's order. */
export const STATUSES = ["flying", "arrived", "braking", "failed", "stale", "lost", "connecting", "taking_off",
  "landing", "landed", "stopped", "stopping", "waiting"];

const text = new TextDecoder();

/** The kind of a message (its second byte), or 0 when it is not a version 1 frame. */
export function kindOf(buffer) {
  const bytes = new Uint8Array(buffer, 0, Math.min(2, buffer.byteLength));
  return bytes.length === 2 && bytes[0] === VERSION ? bytes[1] : 0;
}

/** The JSON of a roster or reservations frame, with its version: `{version, body}`. */
export function decodeJson(buffer) {
  const view = new DataView(buffer);
  return { version: view.getUint32(4, true), body: JSON.parse(text.decode(new Uint8Array(buffer, 8))) };
}

const nan = (x) => (Number.isNaN(x) ? null : x);
/** A float32 parameter as the decimal it was set as (0.3, not 0.30000001192092896). */
const decimal = (x) => Number(x.toPrecision(7));

/**
 * A tick frame as a snapshot object (`GET /api/state`'s fields that the stream carries), with each
 * UAV's id, policy, goal and link from `roster` (the decoded roster frame's `uavs`). The UAV objects
 * are taken from `pool` (an array, grown as needed) and overwritten: at 10,000 UAVs allocating
 * 50,000 objects per frame cost more in garbage collection than the drawing did. Pass a pool whose
 * previous snapshot nobody reads any more (the stream alternates two).
 */
export function decodeTick(buffer, roster, reservations, pool = []) {
  const view = new DataView(buffer);
  const count = view.getUint32(28, true);
  if (buffer.byteLength !== HEADER + RECORD * count) throw new Error(`${buffer.byteLength} bytes for ${count} records`);
  const flags = view.getUint16(2, true);
  while (pool.length < count) {
    pool.push({ id: "", policy: "", goal: null, link: "", p: [0, 0], v: [0, 0], u: [0, 0], target: [0, 0],
      status: "flying", arrived: false, lost: false });
  }
  pool.length = count;
  const uavs = pool;
  for (let k = 0, at = HEADER; k < count; k++, at += RECORD) {
    const who = roster[view.getUint32(at, true)] || {};
    const uflags = view.getUint8(at + 37);
    const u = uavs[k];
    u.id = who.id;
    u.policy = who.policy;
    u.goal = who.goal ?? null;
    u.link = who.link;
    u.p[0] = view.getFloat32(at + 4, true);
    u.p[1] = view.getFloat32(at + 8, true);
    u.v[0] = view.getFloat32(at + 12, true);
    u.v[1] = view.getFloat32(at + 16, true);
    u.u[0] = view.getFloat32(at + 20, true);
    u.u[1] = view.getFloat32(at + 24, true);
    u.target[0] = view.getFloat32(at + 28, true);
    u.target[1] = view.getFloat32(at + 32, true);
    u.status = STATUSES[view.getUint8(at + 36)] || "flying";
    u.arrived = (uflags & 1) !== 0;
    u.lost = (uflags & 2) !== 0;
  }
  return {
    tick: Number(view.getBigUint64(8, true)), time: view.getFloat64(16, true),
    paused: (flags & 1) !== 0, filtered: (flags & 2) !== 0, fleet: view.getUint32(24, true),
    road_version: view.getUint32(32, true),
    min_collision_margin_m: nan(view.getFloat32(36, true)), min_road_margin_m: nan(view.getFloat32(40, true)),
    d_c: decimal(view.getFloat32(44, true)), d_s: decimal(view.getFloat32(48, true)),
    uavs, reservations,
  };
}

/** The region name of a kind 4 message (its header only). */
export function regionName(buffer) {
  const length = new DataView(buffer).getUint16(2, true);
  return text.decode(new Uint8Array(buffer, 28, length));
}

/**
 * Another region's state message (kind 4: a 28-byte header, the region's name, then per UAV its id
 * and a 36-byte record) as `{region, tick, uavs}`, each UAV tagged with `region`. Ghosts (UAVs the
 * region released and no longer flies; flag 4) and the ids in `skip` (flown here) are left out.
 */
export function decodeRegion(buffer, skip) {
  const view = new DataView(buffer);
  const bytes = new Uint8Array(buffer);
  const nameLength = view.getUint16(2, true);
  const count = view.getUint32(4, true);
  const region = text.decode(bytes.subarray(28, 28 + nameLength));
  const uavs = [];
  let at = 28 + nameLength;
  for (let k = 0; k < count; k++) {
    const idLength = view.getUint16(at, true);
    const id = text.decode(bytes.subarray(at + 2, at + 2 + idLength));
    at += 2 + idLength;
    const f = (i) => view.getFloat32(at + 4 * i, true);
    const flags = view.getUint8(at + 33);
    if ((flags & 4) === 0 && !skip.has(id)) {
      uavs.push({ id, region, policy: "", goal: null, link: "", p: [f(0), f(1)], v: [f(2), f(3)], u: [f(4), f(5)],
        target: [f(6), f(7)], status: STATUSES[view.getUint8(at + 32)] || "flying", arrived: (flags & 1) !== 0,
        lost: (flags & 2) !== 0 });
    }
    at += 36;
  }
  return { region, tick: Number(view.getBigUint64(8, true)), uavs };
}
