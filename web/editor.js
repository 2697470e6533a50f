// The road editor's model. A road of n segments is kept as n + 1 cross edges [a, b]: segment i is
// [p1, p2, p3, p4] = [a(i+1), a(i), b(i+1), b(i)], so walls are a(i)→a(i+1) and b(i)→b(i+1) and
// consecutive segments share an edge: joins are seamless by construction and moving a joint vertex
// moves both segments. Every change is undoable. A loaded layout's regions (named segment ranges)
// are kept while the road has as many segments as when it was loaded, and dropped otherwise.

import { dist2, mid, segmentsCross } from "./geometry.js";

const clone = (edges) => edges.map(([a, b]) => [[...a], [...b]]);
const cloneRegions = (regions) => regions && regions.map((r) => ({ ...r, segments: [...r.segments] }));

export class RoadEditor {
  constructor() {
    this.edges = [];
    this.undoStack = [];
    this.redoStack = [];
    this.selected = -1; // selected segment
    this.pending = null; // first point of the next edge while drawing
    this.error = null; // {segment, message} from the server
    this.regions = null; // the loaded layout's regions, or null
    this.regionSegments = 0; // how many segments the road had when they were loaded
    this.version = 0; // bumps on every change (for redraws)
  }

  /** Segments in the layout format. */
  segments() {
    const e = this.edges;
    const out = [];
    for (let i = 0; i + 1 < e.length; i++) out.push([e[i + 1][0], e[i][0], e[i + 1][1], e[i][1]]);
    return out;
  }

  /** The layout to apply or export: with the loaded regions while the segment count is unchanged. */
  layout() {
    const layout = { segments: this.segments().map((s) => s.map((p) => [...p])) };
    if (this.regions && layout.segments.length === this.regionSegments) layout.regions = cloneRegions(this.regions);
    return layout;
  }

  /** Why the loaded regions are left out of `layout()`, or null when they are kept (or there are none). */
  regionsNote() {
    const n = Math.max(this.edges.length - 1, 0);
    if (!this.regions || n === this.regionSegments) return null;
    return `regions dropped: the loaded ${this.regions.length} region(s) covered ${this.regionSegments} segments, the road now has ${n}; add regions to the layout JSON again`;
  }

  /** After an apply: the applied layout's regions (none when they were dropped) are the ones kept from now on. */
  applied(layout) {
    this.regions = cloneRegions(layout.regions) ?? null;
    this.regionSegments = layout.segments.length;
  }

  snapshot() {
    return { edges: clone(this.edges), selected: this.selected, regions: this.regions, regionSegments: this.regionSegments };
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
   * Replaces the road by `layout` (`{segments}`); with `undoable` the previous road can be restored.
   * Returns the number of joins that were not seamless (the editor snaps them to segment i's exit).
   */
  load(layout, undoable = true) {
    if (undoable) this.commit();
    const segs = layout.segments;
    this.regions = Array.isArray(layout.regions) ? cloneRegions(layout.regions) : null;
    this.regionSegments = segs.length;
    let broken = 0;
    this.edges = [];
    if (segs.length) {
      this.edges.push([[...segs[0][1]], [...segs[0][3]]]);
      segs.forEach((s, i) => {
        this.edges.push([[...s[0]], [...s[2]]]);
        const next = segs[i + 1];
        if (next && (dist2(next[1], s[0]) > 0 || dist2(next[3], s[2]) > 0)) broken++;
      });
    }
    this.selected = -1;
    this.pending = null;
    if (!undoable) this.changed();
    return broken;
  }

  clear() {
    this.commit();
    this.edges = [];
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

  /** The vertex nearest to p within `tol` (world units): {edge, side}, or null. */
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
    return best;
  }

  /** Moves a vertex (no undo record: commit() once when a drag starts). */
  moveVertex(ref, p) {
    this.edges[ref.edge][ref.side] = [...p];
    this.changed();
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
    this.edges = state.edges;
    this.selected = state.selected;
    this.regions = state.regions;
    this.regionSegments = state.regionSegments;
    this.pending = null;
    this.changed();
    return true;
  }
}
