// core/camera.js: navigation keeps the invariants the server checks (up orthogonal to the
// view direction) and the ones users feel (orbit keeps the distance, pan keeps the
// direction, a drag back undoes a drag).
import { test } from "node:test";
import assert from "node:assert/strict";

import {
  ORBIT_RAD_PER_PX, cameraFrame, camerasEqual, orbit, pan, vec, volumeBounds, worldPerPixel, zoom,
} from "../../../web/core/camera.js";

const demo = { eye: [600, 500, 700], target: [127.5, 127.5, 127.5], up: [0, 1, 0], projection: "perspective", fov_y_deg: 30 };
const ortho = { eye: [0, 0, 10], target: [0, 0, 0], up: [0, 1, 0], projection: "orthographic", height: 300 };

// Tolerances: the camera is rounded to 12 significant digits for the wire, so values of
// ~1000 carry ~1e-9 of rounding; each test chains at most a few hundred operations.
const near = (a, b, tol = 1e-6) => a.every((x, i) => Math.abs(x - b[i]) <= tol);

test("orbit keeps the distance to the target and an orthonormal up", () => {
  let cam = demo;
  const d0 = cameraFrame(demo).distance;
  for (let i = 0; i < 50; i++) {
    cam = orbit(cam, 13, -7);
    const f = cameraFrame(cam);
    assert.ok(Math.abs(f.distance - d0) < 1e-6 * d0);
    assert.ok(Math.abs(vec.dot(vec.normalize(cam.up), f.forward)) < 1e-9, "up ⟂ forward");
    assert.ok(Math.abs(vec.length(cam.up) - 1) < 1e-9, "up is a unit vector");
    assert.deepEqual(cam.target, demo.target);
  }
});

test("a horizontal drag of a full turn comes back; a drag and its reverse cancel", () => {
  const fullTurnPx = (2 * Math.PI) / ORBIT_RAD_PER_PX;
  const back = orbit(demo, fullTurnPx, 0);
  assert.ok(near(back.eye, demo.eye, 1e-6), `${back.eye}`);
  const there = orbit(orbit(demo, 120, 0), -120, 0);
  assert.ok(near(there.eye, demo.eye));
  // Vertical: over the top is allowed (no pole), and up follows.
  const over = orbit(demo, 0, Math.PI / ORBIT_RAD_PER_PX);  // half a turn about the right axis
  const f0 = cameraFrame(demo), f1 = cameraFrame(over);
  assert.ok(near(f1.up, vec.scale(f0.up, -1), 1e-9), "upside down after half a turn");
});

test("dragging right turns the camera to the left of the volume (content follows the pointer)", () => {
  const f0 = cameraFrame(demo);
  const moved = orbit(demo, 10, 0);
  // The eye moves against the camera's right axis.
  assert.ok(vec.dot(vec.sub(moved.eye, demo.eye), f0.right) < 0);
});

test("pan moves eye and target together by one pixel's world size per pixel", () => {
  const H = 500;
  const moved = pan(demo, 100, 0, H);
  const shift = vec.sub(moved.target, demo.target);
  assert.ok(near(vec.sub(moved.eye, demo.eye), shift, 1e-9), "eye and target move together");
  const expected = 100 * worldPerPixel(demo, H);
  assert.ok(Math.abs(vec.length(shift) - expected) < 1e-6);
  assert.ok(vec.dot(shift, cameraFrame(demo).right) < 0, "drag right: the camera moves left");
  // Orthographic: a drag of the full height moves by the view height.
  const o = pan(ortho, 0, 1000, 1000);
  assert.ok(near(o.target, [0, 300, 0], 1e-9), `${o.target}`);
});

test("zoom scales the distance (perspective) or the height (orthographic), within bounds", () => {
  const d0 = cameraFrame(demo).distance;
  const closer = zoom(demo, 0.5);
  assert.ok(Math.abs(cameraFrame(closer).distance - d0 / 2) < 1e-6);
  assert.ok(near(cameraFrame(closer).forward, cameraFrame(demo).forward, 1e-9));
  assert.equal(zoom(ortho, 2).height, 600);
  const radius = 10;
  assert.ok(Math.abs(cameraFrame(zoom(demo, 1e-9, radius)).distance - 0.2) < 1e-9, "clamped near");
  assert.ok(Math.abs(cameraFrame(zoom(demo, 1e9, radius)).distance - 500) < 1e-6, "clamped far");
  assert.equal(zoom(demo, NaN), demo);
  assert.equal(zoom(demo, -1), demo);
});

test("a degenerate up is repaired rather than sent", () => {
  const bad = { ...demo, eye: [127.5, 600, 127.5], up: [0, 1, 0] };   // up ∥ view direction
  const fixed = orbit(bad, 0, 0);
  assert.ok(Math.abs(vec.dot(vec.normalize(fixed.up), cameraFrame(fixed).forward)) < 1e-9);
});

test("volume bounds are the cell extent of docs/design.md", () => {
  const b = volumeBounds({ dims: [256, 256, 128], spacing: [1, 1, 2], origin: [0, 0, 0] });
  assert.deepEqual(b.lo, [-0.5, -0.5, -1]);
  assert.deepEqual(b.hi, [255.5, 255.5, 255]);
  assert.deepEqual(b.center, [127.5, 127.5, 127]);
  assert.equal(volumeBounds({ name: "not loaded" }), null);
});

test("volume bounds follow the direction matrix: a flipped and a permuted file", () => {
  // A RAS file in LPS: i runs towards −x, j towards −y from the origin.
  const ras = volumeBounds({ dims: [10, 20, 30], spacing: [1, 1, 2], origin: [0, 0, 0],
    direction: [[-1, 0, 0], [0, -1, 0], [0, 0, 1]] });
  assert.deepEqual(ras.lo, [-9.5, -19.5, -1]);
  assert.deepEqual(ras.hi, [0.5, 0.5, 59]);
  // Rows of D: world x = j, world y = −k, world z = −i (index i runs along −z).
  const permuted = volumeBounds({ dims: [10, 20, 30], spacing: [1, 2, 3], origin: [5, 5, 5],
    direction: [[0, 1, 0], [0, 0, -1], [-1, 0, 0]] });
  assert.deepEqual(permuted.lo, [5 - 1, 5 - 29.5 * 3, 5 - 9.5]);
  assert.deepEqual(permuted.hi, [5 + 19.5 * 2, 5 + 1.5, 5 + 0.5]);
  // No direction from an older server: the identity, as before.
  assert.deepEqual(volumeBounds({ dims: [2, 2, 2], spacing: [1, 1, 1], origin: [0, 0, 0] }).hi, [1.5, 1.5, 1.5]);
});

test("cameras compare by value", () => {
  assert.ok(camerasEqual(demo, structuredClone(demo)));
  assert.ok(!camerasEqual(demo, orbit(demo, 1, 0)));
  assert.ok(!camerasEqual(demo, ortho));
});
