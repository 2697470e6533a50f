// Recent positions of every UAV in fixed-size ring buffers (no allocation per frame).

export const TRAIL_LEN = 40;

export class Trails {
  constructor() {
    this.byId = new Map();
  }

  /** Appends every UAV's position of `snapshot` and forgets UAVs that are gone. */
  push(snapshot) {
    const seen = new Set();
    for (const u of snapshot.uavs) {
      seen.add(u.id);
      let t = this.byId.get(u.id);
      if (!t) {
        t = { xs: new Float64Array(TRAIL_LEN), ys: new Float64Array(TRAIL_LEN), head: 0, len: 0 };
        this.byId.set(u.id, t);
      }
      t.xs[t.head] = u.p[0];
      t.ys[t.head] = u.p[1];
      t.head = (t.head + 1) % TRAIL_LEN;
      t.len = Math.min(t.len + 1, TRAIL_LEN);
    }
    if (seen.size !== this.byId.size) for (const id of this.byId.keys()) if (!seen.has(id)) this.byId.delete(id);
  }

  /** Calls f(x, y, first) for the points of `id` from oldest to newest. */
  forEach(id, f) {
    const t = this.byId.get(id);
    if (!t) return;
    const start = (t.head - t.len + TRAIL_LEN) % TRAIL_LEN;
    for (let k = 0; k < t.len; k++) {
      const i = (start + k) % TRAIL_LEN;
      f(t.xs[i], t.ys[i], k === 0);
    }
  }
}
