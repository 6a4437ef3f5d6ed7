// The standard views, the marker's projections, labels that never claim unknown anatomy,
// the saved image's scale bar and the window/level drag (web/core/).

import assert from "node:assert/strict";
import { test } from "node:test";

import {
  anatomySource, composeCorrection, CORRECTION_STEPS, correctionStepLabel, describeCorrection, FILE_AXIS_LABELS,
  IDENTITY_CORRECTION, imageEdgeLabels, isIdentityCorrection, mmPerPixelAtTarget, paneEdgeLetters, PATIENT_AXES,
  projectAxes, rollCamera, scaleBarLength, screenLabels, standardViewCamera, standardViewLabel, STANDARD_VIEWS,
  TREAT_AS, treatAsOf,
} from "../../../web/core/orientation.js";
import { windowLevelStep } from "../../../web/core/window_level.js";

const start = { eye: [0, -500, 0], target: [10, 20, 30], up: [0, 0, 1], projection: "perspective", fov_y_deg: 30 };

test("each standard view puts the expected patient side to the right, up and toward the viewer", () => {
  // Radiology convention: facing the patient, their left is on the image's right.
  const expected = {
    anterior: { right: "L", up: "S", toward: "A" },
    posterior: { right: "R", up: "S", toward: "P" },
    left: { right: "P", up: "S", toward: "L" },
    right: { right: "A", up: "S", toward: "R" },
    superior: { right: "R", up: "A", toward: "S" },
    inferior: { right: "L", up: "A", toward: "I" },
  };
  for (const name of Object.keys(STANDARD_VIEWS)) {
    const cam = standardViewCamera(name, start, [1, 2, 3]);
    assert.deepEqual(screenLabels(cam), expected[name], name);
    assert.deepEqual(cam.target, [1, 2, 3], `${name}: looks at the volume's centre`);
    const d = Math.hypot(...cam.eye.map((e, i) => e - cam.target[i]));
    const d0 = Math.hypot(...start.eye.map((e, i) => e - start.target[i]));
    assert.ok(Math.abs(d - d0) < 1e-9, `${name}: keeps the distance (${d} vs ${d0})`);
  }
  assert.throws(() => standardViewCamera("front", start), /unknown standard view "front"/);
});

test("projected axes are unit vectors split between the image plane and depth", () => {
  const cam = standardViewCamera("anterior", start);
  for (const a of projectAxes(cam)) assert.ok(Math.abs(a.x * a.x + a.y * a.y + a.depth * a.depth - 1) < 1e-12, a.label);
  const byLabel = Object.fromEntries(projectAxes(cam).map((a) => [a.label, a]));
  assert.ok(byLabel.L.x > 0.999 && byLabel.S.y > 0.999 && byLabel.A.depth < -0.999);
});

test("rolling turns the image: 90° clockwise brings the patient's head to the right", () => {
  const cam = standardViewCamera("anterior", start);
  assert.equal(screenLabels(rollCamera(cam, 90)).right, "S");
  assert.equal(screenLabels(rollCamera(cam, -90)).right, "I");
  assert.equal(screenLabels(rollCamera(cam, 180)).up, "I");
  assert.deepEqual(screenLabels(rollCamera(rollCamera(cam, 90), -90)), screenLabels(cam));
});

test("window/level drag scales with the window and the data, not a fixed share of the range", () => {
  const ct = [-1024, 3071];
  const bone = { window: 2000, level: 400 };
  const down75 = windowLevelStep(bone, 0, 75, ct);
  // 0.1 % of the 2000 HU window per px: 150 HU for 75 px (the old drag moved 750 HU).
  assert.ok(Math.abs(down75.level - 550) < 1e-9, JSON.stringify(down75));
  assert.equal(down75.window, 2000);
  const soft = windowLevelStep({ window: 400, level: 40 }, 0, 75, ct);
  assert.ok(Math.abs(soft.level - (40 + 75 * 0.4)) < 1e-9, "a narrow window moves finer");
  // The same drag on 8-bit data moves by the same share of its (same-shaped) window.
  const byte = windowLevelStep({ window: 2000 / 16, level: 25 }, 0, 75, [0, 255]);
  assert.ok(Math.abs(byte.level - 25 - 75 * 0.125) < 1e-9);
  // Horizontal: the window grows by exp(0.004·dx), never to zero.
  assert.ok(Math.abs(windowLevelStep(bone, 100, 0, ct).window - 2000 * Math.exp(0.4)) < 1e-6);
  assert.ok(windowLevelStep(bone, -1e6, 0, ct).window > 0);
});

test("orientation correction steps are signed permutations; composing applies the step after", () => {
  for (const [name, step] of Object.entries(CORRECTION_STEPS)) {
    const m = step.matrix;
    for (let i = 0; i < 3; i++) {
      assert.equal(m[i].filter((v) => v !== 0).length, 1, `${name} row ${i}`);
      assert.equal([0, 1, 2].filter((r) => m[r][i] !== 0).length, 1, `${name} column ${i}`);
    }
    // A flip twice, or a quarter turn four times, is no correction.
    let c = IDENTITY_CORRECTION;
    const times = name.startsWith("flip") ? 2 : 4;
    for (let k = 0; k < times; k++) c = composeCorrection(m, c);
    assert.ok(isIdentityCorrection(c), `${name} ×${times}: ${JSON.stringify(c)}`);
  }
  const flipThenTurn = composeCorrection(CORRECTION_STEPS["turn-si"].matrix, CORRECTION_STEPS["flip-lr"].matrix);
  assert.deepEqual(flipThenTurn, [[0, -1, 0], [-1, 0, 0], [0, 0, 1]]);
  assert.equal(describeCorrection(IDENTITY_CORRECTION), "");
  assert.equal(describeCorrection([[-1, 0, 0], [0, 1, 0], [0, 0, -1]]), "flipped L/R, S/I");
  assert.equal(describeCorrection(flipThenTurn), "x→−y, y→−x, z→z");
});

const ANATOMICAL = new Set(["L", "R", "A", "P", "S", "I"]);
const unknown = { name: "scan.nhdr", orientation_known: false };
const known = { name: "scan.nrrd", orientation_known: true };

test("labels name anatomy only where the file does or the user set it by hand", () => {
  assert.equal(anatomySource(known), "file");
  assert.equal(anatomySource(unknown), "axes");
  assert.equal(anatomySource(unknown, IDENTITY_CORRECTION, true), "hand", "Treat as LPS");
  assert.equal(anatomySource(unknown, CORRECTION_STEPS["flip-ap"].matrix), "hand", "a flip sets the axes by hand");
  assert.equal(anatomySource(known, CORRECTION_STEPS["flip-ap"].matrix), "file", "an override of a file's axes");
  assert.equal(treatAsOf(IDENTITY_CORRECTION, true), "lps");
  assert.equal(treatAsOf(TREAT_AS.ras.matrix, true), "ras");
  assert.equal(treatAsOf(IDENTITY_CORRECTION, false), null);
  assert.equal(treatAsOf(CORRECTION_STEPS["flip-lr"].matrix, true), null);
});

test("pane edge letters: the file's axes for an unoriented file, anatomical once known, opposite edges opposite", () => {
  const opposite = { L: "R", R: "L", A: "P", P: "A", S: "I", I: "S" };
  const letters = paneEdgeLetters(known);
  const axes = paneEdgeLetters(unknown);
  for (const pane of ["axial", "coronal", "sagittal"]) {
    const e = letters[pane];
    assert.equal(opposite[e.left], e.right, pane);
    assert.equal(opposite[e.top], e.bottom, pane);
    for (const edge of ["left", "right", "top", "bottom"]) {
      assert.ok(ANATOMICAL.has(e[edge]), `${pane} ${edge}: ${e[edge]}`);
      // The same edge in the file's axes is the world axis that letter names (LPS: L = +x …).
      assert.equal(axes[pane][edge], FILE_AXIS_LABELS[e[edge]], `${pane} ${edge}`);
      assert.match(axes[pane][edge], /^[+−][xyz]$/);
    }
  }
  // Radiological layout (slice_views.js): the patient's right on the image's left.
  assert.deepEqual(letters.axial, { left: "R", right: "L", top: "A", bottom: "P" });
  assert.deepEqual(axes.axial, { left: "−x", right: "+x", top: "−y", bottom: "+y" });
  assert.deepEqual(paneEdgeLetters(unknown, IDENTITY_CORRECTION, true), letters, "Treat as LPS: anatomical");
  assert.deepEqual(paneEdgeLetters(unknown, CORRECTION_STEPS["turn-si"].matrix), letters, "a turn: anatomical, set by hand");
});

test("Treat as RAS puts each file axis where RAS says: x to the patient's right, y anterior, z superior", () => {
  const C = TREAT_AS.ras.matrix;
  const label = (d) => PATIENT_AXES.find((a) => a.dir.every((v, i) => v === d[i])).label;
  ["R", "A", "S"].forEach((ras, k) => {
    const e = [0, 1, 2].map((i) => (i === k ? 1 : 0));
    assert.equal(label([0, 1, 2].map((r) => C[r].reduce((s, v, c) => s + v * e[c], 0))), ras, `file axis ${"xyz"[k]}`);
  });
  assert.deepEqual(TREAT_AS.lps.matrix, IDENTITY_CORRECTION);
});

test("view buttons, correction steps and image edges speak of the file's axes until the anatomy is known", () => {
  for (const name of Object.keys(STANDARD_VIEWS)) {
    const axes = standardViewLabel(name, false);
    assert.match(axes.label, /^From [+−][xyz]$/, name);
    assert.ok(!/\b(Anterior|Posterior|Left|Right|Superior|Inferior)\b/.test(axes.label + axes.title), `${name}: ${axes.title}`);
    // The eye of the view is on the side the label names.
    const cam = standardViewCamera(name, start, [0, 0, 0]);
    const along = { x: 0, y: 1, z: 2 }[axes.label.at(-1)];
    assert.equal(Math.sign(cam.eye[along]), axes.label.includes("+") ? 1 : -1, name);
    assert.equal(standardViewLabel(name, true).label, STANDARD_VIEWS[name].label);
  }
  for (const name of Object.keys(CORRECTION_STEPS)) {
    const { label } = correctionStepLabel(name, false);
    assert.ok(!label.split(/[^A-Za-z]+/).some((w) => ANATOMICAL.has(w)), `${name}: ${label}`);
    assert.equal(correctionStepLabel(name, true).label, CORRECTION_STEPS[name].label);
  }
  const anterior = standardViewCamera("anterior", start);
  assert.deepEqual(imageEdgeLabels(anterior, true), { right: "L", left: "R", top: "S", bottom: "I" });
  assert.deepEqual(imageEdgeLabels(anterior, false), { right: "+x", left: "−x", top: "+z", bottom: "−z" });
});

test("the scale bar: mm per pixel at the target in closed form, a 1-2-5 length that fits", () => {
  // Perspective: the view's height at distance d is 2·d·tan(fov/2); 500 mm at 30° over 400 px.
  const d = Math.hypot(...start.eye.map((e, i) => e - start.target[i]));
  const mm = mmPerPixelAtTarget(start, 400);
  assert.ok(Math.abs(mm - (2 * d * Math.tan(Math.PI / 12)) / 400) < 1e-12);
  assert.equal(mmPerPixelAtTarget({ ...start, projection: "orthographic", height: 300 }, 600), 0.5);
  assert.equal(mmPerPixelAtTarget(start, 0), null);
  for (const [perPx, maxPx, want] of [[0.5, 200, 100], [0.37, 200, 50], [1, 150, 100], [0.013, 100, 1], [3, 60, 100]]) {
    const bar = scaleBarLength(perPx, maxPx);
    assert.equal(bar.mm, want, `${perPx} mm/px in ${maxPx} px`);
    assert.ok(bar.pixels <= maxPx && Math.abs(bar.pixels * perPx - bar.mm) < 1e-9);
  }
  assert.equal(scaleBarLength(0, 100), null);
});
