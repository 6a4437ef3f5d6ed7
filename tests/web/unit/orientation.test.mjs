// The standard views, the marker's projections and the window/level drag (web/core/).

import assert from "node:assert/strict";
import { test } from "node:test";

import {
  composeCorrection, CORRECTION_STEPS, describeCorrection, IDENTITY_CORRECTION, isIdentityCorrection,
  projectAxes, rollCamera, screenLabels, standardViewCamera, STANDARD_VIEWS,
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
