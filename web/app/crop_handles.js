// The crop box drawn where the user looks: its edges and six face handles over the 3D view
// (projected with the camera of the frame on screen), and where it cuts each slice pane's
// plane, with a handle on every face that crosses the pane. Dragging a handle moves that
// face (core/measure.js's movedCrop: along the face's own axis only) and goes as a crop
// slider's drag does (app/crop_panel.js's setFromHandle: interaction_start, quality.crop at
// most once per animation frame while it moves, interaction_end and the final crop on release).
//
// *Handles* in the crop card turns them on; the box's outline shows on the slices whenever
// the crop is not the whole volume.

import { BOX_EDGES, cropCorners, cropFaces, cropGeometry, cropHandlesOnSlice, cropOnSlice, dragAlong,
  movedCrop, paneToWorld, pixelToPane, projectToView, vec3 } from "../core/measure.js";

const GRAB_PX = 9;          // a press this close to a handle's centre (CSS px) takes it
const HANDLE_PX = 5;        // half the side of a handle's square
const COLOR = "rgba(255, 170, 40, 0.95)";

const isFull = (crop) => crop.min.every((v) => v === 0) && crop.max.every((v) => v === 1);

export class CropHandles {
  // crop: the CropPanel; slices: the SliceViews; viewElement: #view.
  constructor(doc, session, crop, slices, viewElement) {
    this.doc = doc;
    this.session = session;
    this.crop = crop;
    this.slices = slices;
    this.viewElement = viewElement;
    this.enabled = false;
    this.camera = null;
    this.drag = null;

    const row = doc.createElement("div");
    row.className = "row";
    row.innerHTML = `<label title="Drag the crop box's faces in the 3D view and the slice panes"><input id="crop-handles" type="checkbox"> Handles in the view and slices</label>`;
    crop.card.querySelector("#crop-reset").before(row);
    this.toggle = row.querySelector("#crop-handles");
    this.toggle.addEventListener("change", () => this.setEnabled(this.toggle.checked));

    this.overlay = doc.createElement("canvas");
    this.overlay.className = "measure-3d crop-handles-3d";
    this.overlay.setAttribute("aria-hidden", "true");
    viewElement.appendChild(this.overlay);

    slices.addTool(this);
    crop.onShown(() => { this.draw3d(); slices.redraw(); });
    session.on("frame", (f) => { if (f.header.camera) { this.camera = f.header.camera; this.draw3d(); } });
    session.on("opened", () => { this.draw3d(); });
    this.bindView();
  }

  setEnabled(on) {
    this.enabled = on;
    this.toggle.checked = on;
    this.draw3d();
    this.slices.redraw();
  }

  geometry() {
    const v = this.session.volume;
    if (!v?.dims) return null;
    return cropGeometry(v, this.session.policy?.quality?.orientation_correction ?? null);
  }

  viewSize() {
    const r = this.viewElement.getBoundingClientRect();
    return { width: r.width, height: r.height, left: r.left, top: r.top };
  }

  // The six handles in the 3D view's CSS px.
  handles3d() {
    const g = this.geometry();
    const camera = this.camera ?? this.session.scene?.camera;
    if (!g || !camera) return [];
    const { width, height } = this.viewSize();
    return cropFaces(g, this.crop.crop).map((f) => ({ ...f, at: projectToView(camera, f.point, width, height) })).filter((f) => f.at);
  }

  // --- the 3D view ------------------------------------------------------------------------------

  bindView() {
    // Capture on the view's element: a press on a handle never reaches the canvas's orbit.
    this.viewElement.addEventListener("pointerdown", (ev) => {
      if (!this.enabled || ev.button !== 0) return;
      const s = this.viewSize();
      const x = ev.clientX - s.left, y = ev.clientY - s.top;
      let best = null, bestD = GRAB_PX;
      for (const h of this.handles3d()) {
        const d = Math.hypot(h.at.x - x, h.at.y - y);
        if (d <= bestD) { best = h; bestD = d; }
      }
      if (!best) return;
      ev.stopPropagation();
      ev.preventDefault();
      this.drag = { face: best, start: { x: ev.clientX, y: ev.clientY }, crop: this.crop.crop, camera: this.camera ?? this.session.scene.camera, size: s };
      this.overlay.dataset.dragging = `${best.axis}-${best.side}`;
    }, true);
    const move = (ev, final) => {
      const d = this.drag;
      if (!d) return;
      const g = this.geometry();
      if (!g) return;
      const disp = dragAlong(d.camera, d.face.point, g.axes[d.face.axis], ev.clientX - d.start.x, ev.clientY - d.start.y, d.size.width, d.size.height);
      this.crop.setFromHandle(movedCrop(g, d.crop, d.face, disp), !final);
    };
    globalThis.addEventListener("pointermove", (ev) => move(ev, false));
    globalThis.addEventListener("pointerup", (ev) => {
      if (!this.drag) return;
      move(ev, true);
      this.drag = null;
      delete this.overlay.dataset.dragging;
    });
  }

  draw3d() {
    const { width, height } = this.viewSize();
    const dpr = globalThis.devicePixelRatio || 1;
    const c = this.overlay;
    c.width = Math.max(1, Math.round(width * dpr));
    c.height = Math.max(1, Math.round(height * dpr));
    const ctx = c.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, width, height);
    this.shown3d = [];
    const g = this.geometry();
    const camera = this.camera ?? this.session.scene?.camera;
    if (!this.enabled || !g || !camera) return;
    const corners = cropCorners(g, this.crop.crop).map((p) => projectToView(camera, p, width, height));
    ctx.strokeStyle = COLOR;
    ctx.lineWidth = 1;
    ctx.setLineDash([4, 3]);
    ctx.beginPath();
    for (const [i, j] of BOX_EDGES) {
      if (!corners[i] || !corners[j]) continue;
      ctx.moveTo(corners[i].x, corners[i].y);
      ctx.lineTo(corners[j].x, corners[j].y);
    }
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.fillStyle = COLOR;
    for (const h of this.handles3d()) {
      ctx.fillRect(h.at.x - HANDLE_PX, h.at.y - HANDLE_PX, 2 * HANDLE_PX, 2 * HANDLE_PX);
      this.shown3d.push({ axis: h.axis, side: h.side, x: h.at.x, y: h.at.y });
    }
  }

  // --- slice panes (a SliceViews tool) -------------------------------------------------------------

  pointerDown(pane, at) {
    if (!this.enabled) return null;
    const g = this.geometry();
    if (!g) return null;
    const fit = this.slices.fitOf(pane);
    let best = null, bestD = GRAB_PX;
    for (const h of cropHandlesOnSlice(pane.header, g, this.crop.crop)) {
      const p = pixelToPane(fit, h.pixel.c, h.pixel.r);
      const d = Math.hypot(p.x - at.x, p.y - at.y);
      if (d <= bestD) { best = h; bestD = d; }
    }
    if (!best) return null;
    const header = pane.header, start = paneToWorld(header, fit, at.x, at.y), crop = this.crop.crop;
    const to = (p, final) => this.crop.setFromHandle(movedCrop(g, crop, best, vec3.sub(paneToWorld(header, fit, p.x, p.y), start)), !final);
    return { move: (p) => to(p, false), end: (p) => to(p ?? at, true) };
  }

  draw(pane, ctx, fit) {
    const g = this.geometry();
    const crop = this.crop.crop;
    if (!g || (!this.enabled && isFull(crop))) return;
    const poly = cropOnSlice(pane.header, cropCorners(g, crop));
    if (poly.length < 3) return;
    ctx.strokeStyle = COLOR;
    ctx.lineWidth = 1;
    ctx.setLineDash([4, 3]);
    ctx.beginPath();
    poly.forEach((p, i) => { const q = pixelToPane(fit, p.c, p.r); if (i) ctx.lineTo(q.x, q.y); else ctx.moveTo(q.x, q.y); });
    ctx.closePath();
    ctx.stroke();
    ctx.setLineDash([]);
    if (!this.enabled) return;
    ctx.fillStyle = COLOR;
    for (const h of cropHandlesOnSlice(pane.header, g, crop)) {
      const q = pixelToPane(fit, h.pixel.c, h.pixel.r);
      ctx.fillRect(q.x - HANDLE_PX, q.y - HANDLE_PX, 2 * HANDLE_PX, 2 * HANDLE_PX);
    }
  }
}
