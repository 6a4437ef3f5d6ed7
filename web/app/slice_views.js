// Three orthogonal slices beside the 3D view — axial, coronal, sagittal in the patient
// frame — rendered by the server (protocol/README.md, `slice`), with window/level and a
// crosshair: clicking or dragging in one pane moves the point the other two pass through,
// and the point is drawn over the 3D view, projected with the camera the frame on screen
// was rendered with.
//
// One request per pane in flight; a pane that needs a new image while waiting asks again
// when the answer comes (latest wins, as the server does for frames). Slices answer only
// their own requests and never change the 3D scene. The wheel steps the crosshair one
// voxel spacing along a pane's normal (that pane re-slices, the others move their lines); a
// slab (thickness in mm, MIP, MinIP or mean) projects each pane's plane over that thickness;
// the column is resized by dragging its left edge. Tools (measurements, crop handles) hook
// into the panes through addTool(): they see a press first and draw over each pane.

import { requests } from "../core/protocol.js";
import { FULL_CROP, cropCorners, cropGeometry, paneFit, paneToPixel, pixelOf, pixelToPane, projectToView,
  scrolledPoint, sliceNormal, spacingAlong, vec3, worldOf } from "../core/measure.js";
import * as orientation from "../core/orientation.js";

export { pixelOf, projectToView, worldOf };

export const SLICE_AXES = Object.freeze(["axial", "coronal", "sagittal"]);
const LABELS = { axial: "Axial", coronal: "Coronal", sagittal: "Sagittal" };
// Edge letters (LPS world): the patient's right is on the image's left (radiological).
const EDGES = {
  axial: { left: "R", right: "L", top: "A", bottom: "P" },
  coronal: { left: "R", right: "L", top: "S", bottom: "I" },
  sagittal: { left: "A", right: "P", top: "S", bottom: "I" },
};
const WHEEL_NOTCH_PX = 100;    // wheel delta of one notch (Chromium's): one slice per notch
const MAX_SLICE_SIDE = 512;    // px requested per pane: sharp on a laptop, cheap on the server
// CT in Hounsfield units (air near −1000): a soft-tissue window; anything else: its range.
const CT_WINDOW = { window: 400, level: 40 };

const WIDTH_KEY = "volcast.slicesWidth";   // the column's width the user dragged to (CSS px)
const MIN_WIDTH = 160, MAX_WIDTH_FRACTION = 0.7;   // of the window: the 3D view keeps the rest
export const SLAB_MODES = Object.freeze([
  { value: "mip", label: "MIP" }, { value: "minip", label: "MinIP" }, { value: "mean", label: "mean" },
]);

// The window/level slices start with, in the volume's own units.
export function defaultWindowLevel(volume) {
  const [lo, hi] = volume?.value_range ?? [0, 1];
  if (lo <= -900 && hi >= 300) return { ...CT_WINDOW };
  return hi > lo ? { window: hi - lo, level: (lo + hi) / 2 } : { window: 1, level: lo };
}

export class SliceViews {
  // container: an element to fill (the panes and the window/level fields go in it);
  // viewElement: the 3D view's element, over which the crosshair point is drawn.
  constructor(doc, session, container, viewElement) {
    this.doc = doc;
    this.session = session;
    this.container = container;
    this.point = null;                 // the crosshair, world mm; null: the server's default (centre)
    this.wl = { window: 1, level: 0 };
    this.slab = { thickness: 0, mode: "mip" };
    this.panes = {};
    this.camera = null;                // the camera of the 3D frame on screen
    this.requestsById = new Map();     // id -> {axis, generation}
    this.generation = 0;               // bumped when a volume opens: older answers are stale
    this.tools = [];                   // addTool(): measurements, crop handles
    this.correction = null;            // the orientation correction the slices are cut with

    container.classList.add("slices");
    container.innerHTML = "";
    const grip = doc.createElement("div");
    grip.className = "slices-grip";
    grip.title = "Drag to resize the slice panes (double-click: back to the default width)";
    grip.setAttribute("role", "separator");
    grip.setAttribute("aria-orientation", "vertical");
    grip.setAttribute("aria-label", "Resize the slice panes");
    container.appendChild(grip);
    this.bindGrip(grip);
    const bar = doc.createElement("div");
    bar.className = "slices-bar";
    bar.innerHTML = `<label>W <input type="number" step="any" min="0" data-wl="window" aria-label="Slice window"></label>
      <label>L <input type="number" step="any" data-wl="level" aria-label="Slice level"></label>
      <label title="Thick slab: each pane projects this thickness (mm) about its plane; 0: the plane alone">Slab <input type="number" step="any" min="0" value="0" data-slab="thickness" aria-label="Slab thickness (mm)"> mm</label>
      <select data-slab="mode" aria-label="Slab projection">${SLAB_MODES.map((m) => `<option value="${m.value}">${m.label}</option>`).join("")}</select>
      <span class="slices-point muted small" aria-live="polite"></span>`;
    container.appendChild(bar);
    this.bar = bar;
    this.inputs = { window: bar.querySelector('[data-wl="window"]'), level: bar.querySelector('[data-wl="level"]') };
    this.slabInputs = { thickness: bar.querySelector('[data-slab="thickness"]'), mode: bar.querySelector('[data-slab="mode"]') };
    this.pointText = bar.querySelector(".slices-point");
    for (const key of ["window", "level"]) {
      this.inputs[key].addEventListener("change", () => {
        const v = Number(this.inputs[key].value);
        if (!Number.isFinite(v) || (key === "window" && !(v > 0))) { this.showWindowLevel(); return; }
        this.wl = { ...this.wl, [key]: v };
        this.requestAll();
      });
    }
    this.slabInputs.thickness.addEventListener("change", () => {
      const v = Number(this.slabInputs.thickness.value);
      if (!Number.isFinite(v) || v < 0) { this.slabInputs.thickness.value = String(this.slab.thickness); return; }
      this.setSlab({ thickness: v });
    });
    this.slabInputs.mode.addEventListener("change", () => this.setSlab({ mode: this.slabInputs.mode.value }));
    this.paneBox = doc.createElement("div");
    this.paneBox.className = "slice-panes";
    container.appendChild(this.paneBox);
    for (const axis of SLICE_AXES) this.panes[axis] = this.makePane(axis);

    this.marker = doc.createElement("canvas");
    this.marker.className = "slice-crosshair-3d";
    this.marker.setAttribute("aria-hidden", "true");
    viewElement.appendChild(this.marker);
    this.viewElement = viewElement;

    const c = session.connection;
    c.on("slice", (s) => this.onSlice(s));
    c.on("error", (e) => this.onError(e));
    c.on("state", () => {          // answers of a lost socket never come
      this.requestsById.clear();
      for (const pane of Object.values(this.panes)) pane.inFlight = false;
    });
    session.on("opened", ({ restored }) => this.onOpened(restored));
    // A flip or turn of the volume (the policy's orientation_correction) changes what every
    // plane cuts: slice again once the policy carrying it has gone. The server answers a
    // session's messages in order, so these slices are cut with it.
    this.correctionKey = "null";
    session.on("policy", (policy) => {
      const correction = policy.quality?.orientation_correction ?? null;
      const key = JSON.stringify(correction);
      if (key === this.correctionKey) return;
      this.correctionKey = key;
      this.correction = correction;
      this.showEdges();
      this.requestAll();
    });
    session.on("frame", (f) => { if (f.header.camera) { this.camera = f.header.camera; this.drawMarker(); } });
    // The orientation card says after every change (a volume opened, a flip, "treat as …")
    // which letters the panes' edges may carry: anatomical, or the file's axes.
    this.orientationLetters = null;    // {volume, panes}
    doc.addEventListener("volcast:orientation", (e) => {
      if (!e.detail?.panes) return;
      this.orientationLetters = { volume: this.session.volume?.name ?? null, panes: e.detail.panes };
      this.showEdges();
    });
    this.restoreWidth();
    new ResizeObserver(() => { this.layout(); this.requestAll(); this.drawMarker(); }).observe(container);
  }

  // A tool: {pointerDown(pane, at, ev) → {move(at), end(at)} | null, draw(pane, ctx, fit)};
  // `at` is {x, y} in the pane canvas's CSS px. Tools are asked in the order added; a press
  // no tool takes moves the crosshair.
  addTool(tool) { this.tools.push(tool); }

  // --- the column's width -----------------------------------------------------------------

  // Three panes stacked are each a third of the column's height; once the column is wider
  // than two thirds of its height, two columns (axial on the left, coronal over sagittal on
  // the right) give every pane a larger square: min(W/2, H/2) > min(W, H/3).
  layout() {
    const r = this.paneBox.getBoundingClientRect();
    this.paneBox.classList.toggle("two-columns", r.height > 0 && r.width > (2 * r.height) / 3);
  }

  bindGrip(grip) {
    let startX = 0, startWidth = 0;
    grip.addEventListener("pointerdown", (ev) => {
      try { grip.setPointerCapture(ev.pointerId); } catch { /* synthetic */ }
      startX = ev.clientX;
      startWidth = this.container.getBoundingClientRect().width;
      grip.dataset.dragging = "1";
      ev.preventDefault();
    });
    grip.addEventListener("pointermove", (ev) => {
      if (!grip.dataset.dragging) return;
      this.setWidth(startWidth + (startX - ev.clientX));   // the grip is the left edge: left widens
    });
    const end = () => {
      if (!grip.dataset.dragging) return;
      delete grip.dataset.dragging;
      try { localStorage.setItem(WIDTH_KEY, String(Math.round(this.container.getBoundingClientRect().width))); } catch { /* storage off */ }
    };
    grip.addEventListener("pointerup", end);
    grip.addEventListener("pointercancel", end);
    grip.addEventListener("dblclick", () => {
      this.container.style.removeProperty("width");
      try { localStorage.removeItem(WIDTH_KEY); } catch { /* storage off */ }
    });
  }

  setWidth(px) {
    const max = Math.max(MIN_WIDTH, (globalThis.innerWidth || 1600) * MAX_WIDTH_FRACTION);
    const w = Math.round(Math.min(max, Math.max(MIN_WIDTH, px)));
    this.container.style.width = `${w}px`;
    return w;
  }

  restoreWidth() {
    let saved = null;
    try { saved = Number(localStorage.getItem(WIDTH_KEY)); } catch { /* storage off */ }
    if (saved > 0) this.setWidth(saved);
  }

  // --- panes --------------------------------------------------------------------------------

  makePane(axis) {
    const pane = this.doc.createElement("div");
    pane.className = "slice-pane";
    pane.dataset.axis = axis;
    const canvas = this.doc.createElement("canvas");
    canvas.tabIndex = 0;
    canvas.setAttribute("aria-label", `${LABELS[axis]} slice: click or drag to move the crosshair, wheel or up and down arrows to step through slices`);
    pane.appendChild(canvas);
    pane.insertAdjacentHTML("beforeend", `<span class="slice-label">${LABELS[axis]}</span>
      <span class="edge left"></span><span class="edge right"></span>
      <span class="edge top"></span><span class="edge bottom"></span>`);
    this.paneBox.appendChild(pane);
    const state = { axis, element: pane, canvas, header: null, image: null, inFlight: false, dirty: false, handler: null };
    const at = (ev) => { const r = canvas.getBoundingClientRect(); return { x: ev.clientX - r.left, y: ev.clientY - r.top }; };
    const pick = (p) => {
      if (!state.header) return;
      const fit = this.fitOf(state);
      const { c, r } = paneToPixel(fit, p.x, p.y);
      this.setPoint(worldOf(state.header, c, r));
    };
    canvas.addEventListener("pointerdown", (ev) => {
      if (ev.button !== 0) return;
      try { canvas.setPointerCapture(ev.pointerId); } catch { /* synthetic */ }
      const p = at(ev);
      state.handler = null;
      if (state.header) {
        for (const tool of this.tools) {
          const h = tool.pointerDown(state, p, ev);
          if (h) { state.handler = h; break; }
        }
      }
      if (!state.handler) state.handler = { move: pick, end: () => {} };
      state.handler.move(p);
      ev.preventDefault();
    });
    canvas.addEventListener("pointermove", (ev) => { state.handler?.move(at(ev)); });
    const end = (ev) => { const h = state.handler; state.handler = null; h?.end(at(ev)); };
    canvas.addEventListener("pointerup", end);
    canvas.addEventListener("pointercancel", end);
    // The wheel steps through slices: one voxel spacing along this pane's normal per notch
    // (a trackpad's small deltas add up to a notch first).
    let wheelRest = 0;
    canvas.addEventListener("wheel", (ev) => {
      ev.preventDefault();
      const px = ev.deltaY * (ev.deltaMode === 1 ? 40 : ev.deltaMode === 2 ? 400 : 1);
      wheelRest += px;
      const steps = Math.trunc(wheelRest / WHEEL_NOTCH_PX);
      if (steps === 0) return;
      wheelRest -= steps * WHEEL_NOTCH_PX;
      this.scroll(axis, steps);
    }, { passive: false });
    // By keyboard, with the pane focused: ↑/↓ or Page Up/Down step as one wheel notch does.
    canvas.addEventListener("keydown", (ev) => {
      const steps = { ArrowUp: -1, PageUp: -1, ArrowDown: 1, PageDown: 1 }[ev.key];
      if (!steps) return;
      ev.preventDefault();
      this.scroll(axis, steps);
    });
    return state;
  }

  setEdges(pane, e) {
    for (const side of ["left", "right", "top", "bottom"]) pane.element.querySelector(`.edge.${side}`).textContent = e[side];
  }

  // Edge letters from core/orientation.js where it gives them (the file's axes when the
  // orientation is unknown), else the radiologist's anatomical letters.
  showEdges() {
    const fn = orientation.paneEdgeLetters;
    const said = this.orientationLetters;
    let letters = said && said.volume === (this.session.volume?.name ?? null) ? said.panes : null;
    if (!letters && typeof fn === "function" && this.session.volume) {
      try { letters = fn(this.session.volume, this.correction); } catch { letters = null; }
    }
    // Without core/orientation.js's letters (no volume yet) the edges say nothing.
    const none = { left: "", right: "", top: "", bottom: "" };
    for (const axis of SLICE_AXES) this.setEdges(this.panes[axis], letters?.[axis] ?? (typeof fn === "function" ? none : EDGES[axis]));
  }

  // Step the crosshair `steps` slices along `axis`'s normal (positive: down the wheel, away
  // from the plane's top-left normal), within the volume.
  scroll(axis, steps) {
    const pane = this.panes[axis];
    const volume = this.session.volume;
    if (!pane.header || !volume?.dims) return;
    const normal = sliceNormal(pane.header);
    const corners = cropCorners(cropGeometry(volume, this.correction), FULL_CROP);
    const along = corners.map((p) => vec3.dot(p, normal));
    const step = spacingAlong(volume, normal);
    // The outermost planes through sample centres: half a cell inside the cell box.
    const lo = Math.min(...along) + step / 2, hi = Math.max(...along) - step / 2;
    const from = this.point ?? pane.header.point;
    this.setPoint(scrolledPoint(from, normal, steps, step, Math.min(lo, hi), Math.max(lo, hi)));
  }

  setSlab(change) {
    this.slab = { ...this.slab, ...change };
    this.slabInputs.thickness.value = String(this.slab.thickness);
    this.slabInputs.mode.value = this.slab.mode;
    this.requestAll();
  }

  onOpened(restored) {
    this.generation++;
    if (!restored) {
      // The new volume's centre at once: an answer about the previous volume still on its
      // way must not put its centre back (it is dropped by generation below).
      const v = this.session.volume;
      this.point = v?.dims ? cropGeometry(v, this.correction).center : null;
      if (this.point) this.showPoint();
      this.wl = defaultWindowLevel(v);
      for (const pane of Object.values(this.panes)) { pane.header = null; pane.image = null; }
    }
    this.showWindowLevel();
    this.showEdges();
    this.requestAll();
    this.drawMarker();
  }

  showWindowLevel() {
    this.inputs.window.value = +this.wl.window.toPrecision(6);
    this.inputs.level.value = +this.wl.level.toPrecision(6);
  }

  showPoint() {
    this.pointText.textContent = `(${this.point.map((v) => v.toFixed(1)).join(", ")}) mm`;
  }

  // Move the crosshair: a pane whose plane the point leaves re-slices, the others (the point
  // moved within their plane) only move their lines.
  setPoint(point) {
    const old = this.point;
    this.point = point;
    this.showPoint();
    for (const axis of SLICE_AXES) {
      const pane = this.panes[axis];
      const moved = !pane.header || !old ? true
        : Math.abs(vec3.dot(vec3.sub(point, pane.header.point), sliceNormal(pane.header))) > 1e-9;
      if (moved) this.request(pane); else this.draw(pane);
    }
    this.drawMarker();
  }

  requestAll() {
    for (const axis of SLICE_AXES) this.request(this.panes[axis]);
  }

  request(pane) {
    if (!this.session.volume || !this.session.ready) return;
    if (pane.inFlight) { pane.dirty = true; return; }
    const rect = pane.canvas.getBoundingClientRect();
    const dpr = globalThis.devicePixelRatio || 1;
    const side = (v) => Math.max(1, Math.min(MAX_SLICE_SIDE, Math.round(v * dpr)));
    if (rect.width < 2 || rect.height < 2) return;
    const options = { window: this.wl.window, level: this.wl.level, slab: this.slab };
    if (this.point) options.point = this.point;
    let id;
    try {
      id = this.session.connection.send(requests.slice(pane.axis, side(rect.width), side(rect.height), options));
    } catch {
      return;   // not connected: the next `opened` asks again
    }
    pane.inFlight = true;
    pane.dirty = false;
    this.requestsById.set(id, { axis: pane.axis, generation: this.generation });
  }

  onSlice({ header, pixels }) {
    const asked = this.requestsById.get(header.request);
    if (!asked) return;
    this.requestsById.delete(header.request);
    const pane = this.panes[asked.axis];
    pane.inFlight = false;
    if (asked.generation !== this.generation) {   // cut from the volume before this one
      this.request(pane);
      return;
    }
    const image = new ImageData(header.width, header.height);
    for (let i = 0; i < pixels.length; i++) {
      const g = pixels[i];
      image.data[4 * i] = image.data[4 * i + 1] = image.data[4 * i + 2] = g;
      image.data[4 * i + 3] = 255;
    }
    pane.header = header;
    pane.image = image;
    pane.bitmap = null;
    delete pane.element.dataset.error;
    if (!this.point) { this.point = header.point; this.showPoint(); this.drawMarker(); }   // the server's default: the centre
    this.draw(pane);
    if (pane.dirty) this.request(pane);
  }

  onError(e) {
    if (e.request_type !== "slice" || !this.requestsById.has(e.id)) return;
    const pane = this.panes[this.requestsById.get(e.id).axis];
    this.requestsById.delete(e.id);
    pane.inFlight = false;
    pane.element.dataset.error = e.message ?? e.code;
    if (pane.dirty) this.request(pane);
  }

  // The slice image is drawn centred at its own aspect in the canvas: scale and offset.
  fitOf(pane) {
    const rect = pane.canvas.getBoundingClientRect();
    return paneFit(pane.header, rect.width, rect.height);
  }

  redraw() { for (const axis of SLICE_AXES) this.draw(this.panes[axis]); }

  draw(pane) {
    if (!pane.header) return;
    const canvas = pane.canvas;
    const rect = canvas.getBoundingClientRect();
    const dpr = globalThis.devicePixelRatio || 1;
    canvas.width = Math.max(1, Math.round(rect.width * dpr));
    canvas.height = Math.max(1, Math.round(rect.height * dpr));
    const ctx = canvas.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.fillStyle = "#000";
    ctx.fillRect(0, 0, rect.width, rect.height);
    const fit = paneFit(pane.header, rect.width, rect.height);
    if (!pane.bitmap) {
      pane.bitmap = this.doc.createElement("canvas");
      pane.bitmap.width = pane.header.width;
      pane.bitmap.height = pane.header.height;
      pane.bitmap.getContext("2d").putImageData(pane.image, 0, 0);
    }
    ctx.imageSmoothingEnabled = true;
    ctx.drawImage(pane.bitmap, fit.x, fit.y, pane.header.width * fit.scale, pane.header.height * fit.scale);
    if (this.point) {
      const { c, r } = pixelOf(pane.header, this.point);
      const { x, y } = pixelToPane(fit, c, r);
      ctx.strokeStyle = "rgba(80, 220, 120, 0.85)";
      ctx.lineWidth = 1;
      ctx.beginPath();
      ctx.moveTo(0, y); ctx.lineTo(rect.width, y);
      ctx.moveTo(x, 0); ctx.lineTo(x, rect.height);
      ctx.stroke();
      pane.element.dataset.crosshair = `${x.toFixed(1)},${y.toFixed(1)}`;
    }
    for (const tool of this.tools) {
      ctx.save();
      try { tool.draw(pane, ctx, fit); } finally { ctx.restore(); }
    }
  }

  // The crosshair point over the 3D view.
  drawMarker() {
    const rect = this.viewElement.getBoundingClientRect();
    const dpr = globalThis.devicePixelRatio || 1;
    const m = this.marker;
    m.width = Math.max(1, Math.round(rect.width * dpr));
    m.height = Math.max(1, Math.round(rect.height * dpr));
    const ctx = m.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, rect.width, rect.height);
    const camera = this.camera ?? this.session.scene?.camera;
    const at = this.point && camera ? projectToView(camera, this.point, rect.width, rect.height) : null;
    this.markerAt = at;
    if (!at) return;
    ctx.strokeStyle = "rgba(80, 220, 120, 0.95)";
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.arc(at.x, at.y, 6, 0, 2 * Math.PI);
    ctx.moveTo(at.x - 12, at.y); ctx.lineTo(at.x - 4, at.y);
    ctx.moveTo(at.x + 4, at.y); ctx.lineTo(at.x + 12, at.y);
    ctx.moveTo(at.x, at.y - 12); ctx.lineTo(at.x, at.y - 4);
    ctx.moveTo(at.x, at.y + 4); ctx.lineTo(at.x, at.y + 12);
    ctx.stroke();
  }
}
