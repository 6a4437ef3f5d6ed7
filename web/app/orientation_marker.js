// The orientation marker (labelled patient axes L/R, A/P, S/I in the view's corner, turning
// with the camera), the six standard views, and, where the file names no patient space, an
// "orientation unknown" note with controls that turn the view. The turns are camera changes:
// the session keeps them and a saved scene holds them in its camera. The flips and quarter
// turns of the volume itself (a mirror no camera move can give) are the scene's
// quality.orientation_correction: they travel with the quality policy, so the session keeps
// them and a saved scene holds them. Offered first where the file names no patient axes; for
// a file that does, they sit behind "Override the file's orientation".
//
// The module builds its own elements (a canvas over the view, a card in the side panel) and
// follows the session's camera from the `scene` events and the frames, so the page only
// constructs it and hands it the volume and a way to set the camera.

import {
  composeCorrection, CORRECTION_STEPS, describeCorrection, IDENTITY_CORRECTION, isIdentityCorrection,
  projectAxes, rollCamera, screenLabels, standardViewCamera, STANDARD_VIEWS,
} from "../core/orientation.js";

const MARKER_CSS_PX = 96;          // the marker's side, CSS pixels
const AXIS_COLORS = { L: "#e5534b", R: "#e5534b", A: "#3fbf6f", P: "#3fbf6f", S: "#3fb6c8", I: "#3fb6c8" };
// Where the file names no patient space the axes are the file's own.
const FILE_AXIS_LABELS = { L: "+x", R: "−x", P: "+y", A: "−y", S: "+z", I: "−z" };

const STYLE = `
.orientation-marker { position: absolute; right: 10px; bottom: 34px; width: ${MARKER_CSS_PX}px; height: ${MARKER_CSS_PX}px;
  pointer-events: none; background: rgba(11, 14, 18, 0.45); border-radius: 50%; }
.orientation-note { position: absolute; left: 50%; top: 10px; transform: translateX(-50%); padding: 3px 10px;
  border-radius: 10px; background: rgba(90, 64, 10, 0.9); border: 1px solid var(--warn, #e0a73a); color: #ffe6b0;
  font-size: 12px; pointer-events: none; }
.orientation-note[hidden] { display: none; }
.standard-views { display: grid; grid-template-columns: repeat(3, 1fr); gap: 4px; margin: 6px 0; }
.standard-views button, .orientation-turns button { padding: 3px 4px; }
.orientation-turns { display: flex; gap: 4px; flex-wrap: wrap; margin-top: 6px; }
.orientation-turns[hidden] { display: none; }
.orientation-fix { margin-top: 6px; }
.orientation-fix summary { cursor: pointer; }
.orientation-fix-buttons { display: grid; grid-template-columns: repeat(3, 1fr); gap: 4px; margin: 6px 0 4px; }
.orientation-fix-buttons button, .orientation-fix > button { padding: 3px 4px; }
.orientation-fix-status.overrides { color: var(--warn, #e0a73a); }
`;

export class OrientationControls {
  // options: setCamera(camera) sends a camera as a navigation step would; getCamera() the
  // camera being navigated; getTarget() the volume's centre (the starting view's target);
  // onCorrection() after the user changed the orientation correction (the page sends the
  // quality policy, which decorate() completes); onCorrectionShown(matrix) after every
  // change of the correction shown, the user's or the server's (the clip slider's box).
  constructor(doc, session, { setCamera, getCamera, getTarget, onCorrection = () => {}, onCorrectionShown = () => {} }) {
    this.doc = doc;
    this.session = session;
    this.setCamera = setCamera;
    this.getCamera = getCamera;
    this.getTarget = getTarget;
    this.onCorrection = onCorrection;
    this.onCorrectionShown = onCorrectionShown;
    this.correction = IDENTITY_CORRECTION;
    this.known = true;
    this.hasVolume = false;
    this.camera = null;
    this.build();
    session.on("scene", ({ key, value }) => { if (key === "camera") this.showCamera(value); });
    session.on("frame", (f) => { if (f.header?.camera && !this.camera) this.showCamera(f.header.camera); });
  }

  build() {
    const doc = this.doc;
    const style = doc.createElement("style");
    style.textContent = STYLE;
    doc.head.append(style);

    const view = doc.getElementById("view");
    this.canvas = Object.assign(doc.createElement("canvas"), { id: "orientation-marker", className: "orientation-marker" });
    this.canvas.setAttribute("role", "img");
    this.note = Object.assign(doc.createElement("div"), {
      id: "orientation-note", className: "orientation-note", hidden: true,
      textContent: "Orientation unknown: the file names no patient axes; labels show the file's axes",
    });
    view.append(this.canvas, this.note);

    // The card, first in the side panel: views are what a reader reaches for first.
    const card = doc.createElement("details");
    card.className = "card";
    card.open = true;
    card.id = "orientation-card";
    const summary = Object.assign(doc.createElement("summary"), { textContent: "Orientation" });
    const views = Object.assign(doc.createElement("div"), { className: "standard-views" });
    for (const [name, v] of Object.entries(STANDARD_VIEWS)) {
      const b = Object.assign(doc.createElement("button"), { type: "button", textContent: v.label, id: `view-${name}` });
      b.title = `${v.label} view`;
      b.addEventListener("click", () => this.standardView(name));
      views.append(b);
    }
    this.turns = Object.assign(doc.createElement("div"), { className: "orientation-turns", id: "orientation-turns" });
    for (const [label, degrees, title] of [["⟲ 90°", -90, "Turn the image 90° anticlockwise"],
      ["⟳ 90°", 90, "Turn the image 90° clockwise"], ["180°", 180, "Turn the image upside down"]]) {
      const b = Object.assign(doc.createElement("button"), { type: "button", textContent: label, title });
      b.dataset.degrees = String(degrees);
      b.addEventListener("click", () => this.roll(degrees));
      this.turns.append(b);
    }
    this.status = Object.assign(doc.createElement("div"), { id: "orientation-status", className: "muted small" });

    // Flips and quarter turns of the volume: open where the orientation is unknown.
    this.fix = Object.assign(doc.createElement("details"), { id: "orientation-fix", className: "orientation-fix" });
    this.fixSummary = doc.createElement("summary");
    const buttons = Object.assign(doc.createElement("div"), { className: "orientation-fix-buttons" });
    for (const [name, step] of Object.entries(CORRECTION_STEPS)) {
      const b = Object.assign(doc.createElement("button"), { type: "button", textContent: step.label, id: `orientation-${name}`, title: step.title });
      b.addEventListener("click", () => this.correct(step.matrix));
      buttons.append(b);
    }
    const reset = Object.assign(doc.createElement("button"), {
      type: "button", id: "orientation-fix-reset", textContent: "As the file says", title: "Remove the flips and turns",
    });
    reset.addEventListener("click", () => this.setCorrection(IDENTITY_CORRECTION, { send: true }));
    this.fixStatus = Object.assign(doc.createElement("div"), { id: "orientation-fix-status", className: "orientation-fix-status small" });
    this.fix.append(this.fixSummary, buttons, reset, this.fixStatus);
    card.append(summary, views, this.status, this.turns, this.fix);
    const panel = doc.querySelector("aside.panel");
    panel.prepend(card);
    this.setVolume(null);
  }

  setVolume(volume) {
    this.known = volume ? volume.orientation_known !== false : true;
    this.note.hidden = !volume || this.known;
    this.turns.hidden = !volume || this.known;
    this.fix.hidden = !volume;
    this.fix.open = !!volume && !this.known;
    this.fixSummary.textContent = this.known ? "Override the file's orientation" : "Flip or turn the volume";
    this.hasVolume = !!volume;
    this.showCorrection();
    this.camera = null;
    this.draw();
  }

  // The correction a state or frame reports (its scene quality).
  showState(quality) {
    this.setCorrection(quality?.orientation_correction ?? IDENTITY_CORRECTION, { send: false });
  }

  correct(step) {
    if (!this.session.volume) return;
    this.setCorrection(composeCorrection(step, this.correction), { send: true });
  }

  setCorrection(matrix, { send }) {
    this.correction = matrix.map((row) => [...row]);
    this.showCorrection();
    this.onCorrectionShown(this.correction);
    if (send) this.onCorrection();
  }

  showCorrection() {
    const words = describeCorrection(this.correction);
    this.fixStatus.dataset.correction = JSON.stringify(this.correction);
    this.fixStatus.classList.toggle("overrides", this.known && !!words);
    this.fixStatus.textContent = !words ? "As the file places it."
      : this.known ? `Overrides the file's orientation: ${words}.`
        : `Corrected: ${words}. Kept by the session and saved with the scene.`;
    this.note.textContent = !words
      ? "Orientation unknown: the file names no patient axes; labels show the file's axes"
      : `Orientation unknown; corrected by hand (${words})`;
    // An override of a file's own axes is said where the views are explained, not only
    // in the closed "Override" panel.
    this.status.textContent = !this.hasVolume ? "" : !this.known
      ? "Orientation unknown: views follow the file's axes (x, y, z as if L, P, S). Turn the view to correct it."
      : words ? `The file names its patient axes, corrected by hand (${words}): views follow the corrected axes.`
        : "The file names its patient axes: views are anatomical.";
  }

  // quality.orientation_correction added to a quality object (left out when none, as the
  // server writes it).
  decorate(quality) {
    const q = { ...quality };
    if (isIdentityCorrection(this.correction)) delete q.orientation_correction;
    else q.orientation_correction = this.correction.map((row) => [...row]);
    return q;
  }

  standardView(name) {
    const camera = this.getCamera();
    if (!camera || !this.session.volume) return;
    this.setCamera(standardViewCamera(name, camera, this.getTarget() ?? camera.target));
  }

  roll(degrees) {
    const camera = this.getCamera();
    if (!camera || !this.session.volume) return;
    this.setCamera(rollCamera(camera, degrees));
  }

  showCamera(camera) {
    this.camera = camera;
    this.draw();
  }

  draw() {
    const c = this.canvas;
    const dpr = globalThis.devicePixelRatio || 1;
    const side = Math.round(MARKER_CSS_PX * dpr);
    if (c.width !== side) { c.width = side; c.height = side; }
    const g = c.getContext("2d");
    g.clearRect(0, 0, side, side);
    if (!this.camera) { c.hidden = true; return; }
    c.hidden = false;
    const axes = projectAxes(this.camera);
    const labels = screenLabels(this.camera);
    c.dataset.right = labels.right;
    c.dataset.up = labels.up;
    c.dataset.toward = labels.toward;
    c.setAttribute("aria-label", `Orientation: ${labels.right} to the right, ${labels.up} up, ${labels.toward} toward you`);
    const centre = side / 2, reach = side * 0.32;
    // Far axes first, so the near ones are drawn over them.
    for (const a of [...axes].sort((p, q) => q.depth - p.depth)) {
      const x = centre + a.x * reach, y = centre - a.y * reach;
      const near = a.depth <= 0;
      g.globalAlpha = near ? 1 : 0.45;
      g.strokeStyle = g.fillStyle = AXIS_COLORS[a.label];
      g.lineWidth = 2 * dpr;
      g.beginPath();
      g.moveTo(centre, centre);
      g.lineTo(x, y);
      g.stroke();
      const text = this.known ? a.label : FILE_AXIS_LABELS[a.label];
      g.font = `${near ? "bold " : ""}${Math.round(12 * dpr)}px system-ui, sans-serif`;
      g.textAlign = "center";
      g.textBaseline = "middle";
      const lx = centre + a.x * reach * 1.3, ly = centre - a.y * reach * 1.3;
      if (Math.hypot(a.x, a.y) > 0.2) g.fillText(text, lx, ly);
    }
    g.globalAlpha = 1;
  }
}
