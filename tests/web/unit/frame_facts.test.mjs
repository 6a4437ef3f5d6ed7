// core/frame_facts.js: the stats overlay states the size a frame was rendered at, not the
// viewport the server scaled it up to, and its level's mip level and step.
import { test } from "node:test";
import assert from "node:assert/strict";

import { describeFrame, frameFacts, raysForScale } from "../../../web/core/frame_facts.js";

const header = (quality, extra = {}) => ({ seq: 1, request: 3, level: 0, width: 950, height: 755, codec: "jpeg", final: false, quality, ...extra });

test("an older server's frame, scaled up on the server, says it was rendered at a quarter of the viewport", () => {
  const h = header({ step: 2, mip_level: 1, image_scale: 0.25 });
  const f = frameFacts(h);
  // raysForScale as the server rounds: lround(950 · 0.25) = 238 (237.5 rounds away from 0), lround(755 · 0.25) = 189.
  assert.deepEqual(f.rendered, [238, 189]);
  assert.deepEqual(f.sent, [950, 755]);
  const d = describeFrame(h);
  assert.equal(d.image, "238×189 (¼ scale, sent as 950×755)");
  assert.equal(d.level, "0 · mip 1 · step 2 (jpeg)");
});

test("a pass at rest says so beside its level and step", () => {
  const h = header({ step: 0.125 }, { codec: "png", level: 5, rest_pass: 2 });
  assert.equal(describeFrame(h).level, "5 · at rest, pass 2 · step 0.125 (png)");
  assert.equal(describeFrame(header({ step: 0.5 }, { codec: "png", level: 5, final: true })).level, "5 · final · step 0.5 (png)");
});

test("a frame sent at its ray grid's size says the view it fills", () => {
  const h = header({ step: 2, mip_level: 1, image_scale: 0.25 }, { width: 238, height: 189, view_width: 950, view_height: 755 });
  const f = frameFacts(h);
  assert.deepEqual(f.rendered, [238, 189]);
  assert.deepEqual(f.sent, [238, 189]);
  assert.deepEqual(f.view, [950, 755]);
  assert.equal(describeFrame(h).image, "238×189 (¼ scale of 950×755)");
  const full = header({ image_scale: 1 }, { view_width: 950, view_height: 755 });
  assert.equal(describeFrame(full).image, "950×755");
});

test("a full-scale final frame says its size once, and final", () => {
  const d = describeFrame(header({ step: 0.5, mip_level: 0, image_scale: 1 }, { level: 2, final: true, codec: "png" }));
  assert.equal(d.image, "950×755");
  assert.equal(d.level, "2 · final · step 0.5 (png)");
});

test("a header without quality (an older server) is taken at full scale", () => {
  assert.equal(describeFrame({ level: 0, width: 10, height: 20, codec: "jpeg", final: false }).image, "10×20");
  assert.equal(raysForScale(3, 0.1), 1, "never an empty grid");
});
