// The /ws snapshot stream in the binary format (`?format=bin`, decoded by binary.js): keeps the
// roster and reservations as they change and only the latest tick frame (decoded lazily, once per
// animation frame), reconnects with backoff, and reports the connection state.

import {
  KIND_REGION, KIND_RESERVATIONS, KIND_ROSTER, KIND_TICK, decodeJson, decodeRegion, decodeTick, kindOf, regionName,
} from "./binary.js";

/** Another region's UAVs are drawn until its messages stop for this long (ms). */
const REGION_SHOWN_MS = 2000;

export class Stream {
  /** @param {(connected: boolean) => void} onState */
  constructor(onState) {
    this.onState = onState;
    this.latest = null;
    this.roster = [];
    this.rosterVersion = 0;
    this.reservations = [];
    this.frames = 0; // tick frames received
    /** Other regions (`serve --region`): name → {at, buffer} of its newest message. */
    this.elsewhere = new Map();
    this.ownIds = new Set();
    /** Two pools of UAV objects, used in turn: the snapshot before the latest stays intact. */
    this.pools = [[], []];
    this.turn = 0;
    this.delay = 250;
    this.connect();
  }

  connect() {
    const scheme = location.protocol === "https:" ? "wss" : "ws";
    const ws = new WebSocket(`${scheme}://${location.host}/ws?format=bin`);
    ws.binaryType = "arraybuffer";
    ws.onopen = () => {
      this.delay = 250;
      this.onState(true);
    };
    ws.onmessage = (ev) => {
      if (!(ev.data instanceof ArrayBuffer)) return;
      const kind = kindOf(ev.data);
      if (kind === KIND_TICK) {
        this.latest = ev.data;
        this.frames++;
      } else if (kind === KIND_ROSTER) {
        const { version, body } = decodeJson(ev.data);
        [this.roster, this.rosterVersion] = [body.uavs, version];
        this.ownIds = new Set(body.uavs.map((u) => u.id));
      } else if (kind === KIND_RESERVATIONS) {
        this.reservations = decodeJson(ev.data).body.reservations;
      } else if (kind === KIND_REGION) {
        this.elsewhere.set(regionName(ev.data), { at: performance.now(), buffer: ev.data });
      }
    };
    ws.onclose = () => {
      this.onState(false);
      setTimeout(() => this.connect(), this.delay);
      this.delay = Math.min(this.delay * 2, 5000);
    };
    this.ws = ws;
  }

  /** The newest snapshot received since the last call, decoded, or null. */
  take() {
    const buffer = this.latest;
    if (buffer === null) return null;
    this.latest = null;
    // A tick of an older roster (one arrived in between): the next tick will match.
    if (new DataView(buffer).getUint32(4, true) !== this.rosterVersion) return null;
    this.turn ^= 1;
    const snapshot = decodeTick(buffer, this.roster, this.reservations, this.pools[this.turn]);
    // The whole fleet: the other regions' UAVs after this region's own (tagged with `region`).
    const now = performance.now();
    snapshot.regions = [];
    for (const [name, latest] of this.elsewhere) {
      if (now - latest.at > REGION_SHOWN_MS) {
        this.elsewhere.delete(name);
        continue;
      }
      const other = decodeRegion(latest.buffer, this.ownIds);
      snapshot.regions.push({ name, tick: other.tick, uavs: other.uavs.length });
      for (const u of other.uavs) snapshot.uavs.push(u);
    }
    return snapshot;
  }
}
