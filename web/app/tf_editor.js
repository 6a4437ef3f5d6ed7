// The transfer-function editor: the opacity curve drawn over the volume's histogram, with
// points to drag, add (click) and remove (double-click, Delete), a colour per point, a
// colour bar, and window/level fields. Opacity is drawn on a √ scale: the low opacities
// that matter in volume rendering (0.01 … 0.1) get room to be edited.

import {
  addPoint, applyWindowLevel, evaluate, fromHex, movePoint, removePoint, setColor, toHex, windowLevelOf,
} from "../core/transfer_function.js";
import { displayNumber } from "../core/window_level.js";

const PAD = { left: 8, right: 8, top: 8, bottom: 20 };   // CSS px around the plot; the bottom holds the colour bar
const HIT_RADIUS_PX = 9;                                  // CSS px: how near a click must be to take a point
const POINT_RADIUS_PX = 5;                                // CSS px

const KEY_VALUE_STEP = 0.01;    // of the value range per arrow key (Shift: ×10)
const KEY_ALPHA_STEP = 0.01;    // opacity per arrow key (Shift: ×10)

// A field the editor could not apply: show what is applied instead, and say why until the
// next edit of that field.
function markInvalid(field, why) {
  field.setAttribute("aria-invalid", "true");
  field.title = why;
  field.addEventListener("input", () => { field.removeAttribute("aria-invalid"); field.title = field.dataset.title ?? ""; }, { once: true });
}

const yOfAlpha = (a) => Math.sqrt(Math.max(0, a));
const alphaOfY = (y) => Math.min(1, Math.max(0, y)) ** 2;

export class TransferFunctionEditor {
  // elements: {canvas, value, alpha, color, remove, window, level};
  // onChange(points, {interactive}) — interactive while a drag goes on.
  constructor(elements, onChange) {
    this.el = elements;
    this.onChange = onChange;
    this.points = [];
    this.range = [0, 1];          // the x domain: the volume's value range
    this.histogram = null;        // {range, counts}
    this.selected = -1;
    this.drag = null;
    this.ctx = elements.canvas.getContext("2d");
    new ResizeObserver(() => this.draw()).observe(elements.canvas);
    this.bind();
  }

  // --- data in --------------------------------------------------------------------------

  setVolume(volume) {
    this.hounsfield = volume?.modality?.hounsfield === true;   // W/L shown in whole HU
    const r = volume?.value_range ?? volume?.histogram?.range;
    this.range = r && r[1] > r[0] ? [r[0], r[1]] : [0, 1];
    this.histogram = volume?.histogram ?? null;
    this.draw();
  }

  setPoints(points, { keepSelection = false } = {}) {
    this.points = points.map((p) => [...p]);
    if (!keepSelection || this.selected >= this.points.length) this.selected = -1;
    this.syncFields();
    this.draw();
  }

  // --- geometry -------------------------------------------------------------------------

  plotBox() {
    const c = this.el.canvas;
    const w = c.clientWidth, h = c.clientHeight;
    return { x0: PAD.left, y0: PAD.top, w: Math.max(1, w - PAD.left - PAD.right), h: Math.max(1, h - PAD.top - PAD.bottom) };
  }

  toScreen([value, , , , alpha]) {
    const b = this.plotBox();
    const t = (value - this.range[0]) / (this.range[1] - this.range[0]);
    return { x: b.x0 + Math.min(1, Math.max(0, t)) * b.w, y: b.y0 + (1 - yOfAlpha(alpha)) * b.h, outside: t < 0 || t > 1 };
  }

  fromScreen(x, y) {
    const b = this.plotBox();
    return {
      value: this.range[0] + ((x - b.x0) / b.w) * (this.range[1] - this.range[0]),
      alpha: alphaOfY(1 - (y - b.y0) / b.h),
    };
  }

  hit(x, y) {
    let best = -1, bestD = HIT_RADIUS_PX;
    this.points.forEach((p, i) => {
      const s = this.toScreen(p);
      if (s.outside) return;   // points beyond the data range are drawn as edge marks, not taken
      const d = Math.hypot(s.x - x, s.y - y);
      if (d <= bestD) { best = i; bestD = d; }
    });
    return best;
  }

  // --- input ----------------------------------------------------------------------------

  bind() {
    const c = this.el.canvas;
    const local = (e) => { const r = c.getBoundingClientRect(); return { x: e.clientX - r.left, y: e.clientY - r.top }; };
    c.addEventListener("pointerdown", (e) => {
      if (e.button !== 0 || this.points.length === 0) return;
      const { x, y } = local(e);
      let i = this.hit(x, y);
      if (i < 0) {
        const { value, alpha } = this.fromScreen(x, y);
        const added = addPoint(this.points, value, alpha);
        this.points = added.points;
        i = added.index;
        this.onChange(this.points, { interactive: true });
      }
      this.selected = i;
      this.drag = { pointerId: e.pointerId };
      c.setPointerCapture(e.pointerId);
      c.focus();
      this.syncFields();
      this.draw();
    });
    c.addEventListener("pointermove", (e) => {
      if (!this.drag || this.drag.pointerId !== e.pointerId) return;
      const { x, y } = local(e);
      const { value, alpha } = this.fromScreen(x, y);
      this.points = movePoint(this.points, this.selected, value, alpha, this.range);
      this.syncFields();
      this.draw();
      this.onChange(this.points, { interactive: true });
    });
    const end = (e) => {
      if (!this.drag || this.drag.pointerId !== e.pointerId) return;
      this.drag = null;
      this.onChange(this.points, { interactive: false });
    };
    c.addEventListener("pointerup", end);
    c.addEventListener("pointercancel", end);
    c.addEventListener("dblclick", (e) => {
      const { x, y } = local(e);
      const i = this.hit(x, y);
      if (i >= 0) this.remove(i);
    });
    c.tabIndex = 0;
    c.addEventListener("keydown", (e) => this.onKey(e));

    // A field shows what is applied once its edit is taken: a value clamped between its
    // neighbours, or the old value back (marked invalid) when the text is no number.
    const edit = (field, fn) => () => {
      if (this.selected < 0) return;
      const x = field.value.trim() === "" ? NaN : Number(field.value);
      if (field !== this.el.color && !Number.isFinite(x)) {
        markInvalid(field, `"${field.value}" is not a number: the point keeps its value`);
      } else {
        this.points = fn(this.points, this.selected, x);
        this.onChange(this.points, { interactive: false });
      }
      this.syncFields({ force: true });
      this.draw();
    };
    this.el.value.addEventListener("change", edit(this.el.value, (p, i, x) => movePoint(p, i, x, p[i][4], this.range)));
    this.el.alpha.addEventListener("change", edit(this.el.alpha, (p, i, x) => movePoint(p, i, p[i][0], x, this.range)));
    this.el.color.addEventListener("input", edit(this.el.color, (p, i) => setColor(p, i, fromHex(this.el.color.value))));
    this.el.remove.addEventListener("click", () => { if (this.selected >= 0) this.remove(this.selected); });
    const wl = (e) => {
      const w = this.el.window.value.trim() === "" ? NaN : Number(this.el.window.value);
      const l = this.el.level.value.trim() === "" ? NaN : Number(this.el.level.value);
      if (!(w > 0) || !Number.isFinite(l)) {
        markInvalid(e.target, !(w > 0) ? "the window must be a positive number" : "the level must be a number");
        this.syncFields({ force: true });
        return;
      }
      this.applyWindowLevel(w, l, false);
      this.syncFields({ force: true });
    };
    this.el.window.addEventListener("change", wl);
    this.el.level.addEventListener("change", wl);
  }

  // Keyboard (the curve focused): ←/→ select the previous/next point, Shift+←/→ move its
  // value, ↑/↓ its opacity (Shift: ×10), Insert or + adds a point after it, Delete removes it.
  onKey(e) {
    const n = this.points.length;
    if (n === 0) return;
    const i = this.selected, span = this.range[1] - this.range[0];
    const big = e.shiftKey ? 10 : 1;
    if ((e.key === "ArrowLeft" || e.key === "ArrowRight") && !e.shiftKey) {
      const d = e.key === "ArrowLeft" ? -1 : 1;
      this.select(i < 0 ? (d > 0 ? 0 : n - 1) : Math.min(n - 1, Math.max(0, i + d)));
    } else if ((e.key === "ArrowLeft" || e.key === "ArrowRight") && i >= 0) {
      const d = (e.key === "ArrowLeft" ? -1 : 1) * KEY_VALUE_STEP * span;
      this.keyEdit(movePoint(this.points, i, this.points[i][0] + d, this.points[i][4], this.range));
    } else if ((e.key === "ArrowUp" || e.key === "ArrowDown") && i >= 0) {
      const d = (e.key === "ArrowUp" ? 1 : -1) * KEY_ALPHA_STEP * big;
      this.keyEdit(movePoint(this.points, i, this.points[i][0], this.points[i][4] + d, this.range));
    } else if ((e.key === "Insert" || e.key === "+") && n >= 1) {
      // Halfway to the next point (or the previous one, after the last).
      const a = Math.max(0, i), b = a < n - 1 ? a + 1 : a - 1;
      const value = b >= 0 ? (this.points[a][0] + this.points[b][0]) / 2 : this.points[a][0] + 0.1 * span;
      const added = addPoint(this.points, value, evaluate(this.points, value)[3]);
      this.selected = added.index;
      this.keyEdit(added.points);
    } else if ((e.key === "Delete" || e.key === "Backspace") && i >= 0) {
      this.remove(i);
    } else if (e.key === "Escape" && i >= 0) {
      this.select(-1);
    } else {
      return;
    }
    e.preventDefault();
  }

  select(i) {
    this.selected = i;
    this.syncFields({ force: true });
    this.draw();
  }

  keyEdit(points) {
    this.points = points;
    this.syncFields({ force: true });
    this.draw();
    this.onChange(this.points, { interactive: false });
  }

  // What a screen reader hears on the curve: the selected point.
  describeSelection() {
    const p = this.points[this.selected];
    // role="slider" over the points: which one is selected, and what it is.
    const c = this.el.canvas;
    c.setAttribute("aria-valuemin", "1");
    c.setAttribute("aria-valuemax", String(Math.max(1, this.points.length)));
    c.setAttribute("aria-valuenow", String(Math.max(1, this.selected + 1)));
    c.setAttribute("aria-valuetext", p
      ? `point ${this.selected + 1} of ${this.points.length}: value ${round(p[0])}, opacity ${round(p[4], 4)}`
      : `${this.points.length} points, none selected`);
  }

  remove(i) {
    if (this.points.length <= 2) return;
    this.points = removePoint(this.points, i);
    this.selected = Math.min(i, this.points.length - 1);
    this.syncFields();
    this.draw();
    this.onChange(this.points, { interactive: false });
  }

  // Window/level, from the fields or from Alt-drag on the view.
  applyWindowLevel(window, level, interactive) {
    if (this.points.length < 2) return;
    this.points = applyWindowLevel(this.points, window, level);
    this.syncFields();
    this.draw();
    this.onChange(this.points, { interactive });
  }

  get windowLevel() { return this.points.length >= 2 ? windowLevelOf(this.points) : null; }

  // force: also the field being typed in (its edit was just taken or refused).
  syncFields({ force = false } = {}) {
    const p = this.points[this.selected];
    const active = force ? null : document.activeElement;
    this.describeSelection();
    for (const f of [this.el.value, this.el.alpha, this.el.color, this.el.remove]) f.disabled = !p;
    if (p) {
      if (active !== this.el.value) this.el.value.value = round(p[0]);
      if (active !== this.el.alpha) this.el.alpha.value = round(p[4], 4);
      this.el.color.value = toHex(p.slice(1, 4));
    } else {
      this.el.value.value = this.el.alpha.value = "";
    }
    const wl = this.windowLevel;
    if (wl) {
      if (active !== this.el.window) this.el.window.value = displayNumber(wl.window, { hounsfield: this.hounsfield });
      if (active !== this.el.level) this.el.level.value = displayNumber(wl.level, { hounsfield: this.hounsfield });
    }
  }

  // --- drawing --------------------------------------------------------------------------

  draw() {
    const c = this.el.canvas, ctx = this.ctx;
    const dpr = window.devicePixelRatio || 1;
    const W = c.clientWidth, H = c.clientHeight;
    if (W === 0 || H === 0) return;
    if (c.width !== Math.round(W * dpr) || c.height !== Math.round(H * dpr)) {
      c.width = Math.round(W * dpr);
      c.height = Math.round(H * dpr);
    }
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, W, H);
    const b = this.plotBox();

    // Histogram: log counts, so that the background peak does not flatten everything else.
    const counts = this.histogram?.counts;
    if (counts?.length) {
      const hr = this.histogram.range;
      const max = Math.log1p(Math.max(...counts));
      ctx.fillStyle = "rgba(138, 149, 163, 0.28)";
      counts.forEach((n, i) => {
        const v0 = hr[0] + (i / counts.length) * (hr[1] - hr[0]);
        const v1 = hr[0] + ((i + 1) / counts.length) * (hr[1] - hr[0]);
        const x0 = this.toScreen([v0, 0, 0, 0, 0]).x, x1 = this.toScreen([v1, 0, 0, 0, 0]).x;
        const h = (Math.log1p(n) / max) * b.h;
        ctx.fillRect(x0, b.y0 + b.h - h, Math.max(1, x1 - x0), h);
      });
    }

    // Grid lines at opacity 0.01, 0.1, 0.25, 0.5, 1.
    ctx.strokeStyle = "rgba(255, 255, 255, 0.06)";
    ctx.fillStyle = "rgba(255, 255, 255, 0.3)";
    ctx.font = "9px system-ui, sans-serif";
    for (const a of [0.01, 0.1, 0.25, 0.5, 1]) {
      const y = b.y0 + (1 - yOfAlpha(a)) * b.h;
      ctx.beginPath(); ctx.moveTo(b.x0, y); ctx.lineTo(b.x0 + b.w, y); ctx.stroke();
      ctx.fillText(String(a), b.x0 + 2, y - 2);
    }
    if (this.points.length === 0) return;

    // Area under the curve, coloured by the transfer function; and the colour bar.
    const steps = Math.max(2, Math.round(b.w));
    for (let i = 0; i < steps; i++) {
      const v = this.range[0] + (i / (steps - 1)) * (this.range[1] - this.range[0]);
      const [r, g, bl, a] = evaluate(this.points, v);
      const x = b.x0 + (i / (steps - 1)) * b.w;
      const y = b.y0 + (1 - yOfAlpha(a)) * b.h;
      ctx.fillStyle = `rgba(${r * 255 | 0}, ${g * 255 | 0}, ${bl * 255 | 0}, 0.35)`;
      ctx.fillRect(x, y, b.w / steps + 1, b.y0 + b.h - y);
      ctx.fillStyle = `rgb(${r * 255 | 0}, ${g * 255 | 0}, ${bl * 255 | 0})`;
      ctx.fillRect(x, b.y0 + b.h + 6, b.w / steps + 1, 8);
    }

    // The curve, then the points.
    ctx.strokeStyle = "#e8edf2";
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    for (let i = 0; i <= steps; i++) {
      const v = this.range[0] + (i / steps) * (this.range[1] - this.range[0]);
      const y = b.y0 + (1 - yOfAlpha(evaluate(this.points, v)[3])) * b.h;
      const x = b.x0 + (i / steps) * b.w;
      if (i === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
    }
    ctx.stroke();
    this.points.forEach((p, i) => {
      const s = this.toScreen(p);
      ctx.beginPath();
      if (s.outside) {
        // Beyond the data range: a small triangle at the edge it lies past.
        const dir = s.x <= b.x0 ? 1 : -1;
        ctx.moveTo(s.x, s.y - 4); ctx.lineTo(s.x + dir * 6, s.y); ctx.lineTo(s.x, s.y + 4); ctx.closePath();
        ctx.fillStyle = "rgba(255, 255, 255, 0.4)";
        ctx.fill();
        return;
      }
      ctx.arc(s.x, s.y, POINT_RADIUS_PX, 0, 2 * Math.PI);
      ctx.fillStyle = toHex(p.slice(1, 4));
      ctx.fill();
      ctx.lineWidth = i === this.selected ? 2.5 : 1;
      ctx.strokeStyle = i === this.selected ? "#3fb6c8" : "#0b0e12";
      ctx.stroke();
    });
  }
}

function round(x, digits = 6) {
  return Number(Number(x).toPrecision(digits));
}
