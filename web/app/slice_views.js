// Three orthogonal slices beside the 3D view — axial, coronal, sagittal in the patient
// frame — rendered by the server (protocol/README.md, `slice`), with window/level and a
// crosshair: clicking or dragging in one pane moves the point the other two pass through,
// and the point is drawn over the 3D view, projected with the camera the frame on screen
// was rendered with.
//
// One request per pane in flight; a pane that needs a new image while waiting asks again
// when the answer comes (latest wins, as the server does for frames). Slices answer only
// their own requests and never change the 3D scene.

import { requests } from "../core/protocol.js";

export const SLICE_AXES = Object.freeze(["axial", "coronal", "sagittal"]);
const LABELS = { axial: "Axial", coronal: "Coronal", sagittal: "Sagittal" };
// Edge letters (LPS world): the patient's right is on the image's left (radiological).
const EDGES = {
  axial: { left: "R", right: "L", top: "A", bottom: "P" },
  coronal: { left: "R", right: "L", top: "S", bottom: "I" },
  sagittal: { left: "A", right: "P", top: "S", bottom: "I" },
};
const MAX_SLICE_SIDE = 512;    // px requested per pane: sharp on a laptop, cheap on the server
// CT in Hounsfield units (air near −1000): a soft-tissue window; anything else: its range.
const CT_WINDOW = { window: 400, level: 40 };

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const norm = (a) => { const l = Math.hypot(...a) || 1; return [a[0] / l, a[1] / l, a[2] / l]; };

// The window/level slices start with, in the volume's own units.
export function defaultWindowLevel(volume) {
  const [lo, hi] = volume?.value_range ?? [0, 1];
  if (lo <= -900 && hi >= 300) return { ...CT_WINDOW };
  return hi > lo ? { window: hi - lo, level: (lo + hi) / 2 } : { window: 1, level: lo };
}

// Pixel (fractional, centre-based) of a world point on a slice, and back.
export function pixelOf(header, p) {
  const d = sub(p, header.origin);
  return { c: dot(d, header.column) / header.pixel_spacing, r: dot(d, header.row) / header.pixel_spacing };
}
export function worldOf(header, c, r) {
  const s = header.pixel_spacing;
  return [0, 1, 2].map((i) => header.origin[i] + c * s * header.column[i] + r * s * header.row[i]);
}

// A world point in the 3D view's CSS pixels, with docs/design.md's camera (image x along
// forward × up, y up, row 0 at the top); null behind the eye.
export function projectToView(camera, p, width, height) {
  const forward = norm(sub(camera.target, camera.eye));
  const right = norm(cross(forward, camera.up));
  const up = cross(right, forward);
  const v = sub(p, camera.eye);
  const z = dot(v, forward);
  let halfH;
  if (camera.projection === "orthographic") {
    halfH = camera.height / 2;
  } else {
    if (z <= 0) return null;
    halfH = z * Math.tan((camera.fov_y_deg * Math.PI) / 360);
  }
  const halfW = halfH * (width / height);
  return { x: (dot(v, right) / halfW + 1) * width / 2, y: (1 - dot(v, up) / halfH) * height / 2 };
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
    this.panes = {};
    this.camera = null;                // the camera of the 3D frame on screen
    this.requestsById = new Map();     // id -> axis

    container.classList.add("slices");
    container.innerHTML = "";
    const bar = doc.createElement("div");
    bar.className = "slices-bar";
    bar.innerHTML = `<label>W <input type="number" step="any" min="0" data-wl="window" aria-label="Slice window"></label>
      <label>L <input type="number" step="any" data-wl="level" aria-label="Slice level"></label>
      <span class="slices-point muted small" aria-live="polite"></span>`;
    container.appendChild(bar);
    this.inputs = { window: bar.querySelector('[data-wl="window"]'), level: bar.querySelector('[data-wl="level"]') };
    this.pointText = bar.querySelector(".slices-point");
    for (const key of ["window", "level"]) {
      this.inputs[key].addEventListener("change", () => {
        const v = Number(this.inputs[key].value);
        if (!Number.isFinite(v) || (key === "window" && !(v > 0))) { this.showWindowLevel(); return; }
        this.wl = { ...this.wl, [key]: v };
        this.requestAll();
      });
    }
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
    this.correction = "null";
    session.on("policy", (policy) => {
      const correction = JSON.stringify(policy.quality?.orientation_correction ?? null);
      if (correction === this.correction) return;
      this.correction = correction;
      this.requestAll();
    });
    session.on("frame", (f) => { if (f.header.camera) { this.camera = f.header.camera; this.drawMarker(); } });
    new ResizeObserver(() => this.requestAll()).observe(container);
  }

  makePane(axis) {
    const pane = this.doc.createElement("div");
    pane.className = "slice-pane";
    pane.dataset.axis = axis;
    const canvas = this.doc.createElement("canvas");
    canvas.tabIndex = 0;
    canvas.setAttribute("aria-label", `${LABELS[axis]} slice: click or drag to move the crosshair`);
    pane.appendChild(canvas);
    const e = EDGES[axis];
    pane.insertAdjacentHTML("beforeend", `<span class="slice-label">${LABELS[axis]}</span>
      <span class="edge left">${e.left}</span><span class="edge right">${e.right}</span>
      <span class="edge top">${e.top}</span><span class="edge bottom">${e.bottom}</span>`);
    this.container.appendChild(pane);
    const state = { axis, element: pane, canvas, header: null, image: null, inFlight: false, dirty: false };
    const pick = (ev) => {
      if (!state.header) return;
      const rect = canvas.getBoundingClientRect();
      const fit = this.fitOf(state, rect.width, rect.height);
      const c = (ev.clientX - rect.left - fit.x) / fit.scale - 0.5;
      const r = (ev.clientY - rect.top - fit.y) / fit.scale - 0.5;
      this.setPoint(worldOf(state.header, c, r), axis);
    };
    canvas.addEventListener("pointerdown", (ev) => {
      canvas.setPointerCapture(ev.pointerId);
      state.dragging = true;
      pick(ev);
    });
    canvas.addEventListener("pointermove", (ev) => { if (state.dragging) pick(ev); });
    const end = () => { state.dragging = false; };
    canvas.addEventListener("pointerup", end);
    canvas.addEventListener("pointercancel", end);
    return state;
  }

  onOpened(restored) {
    if (!restored) {
      this.point = null;
      this.wl = defaultWindowLevel(this.session.volume);
    }
    this.showWindowLevel();
    this.requestAll();
  }

  showWindowLevel() {
    this.inputs.window.value = +this.wl.window.toPrecision(6);
    this.inputs.level.value = +this.wl.level.toPrecision(6);
  }

  // Move the crosshair; the pane it was picked in keeps its plane, the other two follow.
  setPoint(point, from = null) {
    this.point = point;
    this.pointText.textContent = `(${point.map((v) => v.toFixed(1)).join(", ")}) mm`;
    for (const axis of SLICE_AXES) {
      if (axis === from) this.draw(this.panes[axis]);
      else this.request(this.panes[axis]);
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
    const options = { window: this.wl.window, level: this.wl.level };
    if (this.point) options.point = this.point;
    let id;
    try {
      id = this.session.connection.send(requests.slice(pane.axis, side(rect.width), side(rect.height), options));
    } catch {
      return;   // not connected: the next `opened` asks again
    }
    pane.inFlight = true;
    pane.dirty = false;
    this.requestsById.set(id, pane.axis);
  }

  onSlice({ header, pixels }) {
    const axis = this.requestsById.get(header.request);
    if (!axis) return;
    this.requestsById.delete(header.request);
    const pane = this.panes[axis];
    pane.inFlight = false;
    const image = new ImageData(header.width, header.height);
    for (let i = 0; i < pixels.length; i++) {
      const g = pixels[i];
      image.data[4 * i] = image.data[4 * i + 1] = image.data[4 * i + 2] = g;
      image.data[4 * i + 3] = 255;
    }
    pane.header = header;
    pane.image = image;
    if (!this.point) this.setPoint(header.point, axis);   // the server's default: the centre
    this.draw(pane);
    if (pane.dirty) this.request(pane);
  }

  onError(e) {
    if (e.request_type !== "slice" || !this.requestsById.has(e.id)) return;
    const pane = this.panes[this.requestsById.get(e.id)];
    this.requestsById.delete(e.id);
    pane.inFlight = false;
    pane.element.dataset.error = e.message ?? e.code;
  }

  // The slice image is drawn centred at its own aspect in the canvas: scale and offset.
  fitOf(pane, width, height) {
    const h = pane.header;
    const scale = Math.min(width / h.width, height / h.height);
    return { scale, x: (width - h.width * scale) / 2, y: (height - h.height * scale) / 2 };
  }

  draw(pane) {
    if (!pane.header) return;
    delete pane.element.dataset.error;
    const canvas = pane.canvas;
    const rect = canvas.getBoundingClientRect();
    const dpr = globalThis.devicePixelRatio || 1;
    canvas.width = Math.max(1, Math.round(rect.width * dpr));
    canvas.height = Math.max(1, Math.round(rect.height * dpr));
    const ctx = canvas.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.fillStyle = "#000";
    ctx.fillRect(0, 0, rect.width, rect.height);
    const fit = this.fitOf(pane, rect.width, rect.height);
    const bitmap = this.doc.createElement("canvas");
    bitmap.width = pane.header.width;
    bitmap.height = pane.header.height;
    bitmap.getContext("2d").putImageData(pane.image, 0, 0);
    ctx.imageSmoothingEnabled = true;
    ctx.drawImage(bitmap, fit.x, fit.y, pane.header.width * fit.scale, pane.header.height * fit.scale);
    if (!this.point) return;
    const { c, r } = pixelOf(pane.header, this.point);
    const x = fit.x + (c + 0.5) * fit.scale, y = fit.y + (r + 0.5) * fit.scale;
    ctx.strokeStyle = "rgba(80, 220, 120, 0.85)";
    ctx.lineWidth = 1;
    ctx.beginPath();
    ctx.moveTo(0, y); ctx.lineTo(rect.width, y);
    ctx.moveTo(x, 0); ctx.lineTo(x, rect.height);
    ctx.stroke();
    pane.element.dataset.crosshair = `${x.toFixed(1)},${y.toFixed(1)}`;
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
