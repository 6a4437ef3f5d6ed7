// Measurements on the slice panes and in the 3D view: a distance (mm) dragged on a pane, the
// value at a point (protocol/README.md's `probe`: HU where the server says the volume is CT
// in Hounsfield units, the data's own units otherwise), an ellipse ROI's mean, standard
// deviation, area, minimum and maximum (`roi_stats`), and points picked on the rendered
// surface (`pick`: where the ray's accumulated opacity first reaches one half), two of which
// give a distance in 3D.
//
// Geometry is core/measure.js's; the numbers shown are the server's (value, statistics,
// picked point) or computed from world points (distances), never from screen pixels.
// Each measurement stays drawn on its pane while the pane shows its plane; *Clear* removes them.

import { distanceMm, formatMm, formatRoi, formatValue, paneToWorld, pixelOf, pixelToPane, projectToView,
  roiFromCorners, sliceNormal, vec3 } from "../core/measure.js";

export const TOOLS = Object.freeze([
  { value: "crosshair", label: "Crosshair", title: "Click or drag in a pane to move the crosshair" },
  { value: "distance", label: "Distance", title: "Drag on a slice pane: the distance between the two ends, in mm" },
  { value: "probe", label: "Value", title: "Click on a slice pane: the volume's value there (HU for CT)" },
  { value: "roi", label: "ROI", title: "Drag an ellipse on a slice pane: mean, standard deviation, area, min and max inside it" },
  { value: "pick", label: "3D point", title: "Click on the 3D view: the point on the rendered surface; two points give a distance" },
]);

const ON_PLANE_MM = 1e-3;   // a measurement is drawn on a pane whose plane is this close to it (mm)
const CLICK_PX = 4;         // a press and release this close together is a click, not a drag
const COLOR = "#ffd27a";

export class MeasureTools {
  // slices: the SliceViews; viewElement: the 3D view's element (#view).
  constructor(doc, session, slices, viewElement) {
    this.doc = doc;
    this.session = session;
    this.slices = slices;
    this.viewElement = viewElement;
    this.mode = "crosshair";
    this.items = [];          // {kind, axis, p0, p1 | point, center, radii, text, answer}
    this.picked = [];         // 3D points picked on the surface (world mm), at most two
    this.last = null;         // the latest measurement, for the readout and the tests
    this.draft = null;        // the measurement being dragged

    const tools = doc.createElement("div");
    tools.className = "slices-tools";
    tools.setAttribute("role", "toolbar");
    tools.setAttribute("aria-label", "Measurement tools");
    for (const t of TOOLS) {
      const b = doc.createElement("button");
      b.type = "button";
      b.dataset.tool = t.value;
      b.textContent = t.label;
      b.title = t.title;
      b.setAttribute("aria-pressed", String(t.value === this.mode));
      b.addEventListener("click", () => this.setMode(t.value));
      tools.append(b);
    }
    const clear = doc.createElement("button");
    clear.type = "button";
    clear.dataset.tool = "clear";
    clear.textContent = "Clear";
    clear.title = "Remove the measurements";
    clear.addEventListener("click", () => this.clear());
    tools.append(clear);
    this.readout = doc.createElement("div");
    this.readout.className = "measure-readout";
    this.readout.setAttribute("aria-live", "polite");
    slices.bar.after(tools, this.readout);
    this.toolbar = tools;

    this.overlay = doc.createElement("canvas");
    this.overlay.className = "measure-3d";
    this.overlay.setAttribute("aria-hidden", "true");
    viewElement.appendChild(this.overlay);

    slices.addTool(this);
    this.bindView();
    session.on("frame", (f) => { if (f.header.camera) { this.camera = f.header.camera; this.draw3d(); } });
    session.on("opened", ({ restored }) => { if (!restored) this.clear(); });
  }

  setMode(mode) {
    this.mode = mode;
    for (const b of this.toolbar.querySelectorAll("button[data-tool]")) {
      if (b.dataset.tool !== "clear") b.setAttribute("aria-pressed", String(b.dataset.tool === mode));
    }
    this.viewElement.classList.toggle("picking", mode === "pick");
  }

  clear() {
    this.items = [];
    this.picked = [];
    this.last = null;
    this.draft = null;
    this.say("");
    this.slices.redraw();
    this.draw3d();
  }

  say(text) { this.readout.textContent = text; }

  // --- slice panes (SliceViews tool) --------------------------------------------------------

  pointerDown(pane, at) {
    if (!["distance", "probe", "roi"].includes(this.mode)) return null;
    const header = pane.header;
    const fit = this.slices.fitOf(pane);
    const world = (p) => paneToWorld(header, fit, p.x, p.y);
    const p0 = world(at);
    const draft = { kind: this.mode, axis: pane.axis, header, p0, p1: p0 };
    this.draft = draft;
    return {
      move: (p) => { draft.p1 = world(p); if (draft.kind !== "probe") this.slices.draw(pane); },
      end: (p) => {
        if (p) draft.p1 = world(p);
        this.draft = null;
        this.finish(draft, pane).catch((e) => this.say(`${draft.kind}: ${e.serverMessage ?? e.message}`));
      },
    };
  }

  async finish(d, pane) {
    const item = { kind: d.kind, axis: d.axis, plane: d.header, p0: d.p0, p1: d.p1 };
    if (d.kind === "distance") {
      item.mm = distanceMm(d.p0, d.p1);
      item.text = formatMm(item.mm);
      this.say(`Distance ${item.text}`);
    } else if (d.kind === "probe") {
      item.point = d.p1;
      item.p0 = item.p1 = d.p1;
      this.say("Value: asking the server…");
      item.answer = await this.session.probe(item.point);
      item.text = item.answer.inside ? formatValue(item.answer.value, item.answer.unit) : "outside the volume";
      this.say(`Value at (${item.point.map((v) => v.toFixed(1)).join(", ")}) mm: ${item.text}`);
    } else {
      const { center, radii } = roiFromCorners(d.header, d.p0, d.p1);
      item.center = center;
      item.radii = radii;
      if (!(radii[0] > 0 && radii[1] > 0)) { this.slices.draw(pane); return; }   // a click is no ellipse
      this.say("ROI: asking the server…");
      item.answer = await this.session.roiStats(d.axis, center, radii, "ellipse");
      item.text = formatRoi(item.answer);
      this.say(`ROI ${item.text}`);
    }
    this.items.push(item);
    this.last = item;
    this.slices.draw(pane);
  }

  // Draw the measurements lying in this pane's plane (and the one being dragged).
  draw(pane, ctx, fit) {
    const h = pane.header;
    const n = sliceNormal(h);
    const inPlane = (p) => Math.abs(vec3.dot(vec3.sub(p, h.origin), n)) < ON_PLANE_MM;
    const at = (p) => { const { c, r } = pixelOf(h, p); return pixelToPane(fit, c, r); };
    const list = this.items.filter((m) => m.axis === pane.axis && inPlane(m.p0));
    if (this.draft && this.draft.axis === pane.axis) list.push({ ...this.draft, text: this.draft.kind === "distance" ? formatMm(distanceMm(this.draft.p0, this.draft.p1)) : "" });
    ctx.strokeStyle = ctx.fillStyle = COLOR;
    ctx.lineWidth = 1.5;
    ctx.font = "11px system-ui, sans-serif";
    for (const m of list) {
      const a = at(m.p0), b = at(m.p1);
      ctx.beginPath();
      if (m.kind === "distance") {
        ctx.moveTo(a.x, a.y); ctx.lineTo(b.x, b.y);
        ctx.stroke();
        for (const q of [a, b]) { ctx.beginPath(); ctx.arc(q.x, q.y, 2.5, 0, 2 * Math.PI); ctx.fill(); }
        if (m.text) ctx.fillText(m.text, Math.max(a.x, b.x) + 5, (a.y + b.y) / 2);
      } else if (m.kind === "probe") {
        ctx.arc(b.x, b.y, 3, 0, 2 * Math.PI);
        ctx.stroke();
        if (m.text) ctx.fillText(m.text, b.x + 6, b.y - 4);
      } else {
        ctx.ellipse((a.x + b.x) / 2, (a.y + b.y) / 2, Math.abs(b.x - a.x) / 2, Math.abs(b.y - a.y) / 2, 0, 0, 2 * Math.PI);
        ctx.stroke();
        if (m.text) ctx.fillText(m.text.split(" · ")[0], Math.min(a.x, b.x), Math.max(a.y, b.y) + 12);
      }
    }
  }

  // --- the 3D view ----------------------------------------------------------------------------

  // In "3D point" mode a click (no drag) on the view picks; a drag still turns the view.
  bindView() {
    let down = null;
    this.viewElement.addEventListener("pointerdown", (ev) => {
      down = this.mode === "pick" && ev.button === 0 ? { x: ev.clientX, y: ev.clientY } : null;
    }, true);
    this.viewElement.addEventListener("pointerup", (ev) => {
      if (!down || this.mode !== "pick") return;
      const moved = Math.hypot(ev.clientX - down.x, ev.clientY - down.y);
      down = null;
      if (moved > CLICK_PX) return;
      const rect = this.viewElement.getBoundingClientRect();
      this.pickAt(ev.clientX - rect.left, ev.clientY - rect.top, rect.width, rect.height)
        .catch((e) => this.say(`3D point: ${e.serverMessage ?? e.message}`));
    }, true);
  }

  // Pick at CSS position (x, y) of a view width × height CSS px (the viewport's aspect).
  async pickAt(x, y, width, height) {
    if (!this.session.volume) return null;
    const answer = await this.session.pick(x, y, width, height);
    if (!answer.hit) {
      this.say("3D point: the ray meets nothing opaque there");
      this.last = { kind: "pick", answer };
      return answer;
    }
    if (this.picked.length >= 2) this.picked = [];
    this.picked.push(answer.point);
    const p = answer.point.map((v) => v.toFixed(1)).join(", ");
    if (this.picked.length === 2) {
      const mm = distanceMm(this.picked[0], this.picked[1]);
      this.last = { kind: "distance3d", points: this.picked.map((q) => [...q]), mm, text: formatMm(mm), answer };
      this.say(`3D distance ${formatMm(mm)} (second point (${p}) mm)`);
    } else {
      this.last = { kind: "pick", point: answer.point, answer };
      this.say(`3D point (${p}) mm, opacity ${answer.opacity.toFixed(2)}: click another for a distance`);
    }
    this.draw3d();
    return answer;
  }

  draw3d() {
    const rect = this.viewElement.getBoundingClientRect();
    const dpr = globalThis.devicePixelRatio || 1;
    const c = this.overlay;
    c.width = Math.max(1, Math.round(rect.width * dpr));
    c.height = Math.max(1, Math.round(rect.height * dpr));
    const ctx = c.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, rect.width, rect.height);
    const camera = this.camera ?? this.session.scene?.camera;
    if (!camera || !this.picked.length) return;
    const at = this.picked.map((p) => projectToView(camera, p, rect.width, rect.height));
    ctx.strokeStyle = ctx.fillStyle = COLOR;
    ctx.lineWidth = 2;
    ctx.font = "12px system-ui, sans-serif";
    for (const q of at) if (q) { ctx.beginPath(); ctx.arc(q.x, q.y, 4, 0, 2 * Math.PI); ctx.stroke(); }
    if (at.length === 2 && at[0] && at[1]) {
      ctx.beginPath();
      ctx.moveTo(at[0].x, at[0].y); ctx.lineTo(at[1].x, at[1].y);
      ctx.stroke();
      ctx.fillText(formatMm(distanceMm(this.picked[0], this.picked[1])), (at[0].x + at[1].x) / 2 + 6, (at[0].y + at[1].y) / 2);
    }
  }
}
