// Presets the user controls and any window size, in headless Chromium against a real
// volcast-server on the 8-bit chest CT (lidc2_chest_ct: CT windowed to grey values by its
// source): the modality picker offers every modality the server has presets for, the lung
// preset shows the lungs, another modality's presets are reachable and the note follows the
// choice; a 3840×2160 window gets a final frame within the server's default limits, and the
// stats overlay says what was lowered. Screenshots go to the artifacts folder (presets-*.png).
import { after, before, test } from "node:test";
import assert from "node:assert/strict";
import { existsSync } from "node:fs";
import path from "node:path";

import { DATA_DIR, canvasSummary, checkPrerequisites, launchBrowser, openPage, screenshot, startServer, updateDocScreenshot, waitForFinal } from "./harness.mjs";

const missing = checkPrerequisites();
if (missing.length) throw new Error(`cannot run the browser tests:\n  ${missing.join("\n  ")}`);

const CHEST = "lidc2_chest_ct.nhdr";
const haveScan = Boolean(DATA_DIR) && existsSync(path.join(DATA_DIR, CHEST));
const skip = !haveScan && `no ${CHEST} in VOLCAST_DATA_DIR`;

let server, browser, page, problems;

before(async () => {
  if (!haveScan) return;
  server = await startServer(0);
  browser = await launchBrowser();
  ({ page, problems } = await openPage(browser.context, `${server.url}?volume=${encodeURIComponent(CHEST)}`));
  await page.waitForFunction((name) => window.volcast.session.volume?.name === name, CHEST, { timeout: 120000 });
}, { timeout: 180000 });

after(async () => {
  await browser?.close();
  await server?.stop();
});

// Send nothing more until the view shows a final frame answering the latest request.
async function settle() {
  const id = await page.evaluate(() => window.sentLog.filter((m) => typeof m.id === "number").at(-1)?.id ?? 0);
  return waitForFinal(page, { minRequest: id, timeout: 120000 });
}

const options = (selector) => page.$$eval(`${selector} option`, (os) => os.map((o) => o.value).filter(Boolean));

test("the 8-bit chest CT is CT, every modality is offered, and the lung preset shows the lungs", { skip }, async () => {
  await settle();
  assert.equal(await page.$eval("#tf-modality", (el) => el.value), "CT");
  assert.deepEqual(await options("#tf-modality"), ["CT", "MR", "micro-CT"]);
  const ct = await options("#tf-preset");
  for (const name of ["ct.bone", "ct.soft_tissue", "ct.lung", "ct.angiography"]) assert.ok(ct.includes(name), `${name} in ${ct}`);
  const bone = await canvasSummary(page);

  await page.selectOption("#tf-preset", "ct.lung");
  await settle();
  const note = await page.textContent("#preset-reason");
  assert.match(note, /^CT \(inferred\)/, note);
  assert.match(note, /→ CT lung \(grey values\), W \d+ \/ L [\d.]+, shaded$/, note);
  // W/L fields: grey values at three significant digits at most, never a long decimal.
  for (const id of ["#tf-window", "#tf-level"]) assert.match(await page.inputValue(id), /^-?\d+(\.\d)?$/, id);
  // The lungs fill much of a chest's projection: with the lung preset a large share of the
  // canvas is lit (air and soft tissue are clear in it, renderer/model/presets.cpp), and the
  // picture differs from the bone preset's.
  const lung = await canvasSummary(page);
  assert.ok(lung.litFraction > 0.1, `lit fraction ${lung.litFraction} with the lung preset`);
  assert.notDeepEqual(lung.thumb, bone.thumb);
  await screenshot(page, "presets-lidc2-lung.png");
  updateDocScreenshot("presets-lidc2-lung.png", "presets-lidc2-lung.png");
});

test("another modality's presets are reachable and the note follows the choice", { skip }, async () => {
  await page.selectOption("#tf-modality", "MR");
  await settle();
  const mr = await options("#tf-preset");
  assert.deepEqual(mr.filter((n) => !n.startsWith("mr.")), [], `only MR presets offered: ${mr}`);
  assert.equal(await page.$eval("#tf-preset", (el) => el.value), "mr.t1_brain", "the modality's first preset is applied");
  let note = await page.textContent("#preset-reason");
  assert.match(note, /^MR, chosen by you \(the server chose CT, inferred/, note);
  assert.match(note, /→ MR T1 brain/, note);
  await page.selectOption("#tf-preset", "mr.t2_brain");
  await settle();
  note = await page.textContent("#preset-reason");
  assert.match(note, /→ MR T2 brain/, note);
  // Back to CT: its default (bone) is applied again.
  await page.selectOption("#tf-modality", "CT");
  await settle();
  assert.equal(await page.$eval("#tf-preset", (el) => el.value), "ct.bone");
  assert.deepEqual(problems, []);
});

test("a 3840×2160 window gets a final frame; the stats say what was lowered to fit", { skip }, async () => {
  const sent = await page.evaluate(() => window.sentLog.length);
  await page.setViewportSize({ width: 3840, height: 2160 });
  // The page tells the server its new size once the size has held for 150 ms (view.js's
  // RESIZE_SETTLE_MS): the final frame to check answers that message, not an earlier one.
  await page.waitForFunction((n) => window.sentLog.slice(n).some((m) => m.type === "viewport"), sent, { timeout: 30000 });
  const final = await settle();
  assert.equal(final.final, true);
  // The canvas's device pixels at that size predict far over the default 2^32 samples per
  // frame (lidc2: diagonal 385 voxels, shaded bone): the policy lowered the image scale.
  assert.match(final.limited ?? "", /image scale [\d.]+.*to stay within the server's/, JSON.stringify(final));
  assert.ok(final.quality.image_scale < 1, JSON.stringify(final.quality));
  const shown = await page.$eval("#stat-limited", (el) => ({ text: el.textContent, hidden: el.hidden }));
  assert.equal(shown.hidden, false);
  assert.equal(shown.text, final.limited);
  const refused = await page.$$eval("#errors .error", (es) => es.map((e) => e.dataset.code));
  assert.ok(!refused.includes("too_large"), `no too_large banner: ${refused}`);
  assert.equal(await page.isVisible("#view-message"), false, "no message over the view");
  await screenshot(page, "presets-4k.png");
  assert.deepEqual(problems, []);
});
