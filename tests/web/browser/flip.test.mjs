// Flips and quarter turns of a volume whose file names no patient axes (issue 16, item 1), in
// headless Chromium against a real volcast-server: "Flip L/R" mirrors the image (which no
// camera move can), the correction reaches the server as the scene's
// quality.orientation_correction, camera and transfer function changes keep it, the state and
// the saved scene hold it, and volcast-render draws the saved scene as the browser showed it.
// Saves the screenshot web/README.md shows (web/doc/flip.png) into the artifacts, and with
// VOLCAST_UPDATE_DOC_SCREENSHOTS=1 over web/doc/flip.png.
import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync, writeFileSync } from "node:fs";

import {
  RENDER_EXE, artifact, canvasSummary, download, keepCanvas, mirrored, pixelsDiffering, run, screenshot, shownSeq,
  thumbDifference, updateDocScreenshot,
} from "./harness.mjs";
import { pageUnderTest } from "./page_setup.mjs";
import { compareBytes, decodePng, overBlack } from "../lib/png.mjs";

const FLIP_LR = [[-1, 0, 0], [0, 1, 0], [0, 0, 1]];

let page, problems;
pageUnderTest({ ready: (s) => ({ page, problems } = s) });

const serverQuality = () => page.evaluate(async () => (await window.volcast.session.getState()).scene?.quality ?? null);

// The next final frame after afterSeq whose quality has exactly this correction (null: none)
// and, if `view` is given, whose camera looks from that side ("anterior": from −y, head up;
// "posterior": from +y).
async function finalWith(afterSeq, correction, view = null) {
  const handle = await page.waitForFunction(({ afterSeq, correction, view }) => {
    const h = window.volcast.shown;
    if (!h || !h.final || h.seq <= afterSeq) return null;
    if (JSON.stringify(h.quality?.orientation_correction ?? null) !== JSON.stringify(correction)) return null;
    const c = h.camera;
    if (view === "anterior" && !(c.eye[1] < c.target[1] && c.up[2] === 1)) return null;
    if (view === "posterior" && !(c.eye[1] > c.target[1])) return null;
    return h;
  }, { afterSeq, correction, view }, { timeout: 90000, polling: 100 });
  return handle.jsonValue();
}

test("a volume without patient axes offers the flips and turns, open, beside the unknown-orientation note", async () => {
  assert.equal(await page.evaluate(() => window.volcast.session.volume.orientation_known), false);
  assert.ok(await page.isVisible("#orientation-note"));
  for (const id of ["flip-lr", "flip-ap", "flip-si", "turn-si", "turn-ap", "turn-lr"])
    assert.ok(await page.isVisible(`#orientation-${id}`), `#orientation-${id} is visible`);
  assert.match(await page.textContent("#orientation-fix-status"), /As the file places it/);
});

test("Flip L/R mirrors the image; the server keeps the correction", async () => {
  // From the front: image x is world x, so a left-right flip is a mirror about the vertical.
  let seq = await shownSeq(page);
  await page.click("#view-anterior");
  await finalWith(seq, null, "anterior");
  const plain = await canvasSummary(page);
  await keepCanvas(page, "flipTestPlain");

  seq = await shownSeq(page);
  await page.click("#orientation-flip-lr");
  const flippedHeader = await finalWith(seq, FLIP_LR);
  assert.equal(flippedHeader.codec, "png");
  const flipped = await canvasSummary(page);
  await keepCanvas(page, "flipTestFlipped");
  await screenshot(page, "flip.png");
  updateDocScreenshot("flip.png", "flip.png");

  const toMirror = thumbDifference(mirrored(plain.thumb), flipped.thumb);
  const toPlain = thumbDifference(plain.thumb, flipped.thumb);
  const pixels = plain.width * plain.height;
  const offMirror = await pixelsDiffering(page, "flipTestPlain", "flipTestFlipped", true);
  const offPlain = await pixelsDiffering(page, "flipTestPlain", "flipTestFlipped", false);
  writeFileSync(artifact("flip-comparison.json"), `${JSON.stringify({ toMirror, toPlain, offMirror, offPlain, pixels }, null, 2)}\n`);
  // The thumbnail samples pixel floor((t + ½)/32 · W) and its mirror W − 1 − that, one pixel
  // apart at most: the mirrored frames' thumbnails agree to a few levels on edges only.
  assert.ok(toMirror < 2, `the flipped image is not the mirror of the plain one: mean thumbnail difference ${toMirror.toFixed(2)}/255`);
  // Full resolution: the frame is drawn pixel for pixel, and the same rays through the
  // mirrored volume differ in float rounding only, far below 16 levels; the demo's vessels
  // and the ball on one side are not mirror-symmetric, so the plain frame differs in many.
  assert.ok(offMirror >= 0, "the two canvases have different sizes");
  assert.ok(offMirror <= pixels * 1e-3, `${offMirror} of ${pixels} pixels differ from the mirrored plain image`);
  assert.ok(offPlain > 200 && offPlain > 20 * offMirror,
    `the flip changed too little to tell: ${offPlain} pixels differ from the plain image, ${offMirror} from its mirror`);

  assert.deepEqual((await serverQuality()).orientation_correction, FLIP_LR);
  assert.match(await page.textContent("#orientation-fix-status"), /flipped L\/R/);
  assert.match(await page.textContent("#orientation-note"), /corrected by hand/);
});

test("camera and transfer function changes keep the correction", async () => {
  let seq = await shownSeq(page);
  await page.click("#view-posterior");
  await finalWith(seq, FLIP_LR, "posterior");
  seq = await shownSeq(page);
  await page.evaluate(() => window.volcast.session.setTransferFunction({ points: [[0, 0, 0, 0, 0], [120, 1, 0.8, 0.6, 0.05], [255, 1, 1, 1, 0.9]] }));
  await finalWith(seq, FLIP_LR);
  assert.deepEqual((await serverQuality()).orientation_correction, FLIP_LR);
});

test("turns compose with the flip; 'As the file says' removes them", async () => {
  let seq = await shownSeq(page);
  await page.click("#orientation-turn-si");
  // turn about z · flip x: x → −y, y → x.
  const turned = [[0, -1, 0], [-1, 0, 0], [0, 0, 1]];
  await finalWith(seq, turned);
  assert.deepEqual((await serverQuality()).orientation_correction, turned);
  seq = await shownSeq(page);
  await page.click("#orientation-fix-reset");
  await finalWith(seq, null);
  assert.equal((await serverQuality()).orientation_correction, undefined);
  seq = await shownSeq(page);
  await page.click("#orientation-flip-lr");
  await finalWith(seq, FLIP_LR);
});

test("the saved scene holds the correction, and volcast-render draws it as the browser did", async (t) => {
  const final = await finalWith(0, FLIP_LR);
  const pngPath = await download(page, "#save-png", "flip-final-frame.png");
  const scenePath = await download(page, "#save-scene", "flip-scene.json");
  const scene = JSON.parse(readFileSync(scenePath, "utf8"));
  assert.deepEqual(scene.quality.orientation_correction, FLIP_LR, JSON.stringify(scene.quality));
  assert.deepEqual(scene.quality, final.quality);

  const outPath = artifact("flip-volcast-render.png");
  const r = await run(RENDER_EXE, [scenePath, "-o", outPath]);
  assert.equal(r.code, 0, `volcast-render failed:\n${r.err}${r.out}`);
  const mine = decodePng(readFileSync(pngPath));
  const theirs = decodePng(readFileSync(outPath));
  assert.deepEqual([mine.width, mine.height], [theirs.width, theirs.height]);
  // As in client.test.mjs: straight RGBA re-premultiplied over black is off by at most 1/255,
  // 2 where a rounding boundary is hit exactly; a flip lost on the way would differ by far more.
  const d = compareBytes(overBlack(mine), overBlack(theirs));
  t.diagnostic(`final frame vs volcast-render: max ${d.maxDiff}/255, ${d.channelsOver1} channels over 1/255`);
  assert.ok(d.maxDiff <= 1 || (d.maxDiff === 2 && d.channelsOver1 * 1e4 < mine.width * mine.height),
    `max channel difference ${d.maxDiff}/255 (${d.channelsOver1} channels over 1)`);
  assert.deepEqual(problems, [], problems.join("\n"));
});
