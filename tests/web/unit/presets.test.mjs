// The preset picker's logic (web/core/presets.js), the W/L numbers' precision
// (web/core/window_level.js displayNumber) and the limits in the user's words (web/core/limits.js).
import { test } from "node:test";
import assert from "node:assert/strict";

import { modalitiesOf, presetNote, presetsOfModality } from "../../../web/core/presets.js";
import { displayNumber } from "../../../web/core/window_level.js";
import { limitedLine, tooLargeWords } from "../../../web/core/limits.js";

// A volume object's `modality` as the server sends it for an 8-bit chest CT (grey values).
const preset = (name, label, modality, window, level, shading = true) =>
  ({ name, label, modality, window, level, points: [[level - window / 2, 0, 0, 0, 0], [level + window / 2, 1, 1, 1, 1]], shading });
const greyCt = {
  name: "CT", source: "inferred", reason: "no modality in the file; the name says 'ct': CT", default_preset: "ct.bone",
  hounsfield: false, modalities: ["CT", "MR", "micro-CT"],
  presets: [
    preset("ct.bone", "CT bone (grey values)", "CT", 253, 179.1),
    preset("ct.lung", "CT lung (grey values)", "CT", 189.75, 52.6),
    preset("mr.t1_brain", "MR T1 brain", "MR", 253, 141.15),
    preset("micro_ct.default", "Micro-CT", "micro-CT", 202.4, 153.8),
  ],
};

test("every modality the server has presets for is offered, its choice first", () => {
  assert.deepEqual(modalitiesOf(greyCt), ["CT", "MR", "micro-CT"]);
  // An older server: no `modalities`, presets without a modality are the chosen one's.
  const older = { name: "micro-CT", presets: [{ name: "micro_ct.default" }] };
  assert.deepEqual(modalitiesOf(older), ["micro-CT"]);
  assert.deepEqual(presetsOfModality(older, "micro-CT").map((p) => p.name), ["micro_ct.default"]);
  assert.deepEqual(modalitiesOf(null), []);
});

test("the presets offered are the modality's own, in the server's order", () => {
  assert.deepEqual(presetsOfModality(greyCt, "CT").map((p) => p.name), ["ct.bone", "ct.lung"]);
  assert.deepEqual(presetsOfModality(greyCt, "MR").map((p) => p.name), ["mr.t1_brain"]);
  assert.deepEqual(presetsOfModality(greyCt, "PET"), []);
});

test("the note follows the preset shown and says who chose the modality", () => {
  const lung = greyCt.presets[1];
  const note = presetNote(greyCt, { modality: "CT", preset: lung });
  assert.match(note, /^CT \(inferred\): no modality in the file/);
  assert.match(note, /→ CT lung \(grey values\), W 190 \/ L 52\.6, shaded$/, note);
  const mr = presetNote(greyCt, { modality: "MR", preset: greyCt.presets[2] });
  assert.match(mr, /^MR, chosen by you \(the server chose CT, inferred:/, mr);
  assert.match(mr, /→ MR T1 brain, W 253 \/ L 141/, mr);
  assert.match(presetNote(greyCt, { modality: "CT", preset: null }), /→ your own curve$/);
  // Hounsfield units: whole numbers and the unit.
  const hu = { ...greyCt, hounsfield: true, presets: [preset("ct.lung", "CT lung", "CT", 1500, -600)] };
  assert.match(presetNote(hu, { modality: "CT", preset: hu.presets[0] }), /W 1500 \/ L -600 HU/);
});

test("window and level numbers: whole HU, else three significant digits, whole units above 100", () => {
  assert.equal(displayNumber(176.896), 177);    // an MR window once shown cut in its field
  assert.equal(displayNumber(108.148), 108);
  assert.equal(displayNumber(52.6123), 52.6);
  assert.equal(displayNumber(0.045678), 0.0457);
  assert.equal(displayNumber(12345.6), 12346);
  assert.equal(displayNumber(-600.4, { hounsfield: true }), -600);
  assert.equal(displayNumber(40.5, { hounsfield: true }), 41);
  assert.ok(Object.is(displayNumber(-0.0001, { hounsfield: true }), 0), "no -0");
  // Short enough for an 80 px field: at most 6 characters for these.
  for (const x of [176.896, 0.045678, -1234.5678, 52.6123]) assert.ok(String(displayNumber(x)).length <= 6, String(displayNumber(x)));
});

test("a too_large error is worded about the picture; the flag stays in the server's message", () => {
  const samples = tooLargeWords({ code: "too_large", message: "a frame of this view at step 0.5 is predicted to take 7.84e+09 samples (…) over the server's limit of 4.29e+09 (--max-samples-per-frame); use a larger step" });
  assert.match(samples.title, /rendering work/);
  assert.doesNotMatch(samples.title + samples.detail, /--|samples|e\+0/);
  assert.match(samples.detail, /Automatic quality/);
  const memory = tooLargeWords({ message: "… over the server's limit of 1024 MiB (--max-request-mib)" });
  assert.match(memory.title, /image memory/);
  assert.match(tooLargeWords({ message: "a still of 8192x8192 … (--max-still-pixels)" }).title, /saved picture/);
  assert.match(tooLargeWords({ message: "the message is 100000 bytes" }).title, /too large/);
});

test("the overlay's lowered line is the frame header's own words, or nothing", () => {
  assert.equal(limitedLine({ limited: "image scale 0.5 to stay within the server's per-frame limit" }),
    "image scale 0.5 to stay within the server's per-frame limit");
  assert.equal(limitedLine({}), "");
  assert.equal(limitedLine(null), "");
});
