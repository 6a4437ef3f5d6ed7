// The clip-plane slider's range (web/core/clip_plane.js, orientation.js's correctedBounds):
// after the volume is flipped or turned (quality.orientation_correction) the slider spans
// the box the renderer draws the volume in, not the file's box.

import assert from "node:assert/strict";
import { test } from "node:test";

import { volumeBounds } from "../../../web/core/camera.js";
import { axisClipPlane, sliderOfPlane } from "../../../web/core/clip_plane.js";
import { composeCorrection, CORRECTION_STEPS, correctedBounds, IDENTITY_CORRECTION } from "../../../web/core/orientation.js";

// A non-cubic volume off the origin: 40 × 20 × 10 samples, spacing 1 × 1.5 × 2, so its
// extents (40, 30, 20) all differ and a quarter turn about any axis changes the box.
const volume = { dims: [40, 20, 10], spacing: [1, 1.5, 2], origin: [5, -7, 11] };

// The box the renderer draws: every corner x of the file's box moved to c + C·(x − c)
// (renderer/model/orientation_correction.cpp, correctedPlacement), then the extent of the eight.
function drawnBox(bounds, C) {
  const c = bounds.center;
  const moved = [];
  for (const i of [0, 1]) for (const j of [0, 1]) for (const k of [0, 1]) {
    const x = [i ? bounds.hi[0] : bounds.lo[0], j ? bounds.hi[1] : bounds.lo[1], k ? bounds.hi[2] : bounds.lo[2]];
    moved.push([0, 1, 2].map((r) => c[r] + C[r].reduce((s, v, q) => s + v * (x[q] - c[q]), 0)));
  }
  return {
    lo: [0, 1, 2].map((r) => Math.min(...moved.map((p) => p[r]))),
    hi: [0, 1, 2].map((r) => Math.max(...moved.map((p) => p[r]))),
  };
}

// Every number here is a sum of a few values exactly representable in binary (halves and
// small integers): the boxes agree exactly, and planes to toPrecision(8) of ~50.
const close = (a, b, what) => a.forEach((x, i) => assert.ok(Math.abs(x - b[i]) < 1e-6, `${what}[${i}]: ${x} vs ${b[i]}`));

test("without a correction the slider spans the file's box", () => {
  const b = volumeBounds(volume);
  assert.equal(correctedBounds(b, IDENTITY_CORRECTION), b);
  assert.equal(correctedBounds(b, null), b);
  close(b.lo, [4.5, -7.75, 10], "lo");
  close(b.hi, [44.5, 22.25, 30], "hi");
});

test("a quarter turn about S/I swaps the x and y extents of a non-cubic volume about its centre", () => {
  const b = volumeBounds(volume);
  const turned = correctedBounds(b, CORRECTION_STEPS["turn-si"].matrix);
  const expected = drawnBox(b, CORRECTION_STEPS["turn-si"].matrix);
  close(turned.lo, expected.lo, "lo");
  close(turned.hi, expected.hi, "hi");
  close(turned.center, b.center, "centre");
  // x now spans the file's y extent (30), y the file's x extent (40); z is unchanged.
  close(turned.hi.map((h, i) => h - turned.lo[i]), [30, 40, 20], "extent");
  // The slider's ends are the drawn box's faces along each axis, not the file's.
  for (let axis = 0; axis < 3; axis++) {
    assert.equal(axisClipPlane(turned, axis, 0, false).point[axis], Number(expected.lo[axis].toPrecision(8)), `axis ${axis} at 0`);
    assert.equal(axisClipPlane(turned, axis, 1, true).point[axis], Number(expected.hi[axis].toPrecision(8)), `axis ${axis} at 1`);
  }
  assert.notEqual(axisClipPlane(turned, 0, 0, false).point[0], axisClipPlane(b, 0, 0, false).point[0],
    "a turn of a non-cubic volume moves the slider's end");
});

test("every composition of flips and turns gives the box the renderer draws", () => {
  const b = volumeBounds(volume);
  let C = IDENTITY_CORRECTION;
  // A walk through the steps: 24 signed permutations and their mirrors come up in turn.
  const walk = ["turn-ap", "flip-lr", "turn-lr", "turn-si", "flip-si", "turn-ap", "turn-lr", "flip-ap", "turn-si"];
  for (const step of walk) {
    C = composeCorrection(CORRECTION_STEPS[step].matrix, C);
    const got = correctedBounds(b, C), want = drawnBox(b, C);
    close(got.lo, want.lo, `${step} lo`);
    close(got.hi, want.hi, `${step} hi`);
  }
});

test("a plane the server reports maps back to its slider place in the drawn box", () => {
  const turned = correctedBounds(volumeBounds(volume), CORRECTION_STEPS["turn-lr"].matrix);
  for (const t of [0, 0.25, 0.5, 1]) {
    const plane = axisClipPlane(turned, 2, t, true);
    const s = sliderOfPlane(turned, plane);
    assert.equal(s.axis, 2);
    assert.equal(s.flipped, true);
    assert.ok(Math.abs(s.t - t) < 1e-7, `t ${t} came back as ${s.t}`);
  }
  // Outside the box: the slider stops at its end; an oblique plane has no slider.
  assert.equal(sliderOfPlane(turned, { point: [0, 0, 1e6], normal: [0, 0, 1] }).t, 1);
  assert.equal(sliderOfPlane(turned, { point: [0, 0, 0], normal: [0.6, 0.8, 0] }), null);
});
