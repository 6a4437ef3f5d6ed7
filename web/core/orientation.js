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
// quarter turns only) applied about the volume's centre (renderer/orientation_correction.hpp).
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
// it (renderer/orientation_correction.hpp: the voxel at x is drawn at c + C·(x − c)). Along
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
