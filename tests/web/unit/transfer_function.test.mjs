// core/transfer_function.js: the editor's operations keep docs/design.md's contract (strictly
// increasing values, components in [0, 1]), and its preset table is the renderer's.
import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { fileURLToPath } from "node:url";
import path from "node:path";

import {
  PRESET_NAMES, addPoint, applyWindowLevel, evaluate, fromHex, movePoint, presetPoints, problems, removePoint,
  resolvePoints, setColor, tidyPoints, toHex, windowLevelOf,
} from "../../../web/core/transfer_function.js";
import { TF_PRESETS } from "../../../web/core/protocol.js";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../../..");

// The presets as renderer/model/transfer_function.cpp writes them, read from the source so that
// a change there fails here instead of drifting silently. Relative presets are read on
// the unit range (at(f) = f).
function rendererPresets() {
  const src = readFileSync(path.join(root, "renderer/model/transfer_function.cpp"), "utf8");
  const rows = (block) => [...block.matchAll(/\{([^{}]+)\}/g)].map((m) =>
    m[1].split(",").map((x) => Number(x.trim().replace(/^at\((.*)\)$/, "$1"))));
  const out = {};
  for (const name of ["ct_bone", "ct_soft_tissue", "ct_angiography"]) {
    const m = new RegExp(`name == "${name}"\\) \\{\\s*tf\\.points = \\{(.*?)\\};`, "s").exec(src);
    assert.ok(m, `found ${name} in transfer_function.cpp`);
    out[name] = rows(m[1]);
  }
  const mr = /if \(name == "mr"\)\s*tf\.points = \{(.*?)\};\s*else\s*tf\.points = \{(.*?)\};/s.exec(src);
  assert.ok(mr, "found mr and micro_ct in transfer_function.cpp");
  out.mr = rows(mr[1]);
  out.micro_ct = rows(mr[2]);
  return out;
}

test("the mirrored presets are renderer/model/transfer_function.cpp's, name for name", () => {
  const cpp = rendererPresets();
  assert.deepEqual([...PRESET_NAMES].sort(), Object.keys(cpp).sort());
  assert.deepEqual(TF_PRESETS.map((p) => p.name).sort(), Object.keys(cpp).sort());
  for (const name of PRESET_NAMES) assert.deepEqual(presetPoints(name, [0, 1]), cpp[name], name);
});

test("relative presets are placed on the volume's range; HU presets are not", () => {
  const p = presetPoints("micro_ct", [100, 300]);
  assert.deepEqual(p.map((r) => r[0]), [100, 160, 200, 300]);
  assert.deepEqual(presetPoints("ct_bone", [0, 255]), presetPoints("ct_bone", [-1024, 3071]));
  assert.throws(() => presetPoints("rainbow", [0, 1]), /unknown transfer function preset "rainbow"/);
  assert.deepEqual(resolvePoints({ preset: "mr" }, [0, 1]), presetPoints("mr", [0, 1]));
  assert.deepEqual(resolvePoints({ points: [[0, 0, 0, 0, 0], [1, 1, 1, 1, 1]] }, [0, 1])[1], [1, 1, 1, 1, 1]);
  for (const name of PRESET_NAMES) assert.deepEqual(problems(presetPoints(name, [0, 4095])), [], name);
});

test("evaluate is piecewise linear and clamped outside", () => {
  const pts = [[0, 0, 0, 0, 0], [100, 1, 0.5, 0, 0.8]];
  assert.deepEqual(evaluate(pts, -5), [0, 0, 0, 0]);
  assert.deepEqual(evaluate(pts, 50), [0.5, 0.25, 0, 0.4]);
  assert.deepEqual(evaluate(pts, 500), [1, 0.5, 0, 0.8]);
});

test("moving a point never crosses or touches its neighbours, and clamps opacity", () => {
  const pts = [[0, 0, 0, 0, 0], [50, 1, 1, 1, 0.5], [100, 1, 1, 1, 1]];
  const right = movePoint(pts, 1, 1000, 2);
  assert.ok(right[1][0] < 100 && right[1][0] > 99.9);
  assert.equal(right[1][4], 1);
  const left = movePoint(pts, 1, -1000, -1);
  assert.ok(left[1][0] > 0 && left[1][0] < 0.1);
  assert.equal(left[1][4], 0);
  assert.deepEqual(problems(right), []);
  assert.deepEqual(problems(left), []);
  assert.deepEqual(pts[1], [50, 1, 1, 1, 0.5], "the input is not modified");
  // The end points move freely outward.
  assert.equal(movePoint(pts, 2, 4000, 1)[2][0], 4000);
});

test("adding takes the curve's colour there; removing keeps at least two points", () => {
  const pts = [[0, 0, 0, 0, 0], [100, 1, 0.5, 0, 0.8]];
  const { points, index } = addPoint(pts, 25, 0.3);
  assert.equal(index, 1);
  assert.deepEqual(points[1], [25, 0.25, 0.125, 0, 0.3]);
  assert.equal(addPoint(pts, 300, 1).index, 2);
  assert.equal(addPoint(pts, -300, 1).index, 0);
  assert.equal(addPoint(pts, 100, 0.1).points.length, 2, "a taken value moves that point");
  assert.deepEqual(removePoint(points, 1), pts);
  assert.equal(removePoint(pts, 0).length, 2);
});

test("window/level is the span of the curve's points, and maps it affinely", () => {
  // A curve laid across bone's radiology window, as the server's presets are: it reads as
  // W 2000 / L 400 (the old reading, from the first visible point, gave 2850 / 1575).
  const pts = [[-600, 0, 0, 0, 0], [150, 0.9, 0.6, 0.4, 0], [300, 0.95, 0.85, 0.7, 0.3], [1400, 1, 1, 1, 0.9]];
  const wl = windowLevelOf(pts);
  assert.deepEqual(wl, { window: 2000, level: 400 });
  const moved = applyWindowLevel(pts, 400, 40);
  assert.deepEqual(windowLevelOf(moved), { window: 400, level: 40 });
  assert.deepEqual(moved.map((p) => p.slice(1)), pts.map((p) => p.slice(1)), "colours and opacities stay");
  assert.deepEqual(problems(moved), []);
  const back = applyWindowLevel(moved, wl.window, wl.level);
  back.forEach((p, i) => assert.ok(Math.abs(p[0] - pts[i][0]) < 1e-9));
});

test("problems names every broken rule", () => {
  assert.deepEqual(problems([[0, 0, 0, 0, 0], [0, 1, 1, 1, 1]]), ["points[1]: value not above the previous one"]);
  assert.match(problems([[0, 0, 0, 2, 0]])[0], /outside \[0, 1\]/);
  assert.match(problems([[0, 0, 0, NaN, 0]])[0], /not 5 finite numbers/);
  assert.deepEqual(problems([]), ["needs at least one point"]);
});

test("colours round-trip through #rrggbb; setColor clamps", () => {
  assert.equal(toHex([1, 0.5, 0]), "#ff8000");
  assert.deepEqual(fromHex("#ff8000").map((c) => Math.round(c * 255)), [255, 128, 0]);
  assert.throws(() => fromHex("red"), /not a colour/);
  assert.deepEqual(setColor([[0, 0, 0, 0, 0.5]], 0, [2, -1, 0.5]), [[0, 1, 0, 0.5, 0.5]]);
});

test("tidy points stay valid and within an 8-bit step of the originals", () => {
  const pts = [[0.123456789012, 0.333333333, 0.5, 0.1, 0.05], [0.123456791, 1, 1, 1, 0.999999]];
  const t = tidyPoints(pts);
  assert.deepEqual(problems(t), []);
  t.forEach((p, i) => p.slice(1).forEach((c, k) => assert.ok(Math.abs(c - pts[i][k + 1]) < 0.5 / 255)));
});
