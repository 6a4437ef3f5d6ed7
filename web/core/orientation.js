// Patient orientation on the scene-file camera: the six standard views and the screen
// directions of the patient axes, for the orientation marker. Pure functions, no DOM.
//
// World space is LPS (docs/design.md): +x the patient's left, +y posterior, +z superior.
// Where the file names no patient space (volume object `orientation_known: false`) these
// are the file's own axes, and the page says the labels are a guess.

import { cameraFrame, vec } from "./camera.js";

// The six patient directions, as the marker labels them.
export const PATIENT_AXES = Object.freeze([
  { label: "L", dir: [1, 0, 0] }, { label: "R", dir: [-1, 0, 0] },
  { label: "P", dir: [0, 1, 0] }, { label: "A", dir: [0, -1, 0] },
  { label: "S", dir: [0, 0, 1] }, { label: "I", dir: [0, 0, -1] },
]);

// Each standard view: where the eye is (from the target) and which way is up in the image,
// as radiology shows them: the anterior view faces the patient (their left on the image's
// right), head up; superior and inferior views have anterior at the top.
export const STANDARD_VIEWS = Object.freeze({
  anterior: { label: "Anterior", eye: [0, -1, 0], up: [0, 0, 1] },
  posterior: { label: "Posterior", eye: [0, 1, 0], up: [0, 0, 1] },
  left: { label: "Left", eye: [1, 0, 0], up: [0, 0, 1] },
  right: { label: "Right", eye: [-1, 0, 0], up: [0, 0, 1] },
  superior: { label: "Superior", eye: [0, 0, 1], up: [0, -1, 0] },
  inferior: { label: "Inferior", eye: [0, 0, -1], up: [0, -1, 0] },
});

// The camera of a standard view around `target`, keeping the distance, projection and
// field of view of `camera`.
export function standardViewCamera(name, camera, target = camera.target) {
  const v = STANDARD_VIEWS[name];
  if (!v) throw new Error(`unknown standard view "${name}" (known: ${Object.keys(STANDARD_VIEWS).join(", ")})`);
  const distance = vec.length(vec.sub(camera.eye, camera.target)) || 1;
  return { ...camera, eye: vec.add(target, vec.scale(v.eye, distance)), target: [...target], up: [...v.up] };
}

// The camera turned about its view axis by `degrees` (positive: the image turns clockwise),
// for volumes whose orientation is unknown: the scene keeps the camera, so the turn is saved.
export function rollCamera(camera, degrees) {
  const { up, right } = cameraFrame(camera);
  const a = (degrees * Math.PI) / 180;
  // The image turns clockwise when the camera's up turns away from its right (a head tilted
  // clockwise sees the world turn anticlockwise).
  const newUp = vec.sub(vec.scale(up, Math.cos(a)), vec.scale(right, Math.sin(a)));
  return { ...camera, up: newUp.map((x) => (Math.abs(x) < 1e-12 ? 0 : Number(x.toPrecision(12)))) };
}

// Where each patient axis points on screen: x to the right, y up (unit length in the image
// plane when the axis lies in it), and depth (> 0: away from the viewer).
export function projectAxes(camera) {
  const { forward, right, up } = cameraFrame(camera);
  return PATIENT_AXES.map((a) => ({
    label: a.label,
    x: vec.dot(a.dir, right),
    y: vec.dot(a.dir, up),
    depth: vec.dot(a.dir, forward),
  }));
}

// The patient direction nearest the image's right, up and the viewer: the letters of the
// view ("the patient's left is on the right of the image").
export function screenLabels(camera) {
  const axes = projectAxes(camera);
  const best = (score) => axes.reduce((b, a) => (score(a) > score(b) ? a : b)).label;
  return { right: best((a) => a.x), up: best((a) => a.y), toward: best((a) => -a.depth) };
}

// The user's correction of where the volume lies in patient space: the scene's
// quality.orientation_correction, a signed permutation of the world axes (rows; flips and
// quarter turns only) applied about the volume's centre (renderer/model/orientation_correction.hpp).
// Each step below is one such matrix; pressing it again after others composes them.
export const IDENTITY_CORRECTION = Object.freeze([[1, 0, 0], [0, 1, 0], [0, 0, 1]]);

export const CORRECTION_STEPS = Object.freeze({
  "flip-lr": { label: "Flip L/R", title: "Mirror the volume left–right (no camera move can do this)", matrix: [[-1, 0, 0], [0, 1, 0], [0, 0, 1]] },
  "flip-ap": { label: "Flip A/P", title: "Mirror the volume front–back", matrix: [[1, 0, 0], [0, -1, 0], [0, 0, 1]] },
  "flip-si": { label: "Flip S/I", title: "Mirror the volume head–foot (upside down)", matrix: [[1, 0, 0], [0, 1, 0], [0, 0, -1]] },
  "turn-si": { label: "Turn 90° about S/I", title: "Turn the volume a quarter turn about the head–foot axis", matrix: [[0, -1, 0], [1, 0, 0], [0, 0, 1]] },
  "turn-ap": { label: "Turn 90° about A/P", title: "Turn the volume a quarter turn about the front–back axis", matrix: [[0, 0, 1], [0, 1, 0], [-1, 0, 0]] },
  "turn-lr": { label: "Turn 90° about L/R", title: "Turn the volume a quarter turn about the left–right axis", matrix: [[1, 0, 0], [0, 0, -1], [0, 1, 0]] },
});

// step · correction: the step applied after the correction so far.
export function composeCorrection(step, correction) {
  return step.map((row) => [0, 1, 2].map((c) => row.reduce((s, v, k) => s + v * correction[k][c], 0)));
}

export function isIdentityCorrection(m) {
  return !m || m.every((row, r) => row.every((v, c) => v === (r === c ? 1 : 0)));
}

// The axis-aligned box a volume is drawn in after the correction: `bounds` (camera.js's
// volumeBounds) turned by the signed permutation C about its centre, as the renderer places
// it (renderer/model/orientation_correction.hpp: the voxel at x is drawn at c + C·(x − c)). Along
// world axis r the box spans the volume's extent along the axis k with C[r][k] ≠ 0, so a
// quarter turn of a non-cubic volume swaps two extents. Clip planes are in world space:
// their slider spans this box, not the file's.
export function correctedBounds(bounds, correction) {
  if (!bounds || isIdentityCorrection(correction)) return bounds;
  const half = [0, 1, 2].map((k) => (bounds.hi[k] - bounds.lo[k]) / 2);
  const reach = [0, 1, 2].map((r) => half[correction[r].findIndex((v) => v !== 0)]);
  return {
    lo: bounds.center.map((c, r) => c - reach[r]),
    hi: bounds.center.map((c, r) => c + reach[r]),
    center: [...bounds.center],
    radius: bounds.radius,
  };
}

// In words, for the panel: "" for none; "flipped L/R, S/I" for flips; otherwise where each
// of the file's axes now points ("x→−z, y→y, z→x").
export function describeCorrection(m) {
  if (isIdentityCorrection(m)) return "";
  const names = ["L/R", "A/P", "S/I"];
  if (m.every((row, r) => row.every((v, c) => r === c || v === 0)))
    return `flipped ${names.filter((_, a) => m[a][a] === -1).join(", ")}`;
  const axis = ["x", "y", "z"];
  return [0, 1, 2].map((c) => {
    const r = [0, 1, 2].find((i) => m[i][c] !== 0);
    return `${axis[c]}→${m[r][c] < 0 ? "−" : ""}${axis[r]}`;
  }).join(", ");
}

// --- labels that never claim what the file does not say -----------------------------------
//
// A file that names no patient axes (volume object `orientation_known: false`) is drawn in
// its own axes taken as if they were L, P, S; nothing on the page may then call a direction
// left, anterior or superior, because nobody knows. Labels use the file's axes (+x, −y, …)
// until the user sets the orientation by hand: a flip or quarter turn of the volume, or
// "Treat as LPS" / "Treat as RAS". From then on the corrected axes are the user's statement
// of the patient axes, and labels are anatomical, said to be set by hand.

// Each patient direction's name among the file's own axes (world axes before any correction).
export const FILE_AXIS_LABELS = Object.freeze({ L: "+x", R: "−x", P: "+y", A: "−y", S: "+z", I: "−z" });

// The corrections behind "Treat as LPS" and "Treat as RAS": the file's x, y, z are taken as
// the patient's left, posterior, superior (nothing moves), or as right, anterior, superior
// (x and y mirrored into LPS world space, as the loader does for a file in RAS).
export const TREAT_AS = Object.freeze({
  lps: { label: "Treat as LPS", title: "Take the file's x, y, z as the patient's left, posterior, superior", matrix: [[1, 0, 0], [0, 1, 0], [0, 0, 1]] },
  ras: { label: "Treat as RAS", title: "Take the file's x, y, z as the patient's right, anterior, superior", matrix: [[-1, 0, 0], [0, -1, 0], [0, 0, 1]] },
});

const sameMatrix = (a, b) => JSON.stringify(a) === JSON.stringify(b);

// How the labels of a volume may speak:
//   "file"   the file names its patient axes: anatomical letters;
//   "hand"   it does not, but the user set them by hand (a correction, or a treat-as choice);
//   "axes"   it does not and nobody has: the file's axes.
// setByHand: the user chose "Treat as …" (a correction other than the identity is always by hand).
export function anatomySource(volume, correction = null, setByHand = false) {
  if (volume && volume.orientation_known !== false) return "file";
  if (setByHand || !isIdentityCorrection(correction)) return "hand";
  return "axes";
}

export const isAnatomical = (source) => source !== "axes";

// A patient direction's label: its letter where labels may be anatomical, else the file's axis.
export const directionLabel = (letter, anatomical) => (anatomical ? letter : FILE_AXIS_LABELS[letter]);

// The treat-as choice a correction made by hand amounts to: "lps", "ras" or null (another
// correction, or none made by hand).
export function treatAsOf(correction, setByHand) {
  if (!setByHand) return null;
  const m = correction ?? IDENTITY_CORRECTION;
  return Object.keys(TREAT_AS).find((k) => sameMatrix(TREAT_AS[k].matrix, m)) ?? null;
}

// The letters on the four edges of each slice pane (web/app/slice_views.js's layout, in
// world space after the correction: axial and coronal have the patient's right on the
// image's left; axial has anterior, coronal and sagittal superior at the top; sagittal has
// anterior on the left). Anatomical where the file names its axes or the user set them by
// hand, else the file's axes ("−x" on the left of the axial pane).
const PANE_EDGES = Object.freeze({
  axial: { left: "R", right: "L", top: "A", bottom: "P" },
  coronal: { left: "R", right: "L", top: "S", bottom: "I" },
  sagittal: { left: "A", right: "P", top: "S", bottom: "I" },
});

export function paneEdgeLetters(volume, correction = null, setByHand = false) {
  const anatomical = isAnatomical(anatomySource(volume, correction, setByHand));
  const out = {};
  for (const [pane, edges] of Object.entries(PANE_EDGES)) {
    out[pane] = Object.fromEntries(Object.entries(edges).map(([edge, letter]) => [edge, directionLabel(letter, anatomical)]));
  }
  return out;
}

// The standard views' button text and tooltip: anatomical names, or where the eye is along
// the file's axes ("From −y").
export function standardViewLabel(name, anatomical) {
  const v = STANDARD_VIEWS[name];
  if (anatomical) return { label: v.label, title: `${v.label} view` };
  const axis = v.eye.findIndex((x) => x !== 0);
  const from = `${v.eye[axis] > 0 ? "+" : "−"}${"xyz"[axis]}`;
  const up = v.up.findIndex((x) => x !== 0);
  return { label: `From ${from}`, title: `View from ${from} along the file's axes, ${v.up[up] > 0 ? "+" : "−"}${"xyz"[up]} up (the file names no patient axes)` };
}

// A correction step's button text and tooltip, in the file's axes where labels may not name anatomy.
const STEP_AXES = Object.freeze({
  "flip-lr": ["Flip x", "Mirror the volume along x"], "flip-ap": ["Flip y", "Mirror the volume along y"],
  "flip-si": ["Flip z", "Mirror the volume along z"], "turn-si": ["Turn 90° about z", "Turn the volume a quarter turn about z"],
  "turn-ap": ["Turn 90° about y", "Turn the volume a quarter turn about y"], "turn-lr": ["Turn 90° about x", "Turn the volume a quarter turn about x"],
});
export function correctionStepLabel(name, anatomical) {
  const step = CORRECTION_STEPS[name];
  if (anatomical) return { label: step.label, title: step.title };
  const [label, title] = STEP_AXES[name];
  return { label, title: `${title}; the patient axes are then set by hand` };
}

// The letters at the four edges of a 3D image seen with `camera`: the direction nearest
// each of the image's right, left, top and bottom, anatomical or in the file's axes.
export function imageEdgeLabels(camera, anatomical) {
  const axes = projectAxes(camera);
  const best = (score) => axes.reduce((b, a) => (score(a) > score(b) ? a : b)).label;
  const name = (letter) => directionLabel(letter, anatomical);
  return { right: name(best((a) => a.x)), left: name(best((a) => -a.x)), top: name(best((a) => a.y)), bottom: name(best((a) => -a.y)) };
}

// World millimetres per image pixel at the camera's target (the volume's centre): exact for
// an orthographic camera, at the target's depth only for a perspective one.
export function mmPerPixelAtTarget(camera, imageHeight) {
  if (!(imageHeight > 0)) return null;
  if (camera.projection === "orthographic") return camera.height / imageHeight;
  const d = vec.length(vec.sub(camera.target, camera.eye));
  return (2 * d * Math.tan((camera.fov_y_deg * Math.PI) / 360)) / imageHeight;
}

// A scale bar's length: the largest 1, 2 or 5 × 10^k mm that fits in maxPixels.
export function scaleBarLength(mmPerPixel, maxPixels) {
  if (!(mmPerPixel > 0) || !(maxPixels > 0)) return null;
  const most = mmPerPixel * maxPixels;
  const decade = 10 ** Math.floor(Math.log10(most));
  const mm = [5, 2, 1].map((f) => f * decade).find((v) => v <= most);
  return { mm, pixels: mm / mmPerPixel };
}
