// core/stats.js: latency is measured once per request, fps over the last second, and the
// error series restarts with each new view.
import { test } from "node:test";
import assert from "node:assert/strict";

import { FPS_WINDOW_MS, FrameStats } from "../../../web/core/stats.js";

const frame = (seq, request, level, value, final = false) =>
  ({ seq, request, level, final, error: value === null ? null : { value, method: "m" } });

test("latency: from sending a request to the first frame that shows it, once", () => {
  const s = new FrameStats();
  s.noteSent({ type: "camera", id: 7 }, 100);
  assert.equal(s.noteFrame(frame(1, 7, 0, 0.03), 142), 42);
  assert.equal(s.latencyMs, 42);
  assert.equal(s.noteFrame(frame(2, 7, 1, 0.01), 300), null, "a refinement of the same view is not a latency");
  assert.equal(s.latencyMs, 42);
  assert.equal(s.noteFrame(frame(3, null, 0, null), 310), null, "frames answering nothing measure nothing");
});

test("fps counts the frames of the last second", () => {
  const s = new FrameStats();
  for (let t = 0; t <= 2000; t += 40) s.noteFrame(frame(t, null, 0, null), t);
  assert.equal(s.fps(2000), 25);             // 1000 ms / 40 ms
  assert.equal(s.fps(2000 + FPS_WINDOW_MS), 0);
  assert.equal(new FrameStats().fps(0), 0);
});

test("the error series follows one view's refinement and restarts with the next", () => {
  const s = new FrameStats();
  s.noteSent({ type: "camera", id: 1 }, 1000);
  s.noteFrame(frame(1, 1, 0, 0.03), 1010);
  s.noteFrame(frame(2, 1, 1, 0.01), 1100);
  s.noteFrame(frame(3, 1, 2, 0.002, true), 1400);
  assert.deepEqual(s.series.points.map((p) => [p.tMs, p.value, p.level, p.final]),
    [[10, 0.03, 0, false], [100, 0.01, 1, false], [400, 0.002, 2, true]]);
  // A drag: frames of new requests, then interaction_end and the refinement of the last one.
  s.noteSent({ type: "camera", id: 2 }, 2000);
  s.noteFrame(frame(4, 2, 0, 0.04), 2030);
  assert.equal(s.series.request, 2);
  assert.equal(s.series.points.length, 1);
  s.noteSent({ type: "interaction_end", id: 3 }, 2500);
  s.noteFrame(frame(5, 2, 1, 0.01), 2600);
  assert.deepEqual(s.series.points.map((p) => p.tMs), [100], "time counts from interaction_end");
  s.noteFrame(frame(6, 2, 2, 0.001, true), 2900);
  assert.deepEqual(s.series.points.map((p) => p.tMs), [100, 400]);
  // Passes at rest after the final frame: the same view's series goes on converging.
  s.noteFrame({ ...frame(7, 2, 2, 0.0004), rest_pass: 1 }, 3500);
  s.noteFrame({ ...frame(8, 2, 2, 0.0001), rest_pass: 2 }, 4500);
  assert.deepEqual(s.series.points.map((p) => [p.tMs, p.value, p.final]),
    [[100, 0.01, false], [400, 0.001, true], [1000, 0.0004, true], [2000, 0.0001, true]]);
});
