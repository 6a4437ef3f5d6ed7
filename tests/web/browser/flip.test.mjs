// A volume whose file names no patient axes (builtin:demo), in headless Chromium against a
// real volcast-server. Nothing on the page claims anatomy: no R/L/A/P/S/I letter on the
// buttons, the marker, the slice panes' edges or the saved image, which use the file's axes
// (+x, −y, …); "Treat as LPS" / "Treat as RAS" set the patient axes by hand and the labels
// then say so; the saved PNG is opaque, and with "letters and scale" carries them.
// Flips and quarter turns of the volume: "Flip x" (Flip L/R once the axes are set) mirrors the image (which no
// camera move can), the correction reaches the server as the scene's
// quality.orientation_correction, camera and transfer function changes keep it, the state and
// the saved scene hold it, and volcast-render draws the saved scene as the browser showed it.
// Saves the screenshot web/README.md shows (docs/images/web/flip.png) into the artifacts, and with
// VOLCAST_UPDATE_DOC_SCREENSHOTS=1 over docs/images/web/flip.png.
import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync, writeFileSync } from "node:fs";

import {
  RENDER_EXE, artifact, canvasSummary, download, keepCanvas, mirrored, pixelsDiffering, run, screenshot, shownSeq,
  thumbDifference, updateDocScreenshot,
} from "./harness.mjs";
import { assertNoAnatomy, directionLabels } from "./labels.mjs";
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

test("no anatomical label anywhere on the page, nor on the saved image: the file's axes instead", async () => {
  await page.waitForFunction(() => document.querySelectorAll(".slice-pane .edge").length === 12);
  const labels = await directionLabels(page);
  assertNoAnatomy(labels, "unoriented");
  assert.equal(labels.edges.length, 12, "four edge letters on each of three panes");
  assert.equal(await page.textContent("#view-anterior"), "From −y");
  assert.equal(await page.textContent("#orientation-flip-lr"), "Flip x");
  let seq = await shownSeq(page);
  await page.click("#view-anterior");
  await finalWith(seq, null, "anterior");
  assert.deepEqual((await page.$eval("#orientation-marker", (el) => [el.dataset.right, el.dataset.up, el.dataset.toward])), ["+x", "+z", "−y"]);

  // The saved PNG: opaque, the final frame over black; with letters and scale, the file's axes.
  const framePng = await page.evaluate(() => Array.from(new Uint8Array(window.volcast.session.lastFrame.image)));
  const plainPath = await download(page, "#save-png", "labels-saved-plain.png");
  const saved = decodePng(readFileSync(plainPath));
  const frame = decodePng(Buffer.from(framePng));
  assert.deepEqual([saved.width, saved.height], [frame.width, frame.height], "the rendered size");
  assert.equal(saved.channels, 4);
  for (let i = 3; i < saved.data.length; i += 4) if (saved.data[i] !== 255) assert.fail(`pixel ${(i - 3) / 4} has alpha ${saved.data[i]}: not opaque`);
  // The frame's straight RGBA over black, as the view shows it: the browser's premultiplied
  // decode rounds once (1/255); anything else (a transparent or grey background) is far off.
  const d = compareBytes(overBlack(saved), overBlack(frame));
  assert.ok(d.maxDiff <= 1, `saved vs the frame over black: max ${d.maxDiff}/255`);

  await page.check("#save-annotate");
  await download(page, "#save-png", "labels-saved-annotated.png").finally(() => page.uncheck("#save-annotate"));
  updateDocScreenshot("labels-saved-annotated.png", "saved-png-letters.png");
  const drawn = await page.evaluate(() => window.volcast.lastSaved);
  assert.deepEqual(drawn.labels, { right: "+x", left: "−x", top: "+z", bottom: "−z" });
  assert.match(drawn.note, /orientation unknown/);
  // The bar: 1, 2 or 5 × 10^k mm, at most a quarter of the width, at mm-per-pixel of the frame's camera.
  const cam = (await page.evaluate(() => window.volcast.shown.camera));
  const distance = Math.hypot(...cam.eye.map((e, i) => e - cam.target[i]));
  const perPx = (2 * distance * Math.tan((cam.fov_y_deg * Math.PI) / 360)) / frame.height;
  assert.ok(Math.abs(drawn.scale.mmPerPixel - perPx) < 1e-9 * perPx, JSON.stringify(drawn.scale));
  assert.match(String(drawn.scale.mm), /^[125]0*$|^0\.0*[125]$/);
  assert.ok(drawn.scale.pixels <= frame.width / 4 && drawn.scale.pixels > frame.width / 40, JSON.stringify(drawn.scale));
  assert.match(drawn.scale.words, /mm at the centre$/);
});

test("Treat as LPS / RAS set the patient axes by hand: anatomical labels that say so", async () => {
  let seq = await shownSeq(page);
  await page.click("#orientation-treat-lps");
  await page.waitForFunction(() => document.getElementById("orientation-marker").dataset.right === "L");
  assert.match(await page.textContent("#orientation-note"), /set by hand \(the file's axes taken as LPS\)/);
  assert.match(await page.textContent("#orientation-fix-status"), /set by hand/);
  assert.equal(await page.textContent("#view-anterior"), "Anterior");
  assert.equal(await page.textContent("#orientation-flip-lr"), "Flip L/R");
  const edges = (await directionLabels(page)).edges;
  assert.deepEqual(edges.slice(0, 4).sort(), ["A", "L", "P", "R"], `axial pane edges ${edges}`);
  // LPS changes nothing on the server: no correction.
  assert.equal((await serverQuality())?.orientation_correction, undefined);
  await finalWith(seq, null);
  await page.check("#save-annotate");
  await download(page, "#save-png", "labels-saved-lps.png").finally(() => page.uncheck("#save-annotate"));
  const drawn = await page.evaluate(() => window.volcast.lastSaved);
  // The anterior view of the test before: the patient's left on the right, superior up.
  assert.deepEqual(drawn.labels, { right: "L", left: "R", top: "S", bottom: "I" });
  assert.equal(drawn.note, "patient axes set by hand");

  // RAS: x and y mirrored into LPS, as the loader does for a file in RAS.
  seq = await shownSeq(page);
  await page.click("#orientation-treat-ras");
  await finalWith(seq, [[-1, 0, 0], [0, -1, 0], [0, 0, 1]]);
  assert.deepEqual((await serverQuality()).orientation_correction, [[-1, 0, 0], [0, -1, 0], [0, 0, 1]]);
  assert.match(await page.textContent("#orientation-note"), /taken as RAS/);

  // "As the file says": unknown again, the file's axes again.
  seq = await shownSeq(page);
  await page.click("#orientation-fix-reset");
  await finalWith(seq, null);
  assertNoAnatomy(await directionLabels(page), "after As the file says");
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
  assert.match(await page.textContent("#orientation-note"), /set by hand \(flipped L\/R\)/);
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
  // The slice panes' view and the orientation travel beside the picture, as in a view link.
  const panes = await page.evaluate(() => ({ point: window.volcast.slices.point, wl: window.volcast.slices.wl }));
  assert.deepEqual(scene.viewer.crosshair, panes.point, JSON.stringify(scene.viewer));
  assert.deepEqual(scene.viewer.slice_window, panes.wl, JSON.stringify(scene.viewer));
  assert.ok(scene.viewer.orientation, JSON.stringify(scene.viewer));

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
