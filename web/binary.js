// Decoder of the binary stream (`/ws?format=bin`, format version 1; README "Binary stream"): roster
// and reservations frames are JSON after an 8-byte header; a tick frame is a 52-byte header and a
// 40-byte little-endian record per UAV, turned here into the snapshot objects the renderer draws.

export const VERSION = 1;
export const KIND_TICK = 1;
export const KIND_ROSTER = 2;
export const KIND_RESERVATIONS = 3;
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
 * UAV's id, policy, goal and link from `roster` (the decoded roster frame's `uavs`).
 */
export function decodeTick(buffer, roster, reservations) {
  const view = new DataView(buffer);
  const count = view.getUint32(28, true);
  if (buffer.byteLength !== HEADER + RECORD * count) throw new Error(`${buffer.byteLength} bytes for ${count} records`);
  const flags = view.getUint16(2, true);
  const uavs = new Array(count);
  for (let k = 0, at = HEADER; k < count; k++, at += RECORD) {
    const f = (o) => view.getFloat32(at + o, true);
    const who = roster[view.getUint32(at, true)] || {};
    const uflags = view.getUint8(at + 37);
    uavs[k] = {
      id: who.id, policy: who.policy, goal: who.goal ?? null, link: who.link,
      p: [f(4), f(8)], v: [f(12), f(16)], u: [f(20), f(24)], target: [f(28), f(32)],
      status: STATUSES[view.getUint8(at + 36)] || "flying",
      arrived: (uflags & 1) !== 0, lost: (uflags & 2) !== 0,
    };
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
