// The compositing selector (MIP, MinIP) and the crop box sliders (web/app/crop_panel.js) in
// headless Chromium against a real volcast-server: each reaches the server in the quality
// policy, the state reports it back, and the image changes the way the mode says. Saves the
// screenshots web/README.md shows (docs/images/web/mip.png, docs/images/web/crop.png) into the artifacts.
import { test } from "node:test";
import assert from "node:assert/strict";

import { canvasSummary, screenshot, shownSeq, thumbDifference, updateDocScreenshot } from "./harness.mjs";
import { pageUnderTest } from "./page_setup.mjs";

let page, problems;
pageUnderTest({ finalFrame: true, ready: (s) => ({ page, problems } = s) });

// The quality the server last reported for the session's scene.
const serverQuality = () => page.evaluate(async () => {
  const s = await window.volcast.session.getState();
  return s.scene?.quality ?? null;
});

// Wait until the view shows a final frame newer than afterSeq whose quality has exactly this
// compositing and crop (null: the key is absent, the default). Returns its header.
async function finalWith(afterSeq, { compositing = null, crop = null }) {
  const handle = await page.waitForFunction(({ afterSeq, compositing, crop }) => {
    const h = window.volcast.shown;
    if (!h || !h.final || h.seq <= afterSeq) return null;
    // Key order is the server's (nlohmann sorts "max" before "min"): compare face by face.
    const c = h.quality?.crop ?? null;
    const sameCrop = c === null || crop === null ? c === crop
      : JSON.stringify(c.min) === JSON.stringify(crop.min) && JSON.stringify(c.max) === JSON.stringify(crop.max);
    const same = (h.quality?.compositing ?? null) === compositing && sameCrop;
    return same ? h : null;
  }, { afterSeq, compositing, crop }, { timeout: 90000, polling: 100 });
  return handle.jsonValue();
}

test("the compositing selector switches to MIP and back; the frame says so", async () => {
  const emission = await canvasSummary(page);
  const seq = await shownSeq(page);
  await page.selectOption("#compositing", "mip");
  const final = await finalWith(seq, { compositing: "mip" });
  assert.equal(final.codec, "png");
  const q = await serverQuality();
  assert.equal(q.compositing, "mip");
  // A MIP of the phantom is a different picture from its emission–absorption rendering.
  const mip = await canvasSummary(page);
  assert.ok(mip.litFraction > 0.05, `MIP lit fraction ${mip.litFraction}`);
  assert.ok(thumbDifference(mip.thumb, emission.thumb) > 3, "MIP looks like emission–absorption");
  await screenshot(page, "modes-mip.png");
  updateDocScreenshot("modes-mip.png", "mip.png");
  assert.deepEqual(problems, []);
});

test("crop box sliders reach the server and remove what lies outside", async () => {
  const before = await canvasSummary(page);
  const seq = await shownSeq(page);
  // Keep x from 0.3 to 0.7: the crop box's faces, normalised box coordinates.
  await page.$eval("#crop-min-x", (el) => { el.value = "0.3"; el.dispatchEvent(new Event("change")); });
  await page.$eval("#crop-max-x", (el) => { el.value = "0.7"; el.dispatchEvent(new Event("change")); });
  await finalWith(seq, { compositing: "mip", crop: { min: [0.3, 0, 0], max: [0.7, 1, 1] } });
  const q = await serverQuality();
  assert.deepEqual(q.crop, { min: [0.3, 0, 0], max: [0.7, 1, 1] });
  const cropped = await canvasSummary(page);
  assert.ok(cropped.litFraction < before.litFraction, `cropping lit ${before.litFraction} → ${cropped.litFraction}`);
  assert.ok(cropped.litFraction > 0.01, "something is left inside the box");
  assert.equal(await page.$eval("#crop-min-x", (el) => el.nextElementSibling.value), "0.300");
  await screenshot(page, "modes-mip-cropped.png");
});

test("a face cannot pass its opposite", async () => {
  const seq = await shownSeq(page);
  await page.$eval("#crop-min-y", (el) => { el.value = "1"; el.dispatchEvent(new Event("change")); });
  const [lo, hi] = await page.evaluate(() => [Number(document.getElementById("crop-min-y").value), Number(document.getElementById("crop-max-y").value)]);
  assert.ok(lo < hi, `min ${lo} < max ${hi}`);
  await finalWith(seq, { compositing: "mip", crop: { min: [0.3, lo, 0], max: [0.7, 1, 1] } });
  await page.click("#crop-reset");
});

test("emission–absorption with a crop box; whole volume restores the image", async () => {
  let seq = await shownSeq(page);
  await page.selectOption("#compositing", "emission_absorption");
  await finalWith(seq, {});
  seq = await shownSeq(page);
  await page.$eval("#crop-max-z", (el) => { el.value = "0.55"; el.dispatchEvent(new Event("change")); });
  await finalWith(seq, { crop: { min: [0, 0, 0], max: [1, 1, 0.55] } });
  await screenshot(page, "modes-crop.png");
  updateDocScreenshot("modes-crop.png", "crop.png");
  const q = await serverQuality();
  assert.equal(q.compositing, undefined, "the default is not written");
  assert.deepEqual(q.crop, { min: [0, 0, 0], max: [1, 1, 0.55] });

  seq = await shownSeq(page);
  await page.click("#crop-reset");
  await finalWith(seq, {});
  assert.equal((await serverQuality()).crop, undefined);
  assert.deepEqual(problems, []);
});

test("dragging a crop slider is an interaction: cheap frames while it moves, the final frame after release", async () => {
  const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
  await page.$eval("#crop-card", (el) => { el.open = true; });
  const slider = page.locator("#crop-min-x");
  await slider.scrollIntoViewIfNeeded();
  const box = await slider.boundingBox();
  const y = box.y + box.height / 2;
  const sentBefore = await page.evaluate(() => window.sentLog.length);
  const seqBefore = await page.evaluate(() => window.volcast.frames.at(-1)?.seq ?? 0);
  const since = (seq) => page.evaluate((seq) => window.volcast.frames.filter((h) => h.seq > seq)
    .map((h) => ({ seq: h.seq, final: h.final, codec: h.codec, cropMinX: h.quality?.crop?.min?.[0] ?? 0 })), seq);

  // Press on the thumb (at 0: the slider's left end) and drag it over 40 % of the track in
  // steps 120 ms apart, shorter than the 250 ms an edit settles before a policy is sent alone.
  await page.mouse.move(box.x + 6, y);
  await page.mouse.down();
  for (let i = 1; i <= 12; i++) {
    await page.mouse.move(box.x + 6 + (i * box.width * 0.4) / 12, y);
    await sleep(120);
  }
  // Frames while it moves; taken before the pause below, since the server refines after
  // idleMs (150 ms) without input even while an interaction is open (a still hand gets the
  // sharp frame, as with a camera drag held still).
  const held = await since(seqBefore);
  await sleep(300);
  const sentHeld = await page.evaluate((n) => window.sentLog.slice(n).map((m) => m.type), sentBefore);
  const interactingHeld = await page.evaluate(async () => (await window.volcast.session.getState()).interacting);
  const seqAtRelease = held.at(-1)?.seq ?? seqBefore;
  await page.mouse.up();
  const value = Number(await page.inputValue("#crop-min-x"));

  // While held: interaction_start before the first policy, policies as the slider moves, and
  // the frames answering them are the interactive level's (JPEG, never final).
  assert.ok(value > 0.2, `the drag moved the slider to ${value}`);
  assert.equal(sentHeld[0], "interaction_start", `sent while held: ${sentHeld.join(", ")}`);
  assert.ok(sentHeld.filter((m) => m === "quality_policy").length >= 2, `policies sent while held: ${sentHeld.join(", ")}`);
  assert.ok(!sentHeld.includes("interaction_end"), `sent while held: ${sentHeld.join(", ")}`);
  assert.equal(interactingHeld, true, "the server's state says interacting while the slider is held");
  const cropped = held.filter((h) => h.cropMinX > 0);
  assert.ok(cropped.length >= 1, `frames with the moving crop arrived while the slider was held: ${JSON.stringify(held)}`);
  assert.deepEqual(cropped.filter((h) => h.final || h.codec !== "jpeg"), [], "frames while held are interactive JPEG, not final");

  // After release: interaction_end, and the refinement ends in a final PNG of the new crop.
  const final = await finalWith(seqAtRelease, { crop: { min: [value, 0, 0], max: [1, 1, 1] } });
  assert.equal(final.codec, "png");
  const sentAfter = await page.evaluate((n) => window.sentLog.slice(n).map((m) => m.type), sentBefore);
  assert.equal(sentAfter.at(-1), "interaction_end", `sent: ${sentAfter.join(", ")}`);
  assert.equal(await page.evaluate(async () => (await window.volcast.session.getState()).interacting), false);
  assert.deepEqual((await serverQuality()).crop, { min: [value, 0, 0], max: [1, 1, 1] });
  await screenshot(page, "modes-crop-drag.png");
  assert.deepEqual(problems, []);
});
