// The slice message decoder (core/protocol.js) and the slice views' geometry
// (app/slice_views.js): pixel <-> world on a slice, and the crosshair's projection into the
// 3D view with docs/design.md's camera.
import assert from "node:assert/strict";
import { test } from "node:test";

import { decodeSlice, decodeFrame, isSliceMessage, requests } from "../../../web/core/protocol.js";
import { defaultWindowLevel, pixelOf, projectToView, worldOf } from "../../../web/app/slice_views.js";

const HEADER = { request: 3, axis: "sagittal", width: 3, height: 2, format: "gray8", pixel_spacing: 0.5,
  origin: [1, 2, 3], column: [0, 1, 0], row: [0, 0, -1], point: [4, 5, 6], window: 2000, level: 400,
  render_ms: 1.5, image_bytes: 6 };

function sliceMessage(header, pixels) {
  const text = new TextEncoder().encode(JSON.stringify(header));
  const out = new Uint8Array(8 + text.length + pixels.length);
  out.set(new TextEncoder().encode("VCS1"), 0);
  new DataView(out.buffer).setUint32(4, text.length, true);
  out.set(text, 8);
  out.set(pixels, 8 + text.length);
  return out.buffer;
}

test("a slice message decodes, and is never taken for a frame", () => {
  const data = sliceMessage(HEADER, new Uint8Array([0, 10, 20, 30, 40, 255]));
  assert.ok(isSliceMessage(data));
  const { header, pixels } = decodeSlice(data);
  assert.equal(header.request, 3);
  assert.deepEqual([...pixels], [0, 10, 20, 30, 40, 255]);
  assert.throws(() => decodeFrame(data), /bad magic/);
});

test("damaged slice messages are refused naming the problem", () => {
  assert.throws(() => decodeSlice(sliceMessage(HEADER, new Uint8Array(5))), /5 pixel bytes/);
  assert.throws(() => decodeSlice(sliceMessage({ ...HEADER, format: "rgba8" }, new Uint8Array(6))), /format/);
  assert.throws(() => decodeSlice(sliceMessage({ ...HEADER, origin: [0, 0] }, new Uint8Array(6))), /origin/);
});

test("the slice request carries only the fields given", () => {
  assert.deepEqual(requests.slice("axial", 64, 32), { type: "slice", axis: "axial", width: 64, height: 32 });
  assert.deepEqual(requests.slice("coronal", 8, 8, { point: [1, 2, 3], window: 400, level: 40 }),
    { type: "slice", axis: "coronal", width: 8, height: 8, point: [1, 2, 3], window: 400, level: 40 });
});

test("pixel and world positions on a slice are inverse", () => {
  const p = worldOf(HEADER, 2, 1);
  assert.deepEqual(p, [1, 3, 2.5]);
  assert.deepEqual(pixelOf(HEADER, p), { c: 2, r: 1 });
});

test("the crosshair projects to the view centre on the axis and to the right of it for +right", () => {
  const camera = { eye: [0, 0, 10], target: [0, 0, 0], up: [0, 1, 0], projection: "perspective", fov_y_deg: 90 };
  assert.deepEqual(projectToView(camera, [0, 0, 0], 200, 100), { x: 100, y: 50 });
  // forward (0,0,-1) × up (0,1,0) = (1,0,0): +x is image right. tan(45°)·10 = 10 = half height.
  const right = projectToView(camera, [5, 5, 0], 200, 100);
  assert.ok(Math.abs(right.x - 125) < 1e-9 && Math.abs(right.y - 25) < 1e-9, JSON.stringify(right));
  assert.equal(projectToView(camera, [0, 0, 20], 200, 100), null, "behind the eye");
  const ortho = { ...camera, projection: "orthographic", height: 20 };
  assert.deepEqual(projectToView(ortho, [10, 0, 0], 200, 100), { x: 150, y: 50 });
});

test("CT gets a soft-tissue window, other data its range", () => {
  assert.deepEqual(defaultWindowLevel({ value_range: [-1024, 3071] }), { window: 400, level: 40 });
  assert.deepEqual(defaultWindowLevel({ value_range: [0, 255] }), { window: 255, level: 127.5 });
});
