// The road editor's model: one road (a chain layout) or a network of named roads and junctions.
// A road of n segments is kept as n + 1 cross edges [a, b]: segment i is [p1, p2, p3, p4] =
// [a(i+1), a(i), b(i+1), b(i)], so walls are a(i)→a(i+1) and b(i)→b(i+1) and consecutive segments
// share an edge: joins are seamless by construction and moving a joint vertex moves both segments.
// The drawing and segment operations act on the active road (`edges`). A junction is a polygon; a
// road starts at a junction's side or another road's end (its first edge is that side, exactly) and
// its end attaches to a side the same way; moving a vertex moves every vertex at the same point, so
// what is attached stays attached. Every change is undoable. A loaded layout's regions (named segment
// ranges) are kept while the road has as many segments as when it was loaded, and dropped otherwise.

import { dist2, mid, segmentsCross } from "./geometry.js";

const clone = (edges) => edges.map(([a, b]) => [[...a], [...b]]);
const cloneRegions = (regions) => regions && regions.map((r) => ({ ...r, segments: [...r.segments] }));
const cloneRoads = (roads) => roads.map((r) => ({ ...r, edges: clone(r.edges) }));
const cloneJunctions = (junctions) => junctions.map((j) => ({ ...j, polygon: j.polygon.map((p) => [...p]) }));
const newRoad = (name) => ({ name, edges: [], one_way: false, speed_limit: null });
/** The segments of a road's cross edges in the layout format. */
const segmentsOf = (e) => {
  const out = [];
  for (let i = 0; i + 1 < e.length; i++) out.push([e[i + 1][0], e[i][0], e[i + 1][1], e[i][1]]);
  return out;
};
/** Cross edges of a chain of segments (the first one's entry edge, then every exit edge). */
const edgesOf = (segs) => (segs.length ? [[[...segs[0][1]], [...segs[0][3]]], ...segs.map((s) => [[...s[0]], [...s[2]]])] : []);
/** The squared distance from p to the segment a–b. */
const toSegment2 = (p, a, b) => {
  const d = [b[0] - a[0], b[1] - a[1]];
  const len2 = d[0] ** 2 + d[1] ** 2;
  const t = len2 > 0 ? Math.max(0, Math.min(1, ((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2)) : 0;
  return dist2(p, [a[0] + t * d[0], a[1] + t * d[1]]);
};
/** Side length (m) of a junction added by `addJunction`. */
export const JUNCTION_SIZE_M = 3;

export class RoadEditor {
  constructor() {
    this.roads = [newRoad("road")];
    this.junctions = [];
    this.active = 0; // the road the drawing and segment operations act on
    this.undoStack = [];
    this.redoStack = [];
    this.selected = -1; // selected segment
    this.pending = null; // first point of the next edge while drawing
    this.error = null; // {segment, message} from the server
    this.regions = null; // the loaded layout's regions, or null
    this.regionSegments = 0; // how many segments the road had when they were loaded
    this.version = 0; // bumps on every change (for redraws)
  }

  /** The active road's cross edges. */
  get edges() {
    return this.roads[this.active].edges;
  }

  set edges(edges) {
    this.roads[this.active].edges = edges;
  }

  /** True when the layout is a network (junctions, or more than one road), not a chain. */
  isNetwork() {
    return this.junctions.length > 0 || this.roads.length > 1;
  }

  /** The active road's segments in the layout format. */
  segments() {
    return segmentsOf(this.edges);
  }

  /** Every road's segments, with its index: [{road, name, segments}]. */
  allSegments() {
    return this.roads.map((r, road) => ({ road, name: r.name, segments: segmentsOf(r.edges) }));
  }

  /**
   * The layout to apply or export. A chain (one road, no junction): `{segments}`, with the loaded
   * regions while the segment count is unchanged. A network: `{roads, junctions}` (roads without a
   * segment yet are left out).
   */
  layout() {
    if (this.isNetwork()) {
      const roads = this.roads
        .filter((r) => r.edges.length >= 2)
        .map((r) => {
          const road = { name: r.name, segments: segmentsOf(r.edges).map((s) => s.map((p) => [...p])) };
          if (r.one_way) road.one_way = true;
          if (r.speed_limit !== null && r.speed_limit !== undefined) road.speed_limit = r.speed_limit;
          return road;
        });
      return { roads, junctions: this.junctions.map((j) => ({ name: j.name, polygon: j.polygon.map((p) => [...p]) })) };
    }
    const layout = { segments: this.segments().map((s) => s.map((p) => [...p])) };
    if (this.regions && layout.segments.length === this.regionSegments) layout.regions = cloneRegions(this.regions);
    return layout;
  }

  /** Why the loaded regions are left out of `layout()`, or null when they are kept (or there are none). */
  regionsNote() {
    const n = Math.max(this.edges.length - 1, 0);
    if (!this.regions) return null;
    if (this.isNetwork()) return `regions dropped: a network has no regions by segment range`;
    if (n === this.regionSegments) return null;
    return `regions dropped: the loaded ${this.regions.length} region(s) covered ${this.regionSegments} segments, the road now has ${n}; add regions to the layout JSON again`;
  }

  /** After an apply: the applied layout's regions (none when they were dropped) are the ones kept from now on. */
  applied(layout) {
    this.regions = cloneRegions(layout.regions) ?? null;
    this.regionSegments = layout.segments ? layout.segments.length : 0;
  }

  snapshot() {
    return {
      roads: cloneRoads(this.roads),
      junctions: cloneJunctions(this.junctions),
      active: this.active,
      selected: this.selected,
      regions: this.regions,
      regionSegments: this.regionSegments,
    };
  }

  /** Call before every change: records the state for undo. */
  commit() {
    this.undoStack.push(this.snapshot());
    if (this.undoStack.length > 200) this.undoStack.shift();
    this.redoStack = [];
    this.changed();
  }

  changed() {
    this.error = null;
    this.version++;
  }

  /**
   * Replaces the road by `layout` (`{segments}`, or a network `{roads, junctions}`); with `undoable`
   * the previous road can be restored. Returns the number of joins that were not seamless (the editor
   * snaps them to segment i's exit).
   */
  load(layout, undoable = true) {
    if (undoable) this.commit();
    const chains = Array.isArray(layout.roads) ? layout.roads : [{ name: "road", segments: layout.segments || [] }];
    this.regions = Array.isArray(layout.regions) ? cloneRegions(layout.regions) : null;
    this.regionSegments = (layout.segments || []).length;
    let broken = 0;
    this.roads = chains.map((r) => {
      const segs = r.segments || [];
      segs.forEach((s, i) => {
        const next = segs[i + 1];
        if (next && (dist2(next[1], s[0]) > 0 || dist2(next[3], s[2]) > 0)) broken++;
      });
      return { name: r.name, edges: edgesOf(segs), one_way: !!r.one_way, speed_limit: r.speed_limit ?? null };
    });
    if (!this.roads.length) this.roads = [newRoad("road")];
    this.junctions = cloneJunctions(layout.junctions || []);
    this.active = 0;
    this.selected = -1;
    this.pending = null;
    if (!undoable) this.changed();
    return broken;
  }

  clear() {
    this.commit();
    this.roads = [newRoad("road")];
    this.junctions = [];
    this.active = 0;
    this.regions = null;
    this.selected = -1;
    this.pending = null;
  }

  /**
   * Drawing: the first two points of an empty road make its entry edge; afterwards every two points
   * make the far edge of a new segment that starts at the previous exit edge. The two new points are
   * paired with the previous edge's ends so that the walls do not cross. Returns true when a
   * segment (or the entry edge) was added.
   */
  addPoint(p) {
    if (!this.pending) {
      this.pending = [...p];
      this.version++;
      return false;
    }
    const q = this.pending;
    this.pending = null;
    this.commit();
    const last = this.edges[this.edges.length - 1];
    let edge = [q, [...p]];
    if (last && segmentsCross(last[0], q, last[1], p)) edge = [[...p], q];
    this.edges.push(edge);
    this.selected = this.edges.length - 2;
    return true;
  }

  cancelPending() {
    if (this.pending) {
      this.pending = null;
      this.version++;
    }
  }

  /** The vertex of the active road nearest to p within `tol` (world units): {edge, side}, or null;
   * else a junction's vertex: {junction, vertex}. */
  vertexAt(p, tol) {
    let best = null;
    let bestD = tol * tol;
    this.edges.forEach((edge, i) =>
      edge.forEach((v, side) => {
        const d = dist2(v, p);
        if (d <= bestD) {
          bestD = d;
          best = { edge: i, side };
        }
      }),
    );
    if (best) return best;
    this.junctions.forEach((j, junction) =>
      j.polygon.forEach((v, vertex) => {
        const d = dist2(v, p);
        if (d <= bestD) {
          bestD = d;
          best = { junction, vertex };
        }
      }),
    );
    return best;
  }

  /** Moves a vertex and every other vertex at the same point, of any road or junction, so that what
   * is attached stays attached (no undo record: commit() once when a drag starts). */
  moveVertex(ref, p) {
    const from = ref.junction !== undefined ? this.junctions[ref.junction].polygon[ref.vertex] : this.edges[ref.edge][ref.side];
    const at = [...from];
    const same = (v) => dist2(v, at) < 1e-18;
    for (const r of this.roads) for (const edge of r.edges) for (let k = 0; k < 2; k++) if (same(edge[k])) edge[k] = [...p];
    for (const j of this.junctions) j.polygon.forEach((v, k) => same(v) && (j.polygon[k] = [...p]));
    this.changed();
  }

  /** Adds a square junction of `size` m centred at p, named j1, j2, … (the first free name). */
  addJunction(p, size = JUNCTION_SIZE_M) {
    this.commit();
    const h = size / 2;
    const name = this.freeName("j", this.junctions);
    this.junctions.push({ name, polygon: [[p[0] - h, p[1] - h], [p[0] + h, p[1] - h], [p[0] + h, p[1] + h], [p[0] - h, p[1] + h]] });
    return this.junctions.length - 1;
  }

  /** The first name `prefix`N not taken in `list`. */
  freeName(prefix, list) {
    for (let n = 1; ; n++) if (!list.some((x) => x.name === `${prefix}${n}`)) return `${prefix}${n}`;
  }

  /**
   * The side nearest to p within `tol` that a road can start at or attach to: a junction's side, or
   * an end edge of a road other than the active one (while it is being drawn), as its two ends.
   */
  sideAt(p, tol, exceptActive = false) {
    let best = null;
    let bestD = tol * tol;
    const consider = (a, b) => {
      const d = toSegment2(p, a, b);
      if (d <= bestD) {
        bestD = d;
        best = [[...a], [...b]];
      }
    };
    for (const j of this.junctions) j.polygon.forEach((a, k) => consider(a, j.polygon[(k + 1) % j.polygon.length]));
    this.roads.forEach((r, i) => {
      if ((exceptActive && i === this.active) || r.edges.length < 2) return;
      consider(...r.edges[0]);
      consider(...r.edges[r.edges.length - 1]);
    });
    return best;
  }

  /** Starts a new road (active from now on) at the side nearest to p within `tol`; false if none. */
  startRoad(p, tol) {
    const side = this.sideAt(p, tol);
    if (!side) return false;
    this.commit();
    this.roads.push({ ...newRoad(this.freeName("r", this.roads)), edges: [side] });
    this.active = this.roads.length - 1;
    this.selected = -1;
    this.pending = null;
    return true;
  }

  /** Ends the active road at the side nearest to p within `tol` (its last segment reaches that side
   * exactly, paired so its walls do not cross); false if none or the road has no edge yet. */
  attachEnd(p, tol) {
    const last = this.edges[this.edges.length - 1];
    const side = last && this.sideAt(p, tol, true);
    if (!side) return false;
    this.commit();
    const edge = segmentsCross(last[0], side[0], last[1], side[1]) ? [side[1], side[0]] : side;
    this.edges.push(edge);
    this.selected = this.edges.length - 2;
    this.pending = null;
    return true;
  }

  /** Makes the road holding p (in one of its segments) the active one; returns its index or -1. */
  activateAt(p, segmentAt) {
    for (let i = 0; i < this.roads.length; i++) {
      const k = segmentAt(segmentsOf(this.roads[i].edges), p);
      if (k >= 0) {
        this.active = i;
        this.selected = k;
        this.version++;
        return i;
      }
    }
    return -1;
  }

  /** Splits segment i in two at the middle of its walls. */
  insert(i) {
    if (i < 0 || i + 1 >= this.edges.length) return false;
    this.commit();
    const [a0, b0] = this.edges[i];
    const [a1, b1] = this.edges[i + 1];
    this.edges.splice(i + 1, 0, [mid(a0, a1), mid(b0, b1)]);
    this.selected = i;
    return true;
  }

  /**
   * Deletes segment i: an end segment is dropped; a middle one is closed up (the next segment then
   * starts at segment i's entry edge).
   */
  remove(i) {
    const n = this.edges.length - 1;
    if (i < 0 || i >= n) return false;
    this.commit();
    if (n === 1) this.edges = [];
    else if (i === 0) this.edges.shift();
    else this.edges.splice(i + 1, 1);
    this.selected = Math.min(i, this.edges.length - 2);
    return true;
  }

  undo() {
    return this.swap(this.undoStack, this.redoStack);
  }

  redo() {
    return this.swap(this.redoStack, this.undoStack);
  }

  swap(from, to) {
    const state = from.pop();
    if (!state) return false;
    to.push(this.snapshot());
    this.roads = state.roads;
    this.junctions = state.junctions;
    this.active = state.active;
    this.selected = state.selected;
    this.regions = state.regions;
    this.regionSegments = state.regionSegments;
    this.pending = null;
    this.changed();
    return true;
  }
}
