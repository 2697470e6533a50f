// The /ws snapshot stream in the binary format (`?format=bin`, decoded by binary.js): keeps the
// roster and reservations as they change and only the latest tick frame (decoded lazily, once per
// animation frame), reconnects with backoff, and reports the connection state.

import { KIND_RESERVATIONS, KIND_ROSTER, KIND_TICK, decodeJson, decodeTick, kindOf } from "./binary.js";

export class Stream {
  /** @param {(connected: boolean) => void} onState */
  constructor(onState) {
    this.onState = onState;
    this.latest = null;
    this.roster = [];
    this.rosterVersion = 0;
    this.reservations = [];
    this.frames = 0; // tick frames received
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
      } else if (kind === KIND_RESERVATIONS) {
        this.reservations = decodeJson(ev.data).body.reservations;
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
    return decodeTick(buffer, this.roster, this.reservations, this.pools[this.turn]);
  }
}
