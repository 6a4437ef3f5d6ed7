// The stats overlay: fps, latency, level, render and encode times, error estimate, image
// size, and a small chart of the error estimate against time while the view refines.

import { describeFrame } from "../core/frame_facts.js";
import { limitedLine } from "../core/limits.js";
import { psnrOf } from "../core/protocol.js";

export const STATS_REFRESH_MS = 250;   // ms between refreshes of the time-dependent numbers (fps)

const fmtMs = (x) => (Number.isFinite(x) ? `${x < 10 ? x.toFixed(1) : Math.round(x)} ms` : "–");

export class StatsOverlay {
  constructor(root, stats) {
    this.$ = (id) => root.getElementById(id);
    this.stats = stats;
    this.chart = this.$("error-chart");
    // What the automatic policy lowered to stay within the server's limits: a row of its own,
    // shown only while the frame on screen says so.
    const image = this.$("stat-image");
    this.limitedTerm = Object.assign(root.createElement("dt"), { textContent: "lowered", hidden: true });
    this.limited = Object.assign(root.createElement("dd"), { id: "stat-limited", hidden: true });
    this.limited.style.whiteSpace = "normal";   // a sentence: wrapped, not cut like the numbers
    this.limited.style.textAlign = "left";
    image.after(this.limitedTerm, this.limited);
    setInterval(() => this.refresh(), STATS_REFRESH_MS);
  }

  refresh() {
    const s = this.stats;
    this.$("stat-fps").textContent = s.fps(performance.now()).toFixed(0);
    this.$("stat-latency").textContent = fmtMs(s.latencyMs ?? NaN);
    const h = s.last;
    if (!h) {
      for (const id of ["stat-level", "stat-render", "stat-encode", "stat-error", "stat-image"]) this.$(id).textContent = "–";
    } else {
      // The frame as rendered: a reduced-scale frame says its own ray grid, not the viewport.
      const d = describeFrame(h);
      const level = this.$("stat-level");
      level.textContent = level.title = d.level;
      level.classList.toggle("final", h.final || h.rest_pass > 0);
      this.$("stat-render").textContent = fmtMs(h.render_ms);
      this.$("stat-encode").textContent = fmtMs(h.encode_ms);
      const e = h.error;
      const err = this.$("stat-error");
      err.textContent = e ? `${e.value.toExponential(1)} · ${psnrOf(e.value).toFixed(1)} dB (${e.method.replace(/_/g, " ")})` : "not estimated";
      err.title = e ? `RMSE ${e.value} (${e.method})` : "";
      const image = this.$("stat-image");
      image.textContent = image.title = d.image;
    }
    const limited = limitedLine(h);
    this.limited.textContent = this.limited.title = limited;
    this.limited.hidden = this.limitedTerm.hidden = !limited;
    this.drawChart();
  }

  // Error (log scale) against ms since the view changed; a dot per frame, final ones green.
  drawChart() {
    const c = this.chart, dpr = window.devicePixelRatio || 1;
    const W = c.clientWidth || 200, H = c.clientHeight || 72;
    if (c.width !== Math.round(W * dpr)) { c.width = Math.round(W * dpr); c.height = Math.round(H * dpr); }
    const ctx = c.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, W, H);
    ctx.strokeStyle = "rgba(255,255,255,0.12)";
    ctx.strokeRect(0.5, 0.5, W - 1, H - 1);
    const pts = this.stats.series.points;
    if (pts.length === 0) {
      ctx.fillStyle = "rgba(255,255,255,0.35)";
      ctx.font = "10px system-ui, sans-serif";
      ctx.fillText("no error estimates yet", 8, H / 2 + 3);
      return;
    }
    const logs = pts.map((p) => Math.log10(Math.max(p.value, 1e-6)));
    let lo = Math.floor(Math.min(...logs)), hi = Math.ceil(Math.max(...logs));
    if (hi - lo < 1) hi = lo + 1;
    const tMax = Math.max(...pts.map((p) => p.tMs), 1) * 1.1;
    const x = (t) => 4 + (t / tMax) * (W - 8);
    const y = (l) => 4 + ((hi - l) / (hi - lo)) * (H - 16);
    // Decade lines, labelled where there is room (at least 11 px between labels).
    ctx.font = "9px system-ui, sans-serif";
    const every = Math.max(1, Math.ceil(11 / ((H - 16) / (hi - lo))));
    for (let d = lo; d <= hi; d++) {
      ctx.fillStyle = "rgba(255,255,255,0.08)";
      ctx.fillRect(2, y(d), W - 4, 1);
      if ((hi - d) % every !== 0) continue;
      ctx.fillStyle = "rgba(255,255,255,0.35)";
      ctx.fillText(`1e${d}`, W - 26, y(d) + 3);   // centred on its line
    }
    ctx.fillStyle = "rgba(255,255,255,0.35)";
    ctx.fillText(`${Math.round(tMax)} ms`, 4, H - 2);
    ctx.strokeStyle = "#3fb6c8";
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    pts.forEach((p, i) => (i ? ctx.lineTo(x(p.tMs), y(logs[i])) : ctx.moveTo(x(p.tMs), y(logs[i]))));
    ctx.stroke();
    pts.forEach((p, i) => {
      ctx.fillStyle = p.final ? "#3fbf6f" : "#3fb6c8";
      ctx.beginPath();
      ctx.arc(x(p.tMs), y(logs[i]), p.final ? 3.5 : 2.5, 0, 2 * Math.PI);
      ctx.fill();
    });
  }
}
