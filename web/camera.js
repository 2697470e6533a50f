// World (metres, y up as on a map) <-> screen (CSS pixels, y down) transform, pan and zoom.

export class Camera {
  constructor() {
    this.cx = 0; // world point at the canvas centre
    this.cy = 0;
    this.scale = 40; // pixels per metre
    this.width = 1;
    this.height = 1;
  }

  resize(width, height) {
    this.width = width;
    this.height = height;
  }

  toScreen(x, y) {
    return [(x - this.cx) * this.scale + this.width / 2, this.height / 2 - (y - this.cy) * this.scale];
  }

  toWorld(sx, sy) {
    return [(sx - this.width / 2) / this.scale + this.cx, (this.height / 2 - sy) / this.scale + this.cy];
  }

  panBy(dxPx, dyPx) {
    this.cx -= dxPx / this.scale;
    this.cy += dyPx / this.scale;
  }

  /** Zooms by `factor` keeping the world point under (sx, sy) fixed. */
  zoomAt(sx, sy, factor) {
    const [wx, wy] = this.toWorld(sx, sy);
    this.scale = Math.min(2000, Math.max(0.5, this.scale * factor));
    const [nx, ny] = this.toWorld(sx, sy);
    this.cx += wx - nx;
    this.cy += wy - ny;
  }

  /** Frames the box [x0, y0, x1, y1] with a margin. */
  fit(box) {
    const [x0, y0, x1, y1] = box;
    if (!isFinite(x0) || x1 <= x0 || y1 <= y0) return;
    this.cx = (x0 + x1) / 2;
    this.cy = (y0 + y1) / 2;
    this.scale = 0.85 * Math.min(this.width / (x1 - x0), this.height / (y1 - y0));
  }
}

/** Bounding box [x0, y0, x1, y1] of a list of points. */
export function bounds(points) {
  let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
  for (const [x, y] of points) {
    x0 = Math.min(x0, x); y0 = Math.min(y0, y); x1 = Math.max(x1, x); y1 = Math.max(y1, y);
  }
  return [x0, y0, x1, y1];
}
