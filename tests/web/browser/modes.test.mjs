// The compositing selector (MIP, MinIP) and the crop box sliders (web/app/crop_panel.js) in
// headless Chromium against a real volcast-server: each reaches the server in the quality
// policy, the state reports it back, and the image changes the way the mode says. Saves the
// screenshots web/README.md shows (web/doc/mip.png, web/doc/crop.png) into the artifacts.
import { after, before, test } from "node:test";
import assert from "node:assert/strict";

import {
  ARTIFACTS, canvasSummary, checkPrerequisites, launchBrowser, openPage, screenshot, shownSeq, startServer,
  thumbDifference, waitForFinal,
} from "./harness.mjs";

const missing = checkPrerequisites();
if (missing.length) throw new Error(`cannot run the browser tests:\n  ${missing.join("\n  ")}`);

let server, browser, page, problems;

before(async () => {
  server = await startServer(0);
  browser = await launchBrowser();
  ({ page, problems } = await openPage(browser.context, server.url));
  await page.waitForFunction(() => window.volcast.session.volume?.name === "builtin:demo", null, { timeout: 60000 });
  await waitForFinal(page);
}, { timeout: 240000 });

after(async () => {
  await browser?.close();
  await server?.stop();
  console.log(`artifacts in ${ARTIFACTS}`);
});

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
  const q = await serverQuality();
  assert.equal(q.compositing, undefined, "the default is not written");
  assert.deepEqual(q.crop, { min: [0, 0, 0], max: [1, 1, 0.55] });

  seq = await shownSeq(page);
  await page.click("#crop-reset");
  await finalWith(seq, {});
  assert.equal((await serverQuality()).crop, undefined);
  assert.deepEqual(problems, []);
});
