// Time series of the fleet's smallest collision and road margins against D_c and D_s.

const WINDOW_S = 60;
const COLL = "#d6336c";
const ROAD = "#1c7ed6";

export class MarginPlot {
  constructor(canvas) {
    this.canvas = canvas;
    this.samples = []; // [time, collision|null, road|null]
    this.dc = 0.3;
    this.ds = 0.1;
  }

  push(snapshot) {
    const s = this.samples;
    if (s.length && snapshot.time < s[s.length - 1][0]) s.length = 0; // the server restarted its clock
    s.push([snapshot.time, snapshot.min_collision_margin_m, snapshot.min_road_margin_m]);
    while (s.length && s[0][0] < snapshot.time - WINDOW_S) s.shift();
    this.dc = snapshot.d_c;
    this.ds = snapshot.d_s;
  }

  draw() {
    const c = this.canvas;
    const dpr = window.devicePixelRatio || 1;
    const w = c.clientWidth, h = c.clientHeight;
    if (c.width !== Math.round(w * dpr)) c.width = Math.round(w * dpr);
    if (c.height !== Math.round(h * dpr)) c.height = Math.round(h * dpr);
    const ctx = c.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, w, h);
    const s = this.samples;
    const left = 34, right = w - 6, top = 16, bottom = h - 14;
    const yMax = 4 * Math.max(this.dc, this.ds);
    const t1 = s.length ? s[s.length - 1][0] : WINDOW_S, t0 = t1 - WINDOW_S;
    const X = (t) => left + ((t - t0) / WINDOW_S) * (right - left);
    const Y = (v) => bottom - (Math.min(Math.max(v, 0), yMax) / yMax) * (bottom - top);

    ctx.font = "10px system-ui, sans-serif";
    ctx.fillStyle = "#555";
    ctx.textBaseline = "middle";
    ctx.textAlign = "right";
    for (const v of [0, yMax / 2, yMax]) ctx.fillText(v.toFixed(2), left - 3, Y(v));
    ctx.strokeStyle = "#ccc";
    ctx.lineWidth = 1;
    ctx.strokeRect(left, top, right - left, bottom - top);
    const limit = (v, colour) => {
      ctx.strokeStyle = colour;
      ctx.setLineDash([4, 3]);
      ctx.beginPath();
      ctx.moveTo(left, Y(v));
      ctx.lineTo(right, Y(v));
      ctx.stroke();
      ctx.setLineDash([]);
    };
    limit(this.dc, COLL);
    limit(this.ds, ROAD);
    const series = (k, colour) => {
      ctx.strokeStyle = colour;
      ctx.lineWidth = 1.5;
      ctx.beginPath();
      let pen = false;
      for (const row of s) {
        if (row[k] === null || row[k] === undefined) {
          pen = false;
          continue;
        }
        if (pen) ctx.lineTo(X(row[0]), Y(row[k]));
        else ctx.moveTo(X(row[0]), Y(row[k]));
        pen = true;
      }
      ctx.stroke();
    };
    series(1, COLL);
    series(2, ROAD);
    ctx.textAlign = "left";
    ctx.textBaseline = "top";
    ctx.fillStyle = COLL;
    ctx.fillText(`collision margin (– – D_c ${this.dc})`, left, 2);
    ctx.fillStyle = ROAD;
    ctx.fillText(`road margin (– – D_s ${this.ds})`, left + 150, 2);
    ctx.fillStyle = "#555";
    ctx.fillText("last 60 s, m", left, bottom + 1);
  }
}
