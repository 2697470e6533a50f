// Small 2D helpers on [x, y] arrays.

export const sub = (a, b) => [a[0] - b[0], a[1] - b[1]];
export const mid = (a, b) => [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2];
export const cross = (a, b) => a[0] * b[1] - a[1] * b[0];
export const dist2 = (a, b) => (a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2;

/** True when segments p1–p2 and q1–q2 properly cross. */
export function segmentsCross(p1, p2, q1, q2) {
  const d1 = cross(sub(p2, p1), sub(q1, p1));
  const d2 = cross(sub(p2, p1), sub(q2, p1));
  const d3 = cross(sub(q2, q1), sub(p1, q1));
  const d4 = cross(sub(q2, q1), sub(p2, q1));
  return d1 * d2 < 0 && d3 * d4 < 0;
}

/** Point in polygon (even-odd rule). */
export function inPolygon(p, poly) {
  let inside = false;
  for (let i = 0, j = poly.length - 1; i < poly.length; j = i++) {
    const [xi, yi] = poly[i];
    const [xj, yj] = poly[j];
    if (yi > p[1] !== yj > p[1] && p[0] < ((xj - xi) * (p[1] - yi)) / (yj - yi) + xi) inside = !inside;
  }
  return inside;
}

/** A segment [p1, p2, p3, p4] as a polygon in cyclic order p1, p2, p4, p3. */
export const quadPolygon = (s) => [s[0], s[1], s[3], s[2]];

export const centroid = (poly) => [
  poly.reduce((a, p) => a + p[0], 0) / poly.length,
  poly.reduce((a, p) => a + p[1], 0) / poly.length,
];

/** Index of the segment of `segments` containing p, or -1. */
export function segmentAt(segments, p) {
  for (let i = 0; i < segments.length; i++) if (inPolygon(p, quadPolygon(segments[i]))) return i;
  return -1;
}

/** The live road's cells as polygons: a network's cells, or a chain road's segments. */
export function roadPolygons(geometry) {
  if (!geometry) return [];
  if (Array.isArray(geometry.cells) && geometry.cells.length) return geometry.cells.map((c) => c.polygon);
  return (geometry.layout.segments || []).map(quadPolygon);
}

/** True when p is inside one of `polygons`. */
export const insideAny = (polygons, p) => polygons.some((poly) => inPolygon(p, poly));
