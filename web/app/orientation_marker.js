// The orientation marker (labelled patient axes L/R, A/P, S/I in the view's corner, turning
// with the camera), the six standard views, and, where the file names no patient space, an
// "orientation unknown" note with controls that turn the view. The turns are camera changes:
// the session keeps them and a saved scene holds them in its camera. The flips and quarter
// turns of the volume itself (a mirror no camera move can give) are the scene's
// quality.orientation_correction: they travel with the quality policy, so the session keeps
// them and a saved scene holds them. Offered first where the file names no patient axes; for
// a file that does, they sit behind "Override the file's orientation".
//
// Labels never claim anatomy the file does not name (core/orientation.js's anatomySource):
// for such a file the buttons, the marker and the note speak of the file's axes (+x, −y, …)
// until the user sets the patient axes by hand — a flip or turn of the volume, or "Treat as
// LPS" / "Treat as RAS" — and then say they were set by hand. Every change is announced on
// the document as a "volcast:orientation" event (detail: source, anatomical, setByHand,
// correction, panes: the slice panes' edge letters), for the slice panes and the saved image.
//
// The module builds its own elements (a canvas over the view, a card in the side panel) and
// follows the session's camera from the `scene` events and the frames, so the page only
// constructs it and hands it the volume and a way to set the camera.

import {
  anatomySource, composeCorrection, CORRECTION_STEPS, correctionStepLabel, describeCorrection, directionLabel,
  IDENTITY_CORRECTION, isAnatomical, isIdentityCorrection, paneEdgeLetters, projectAxes, rollCamera, screenLabels,
  standardViewCamera, standardViewLabel, STANDARD_VIEWS, TREAT_AS, treatAsOf,
} from "../core/orientation.js";

const MARKER_CSS_PX = 96;          // the marker's side, CSS pixels
const AXIS_COLORS = { L: "#e5534b", R: "#e5534b", A: "#3fbf6f", P: "#3fbf6f", S: "#3fb6c8", I: "#3fb6c8" };

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
.orientation-treat { display: grid; grid-template-columns: repeat(2, 1fr); gap: 4px; margin: 6px 0 4px; }
.orientation-treat[hidden] { display: none; }
.orientation-treat button { padding: 3px 4px; }
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
    this.setByHand = false;       // the user chose "Treat as …" (any other correction is by hand anyway)
    this.volume = null;
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
    this.viewButtons = {};
    for (const name of Object.keys(STANDARD_VIEWS)) {
      const b = Object.assign(doc.createElement("button"), { type: "button", id: `view-${name}` });
      b.addEventListener("click", () => this.standardView(name));
      views.append(b);
      this.viewButtons[name] = b;
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
    this.stepButtons = {};
    for (const [name, step] of Object.entries(CORRECTION_STEPS)) {
      const b = Object.assign(doc.createElement("button"), { type: "button", id: `orientation-${name}` });
      b.addEventListener("click", () => this.correct(step.matrix));
      buttons.append(b);
      this.stepButtons[name] = b;
    }
    // Where the file names no patient axes: say what its axes are, in one click.
    this.treat = Object.assign(doc.createElement("div"), { className: "orientation-treat", id: "orientation-treat" });
    for (const [key, t] of Object.entries(TREAT_AS)) {
      const b = Object.assign(doc.createElement("button"), { type: "button", id: `orientation-treat-${key}`, textContent: t.label, title: t.title });
      b.addEventListener("click", () => this.treatAs(key));
      this.treat.append(b);
    }
    const reset = Object.assign(doc.createElement("button"), {
      type: "button", id: "orientation-fix-reset", textContent: "As the file says", title: "Remove the flips and turns",
    });
    reset.addEventListener("click", () => { this.setByHand = false; this.setCorrection(IDENTITY_CORRECTION, { send: true }); });
    this.fixStatus = Object.assign(doc.createElement("div"), { id: "orientation-fix-status", className: "orientation-fix-status small" });
    this.fix.append(this.fixSummary, this.treat, buttons, reset, this.fixStatus);
    card.append(summary, views, this.status, this.turns, this.fix);
    const panel = doc.querySelector("aside.panel");
    panel.prepend(card);
    this.setVolume(null);
  }

  // keepHand: the same volume came back (a reconnection): the axes set by hand stay set.
  setVolume(volume, { keepHand = false } = {}) {
    if (!(keepHand && volume?.name === this.volume?.name)) this.setByHand = false;
    this.volume = volume;
    this.known = volume ? volume.orientation_known !== false : true;
    this.treat.hidden = !volume || this.known;
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

  // "Treat as LPS" / "Treat as RAS": the file's axes are the patient's, as chosen.
  treatAs(key) {
    if (!this.session.volume || this.known) return;
    this.setByHand = true;
    this.setCorrection(TREAT_AS[key].matrix, { send: true });
  }

  // The labels' source now: "file", "hand" or "axes" (core/orientation.js's anatomySource).
  get source() { return anatomySource(this.volume, this.correction, this.setByHand); }
  get anatomical() { return isAnatomical(this.source); }

  // What a view link or saved view carries: the correction and whether the axes were set by hand.
  orientationView() {
    return { correction: this.correction.map((row) => [...row]), setByHand: this.setByHand };
  }

  // A link's orientation, once its volume is open: shown, sent with the quality policy.
  applyOrientationView({ correction, setByHand }) {
    this.setByHand = !this.known && !!setByHand;
    this.setCorrection(correction ?? IDENTITY_CORRECTION, { send: true });
  }

  setCorrection(matrix, { send }) {
    this.correction = matrix.map((row) => [...row]);
    this.showCorrection();
    this.onCorrectionShown(this.correction);
    if (send) this.onCorrection();
  }

  showCorrection() {
    const words = describeCorrection(this.correction);
    const source = this.source, anatomical = isAnatomical(source);
    const treated = treatAsOf(this.correction, this.setByHand);
    // What was set by hand, in words: "the file's axes taken as RAS" or "flipped L/R".
    const hand = treated ? `the file's axes taken as ${treated.toUpperCase()}` : words;
    this.fixStatus.dataset.correction = JSON.stringify(this.correction);
    this.fixStatus.dataset.source = source;
    this.fixStatus.classList.toggle("overrides", this.known && !!words);
    this.fixStatus.textContent = source === "axes" ? "As the file places it; the patient axes are unknown."
      : this.known ? (words ? `Overrides the file's orientation: ${words}.` : "As the file places it.")
        : `Patient axes set by hand: ${hand}. Kept by the session, in links and saved scenes.`;
    this.note.textContent = source === "axes"
      ? "Orientation unknown: the file names no patient axes; labels show the file's axes"
      : `Patient axes set by hand (${hand}); the file names none`;
    // An override of a file's own axes is said where the views are explained, not only
    // in the closed "Override" panel.
    this.status.textContent = !this.hasVolume ? "" : source === "axes"
      ? "Orientation unknown: views and labels follow the file's own axes (x, y, z). Set the patient axes below: a flip, a turn, or Treat as LPS / RAS."
      : source === "hand" ? `The file names no patient axes; they were set by hand (${hand}): views and labels follow them.`
        : words ? `The file names its patient axes, corrected by hand (${words}): views follow the corrected axes.`
          : "The file names its patient axes: views are anatomical.";
    for (const [name, b] of Object.entries(this.viewButtons)) {
      const { label, title } = standardViewLabel(name, anatomical);
      Object.assign(b, { textContent: label, title });
    }
    // The flips and turns name what they act on: file axes until the patient axes are known.
    for (const [name, b] of Object.entries(this.stepButtons)) {
      const { label, title } = correctionStepLabel(name, anatomical);
      Object.assign(b, { textContent: label, title });
    }
    this.draw();
    this.doc.dispatchEvent(new CustomEvent("volcast:orientation", {
      detail: {
        source, anatomical, setByHand: this.setByHand, correction: this.correction.map((row) => [...row]),
        panes: paneEdgeLetters(this.volume, this.correction, this.setByHand),
      },
    }));
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
    const anatomical = this.anatomical;
    const labels = Object.fromEntries(Object.entries(screenLabels(this.camera)).map(([k, v]) => [k, directionLabel(v, anatomical)]));
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
      const text = directionLabel(a.label, anatomical);
      g.font = `${near ? "bold " : ""}${Math.round(12 * dpr)}px system-ui, sans-serif`;
      g.textAlign = "center";
      g.textBaseline = "middle";
      const lx = centre + a.x * reach * 1.3, ly = centre - a.y * reach * 1.3;
      if (Math.hypot(a.x, a.y) > 0.2) g.fillText(text, lx, ly);
    }
    g.globalAlpha = 1;
  }
}
