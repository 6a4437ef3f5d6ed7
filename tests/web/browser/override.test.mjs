// A file that names its patient axes (a NRRD in left-posterior-superior space, written
// here), in headless Chromium against a real volcast-server: the flips and turns sit behind
// "Override the file's orientation" until it is opened, a flip mirrors the image, and the
// card says the file's axes were corrected by hand. The volume is not a cube, so a quarter
// turn changes the box it is drawn in: the clip plane's slider spans that box. The slice
// panes follow a flip and a turn as the 3D view does.
// Saves the card's screenshot web/README.md shows (docs/images/web/orient-override.png) into the
// artifacts, and with VOLCAST_UPDATE_DOC_SCREENSHOTS=1 over the doc file.
import { test } from "node:test";
import assert from "node:assert/strict";
import { mkdirSync, mkdtempSync, rmSync, writeFileSync } from "node:fs";
import os from "node:os";
import path from "node:path";

import { artifact, keepCanvas, pixelsDiffering, shownSeq, updateDocScreenshot, waitForFinal } from "./harness.mjs";
import { pageUnderTest } from "./page_setup.mjs";

const SCAN = "oriented/slab.nrrd";   // server-relative name of the scan written below
const DIMS = [48, 32, 16];
const FLIP_LR = [[-1, 0, 0], [0, 1, 0], [0, 0, 1]];
const TURN_SI = [[0, -1, 0], [1, 0, 0], [0, 0, 1]];   // web/core/orientation.js's "turn-si"

// A 48 × 32 × 16 uint8 slab in LPS space, unit spacing, origin 0: a ball (120) at the
// centre and a block (250) towards the patient's left (+x), so a left-right flip shows.
function writeScan(folder) {
  const [nx, ny, nz] = DIMS, voxels = new Uint8Array(nx * ny * nz);
  for (let z = 0; z < nz; z++) for (let y = 0; y < ny; y++) for (let x = 0; x < nx; x++) {
    const ball = Math.hypot(x - 23.5, y - 15.5, z - 7.5) < 7;
    const block = x >= 36 && x <= 44 && y >= 10 && y <= 22 && z >= 3 && z <= 12;
    voxels[(z * ny + y) * nx + x] = block ? 250 : ball ? 120 : 0;
  }
  const header = "NRRD0004\ntype: uint8\ndimension: 3\nspace: left-posterior-superior\n" +
    `sizes: ${nx} ${ny} ${nz}\nspace directions: (1,0,0) (0,1,0) (0,0,1)\nspace origin: (0,0,0)\nencoding: raw\n\n`;
  mkdirSync(path.join(folder, "oriented"), { recursive: true });
  writeFileSync(path.join(folder, SCAN), Buffer.concat([Buffer.from(header, "latin1"), Buffer.from(voxels)]));
}

let dataDir;
let page, problems;
pageUnderTest({
  setUp: () => { dataDir = mkdtempSync(path.join(os.tmpdir(), "volcast-override-data-")); writeScan(dataDir); },
  serverOptions: () => ({ extraArgs: ["--data", dataDir] }),
  tearDown: () => { if (dataDir) rmSync(dataDir, { recursive: true, force: true }); },
  ready: (s) => ({ page, problems } = s),
});

const serverState = () => page.evaluate(() => window.volcast.session.getState());

// The next final frame after afterSeq whose quality has exactly this correction (null: none)
// and, with `anterior`, whose camera looks from −y with +z up.
async function finalWith(afterSeq, correction, anterior = false) {
  const handle = await page.waitForFunction(({ afterSeq, correction, anterior }) => {
    const h = window.volcast.shown;
    if (!h || !h.final || h.seq <= afterSeq) return null;
    if (JSON.stringify(h.quality?.orientation_correction ?? null) !== JSON.stringify(correction)) return null;
    if (anterior && !(h.camera.eye[1] < h.camera.target[1] && h.camera.up[2] === 1)) return null;
    return h;
  }, { afterSeq, correction, anterior }, { timeout: 90000, polling: 100 });
  return handle.jsonValue();
}

// The server's clip plane once its point along `axis` is `value` (the client's request has
// been applied); fails after 20 s with the plane it has.
async function serverClipAt(axis, value) {
  const deadline = Date.now() + 20000;
  let planes;
  while (Date.now() < deadline) {
    planes = (await serverState()).scene?.clip_planes ?? [];
    if (planes.length === 1 && planes[0].point[axis] === value) return planes[0];
    await new Promise((r) => setTimeout(r, 100));
  }
  assert.fail(`the server's clip plane did not reach ${value} along axis ${axis}: ${JSON.stringify(planes)}`);
}

// Where the block (250; the ball is 120) lies in the axial slice pane's own image, as the
// server cut it: its mean column and row relative to the image's centre, in mm. The
// image is radiological (columns towards the patient's left, rows towards posterior).
async function axialBlock() {
  await page.waitForFunction(() => {
    const p = window.volcast.slices.panes.axial;
    return p.image && !p.inFlight && !p.dirty;
  }, null, { timeout: 30000, polling: 50 });
  return page.evaluate(() => {
    const { image, header } = window.volcast.slices.panes.axial;
    let n = 0, cs = 0, rs = 0;
    for (let i = 0; i < header.width * header.height; i++) {
      if (image.data[4 * i] <= 200) continue;
      n++;
      cs += i % header.width;
      rs += Math.floor(i / header.width);
    }
    const mm = header.pixel_spacing;
    return { n, column: n ? (cs / n + 0.5 - header.width / 2) * mm : 0, row: n ? (rs / n + 0.5 - header.height / 2) * mm : 0 };
  });
}

const setClipPosition = (t) => page.$eval("#clip-position", (el, t) => { el.value = String(t); el.dispatchEvent(new Event("change")); }, t);

test("a file that names its patient axes keeps the flips and turns behind Override", async () => {
  await page.selectOption("#volume-select", SCAN);
  await page.waitForFunction((n) => window.volcast.session.volume?.name === n, SCAN, { timeout: 60000 });
  await waitForFinal(page);
  assert.equal(await page.evaluate(() => window.volcast.session.volume.orientation_known), true);
  assert.ok(await page.isHidden("#orientation-note"), "no 'orientation unknown' note for a file with patient axes");
  assert.match(await page.textContent("#orientation-status"), /views are anatomical/);
  assert.ok(await page.isVisible("#orientation-fix"));
  assert.match(await page.textContent("#orientation-fix > summary"), /Override the file's orientation/);
  assert.equal(await page.$eval("#orientation-fix", (el) => el.open), false, "Override starts closed");
  for (const id of ["flip-lr", "flip-ap", "flip-si", "turn-si", "turn-ap", "turn-lr", "fix-reset"])
    assert.ok(await page.isHidden(`#orientation-${id}`), `#orientation-${id} is hidden until Override is opened`);

  await page.click("#orientation-fix > summary");
  for (const id of ["flip-lr", "flip-ap", "flip-si", "turn-si", "turn-ap", "turn-lr", "fix-reset"])
    assert.ok(await page.isVisible(`#orientation-${id}`), `#orientation-${id} shows once Override is opened`);
  assert.match(await page.textContent("#orientation-fix-status"), /As the file places it/);
  // The file names its axes: anatomical labels everywhere, and no "Treat as" to offer.
  assert.ok(await page.isHidden("#orientation-treat"));
  assert.equal(await page.textContent("#view-anterior"), "Anterior");
  assert.equal(await page.textContent("#orientation-flip-lr"), "Flip L/R");
  await page.click("#view-anterior");
  assert.deepEqual(await page.$eval("#orientation-marker", (el) => [el.dataset.right, el.dataset.up, el.dataset.toward]), ["L", "S", "A"]);
  assert.deepEqual(await page.$$eval('.slice-pane[data-axis="axial"] .edge', (es) => es.map((e) => e.textContent.trim()).sort()), ["A", "L", "P", "R"]);
});

test("Override's Flip L/R mirrors the image; the card says the file's axes were corrected by hand", async () => {
  await page.evaluate(() => window.volcast.session.setTransferFunction({ points: [[0, 0, 0, 0, 0], [100, 0.9, 0.7, 0.5, 0.3], [255, 1, 1, 1, 0.95]] }));
  let seq = await shownSeq(page);
  await page.click("#view-anterior");
  await finalWith(seq, null, true);
  await keepCanvas(page, "overridePlain");
  // The block's centre is 16.5 mm towards the patient's left (+x): the axial slice's right half.
  const plainSlice = await axialBlock();
  assert.ok(plainSlice.n > 20 && plainSlice.column > 12 && plainSlice.column < 21, `axial slice before the flip: ${JSON.stringify(plainSlice)}`);

  seq = await shownSeq(page);
  await page.click("#orientation-flip-lr");
  const flipped = await finalWith(seq, FLIP_LR, true);
  assert.equal(flipped.codec, "png");
  await keepCanvas(page, "overrideFlipped");
  const pixels = flipped.width * flipped.height;
  const offMirror = await pixelsDiffering(page, "overridePlain", "overrideFlipped", true);
  const offPlain = await pixelsDiffering(page, "overridePlain", "overrideFlipped", false);
  // As in flip.test.mjs: the mirrored volume's rays differ from the plain one's mirrored in
  // float rounding only; the block on the patient's left moves to the other side.
  assert.ok(offMirror >= 0 && offMirror <= pixels * 1e-3, `${offMirror} of ${pixels} pixels differ from the mirrored plain image`);
  assert.ok(offPlain > 200 && offPlain > 20 * offMirror, `the flip changed too little: ${offPlain} pixels differ from the plain image, ${offMirror} from its mirror`);

  assert.deepEqual((await serverState()).scene.quality.orientation_correction, FLIP_LR);
  // The slice panes follow the flip, mirrored about the centre like the 3D view (they kept
  // the file's placement until something else made them slice again).
  const flippedSlice = await axialBlock();
  // 1 mm: a voxel; the pixels are finer, and the cut is symmetric about the centre.
  assert.ok(Math.abs(flippedSlice.column + plainSlice.column) <= 1 && Math.abs(flippedSlice.row - plainSlice.row) <= 1,
    `axial slice after Flip L/R ${JSON.stringify(flippedSlice)}, before ${JSON.stringify(plainSlice)}: not mirrored`);
  assert.match(await page.textContent("#orientation-fix-status"), /Overrides the file's orientation: flipped L\/R/);
  assert.match(await page.textContent("#orientation-status"), /corrected by hand \(flipped L\/R\)/);
  assert.ok(await page.isHidden("#orientation-note"), "the file's orientation is known: still no 'unknown' note");
  await page.locator("#orientation-card").screenshot({ path: artifact("override-card.png") });
  updateDocScreenshot("override-card.png", "orient-override.png");
});

test("after a quarter turn the clip slider spans the volume as drawn, not the file's box", async () => {
  let seq = await shownSeq(page);
  await page.click("#orientation-fix-reset");
  await finalWith(seq, null);
  // The file's box along x: −0.5 to 47.5 (cell extent, unit spacing); centre (23.5, 15.5, 7.5).
  await page.check("#clip-enabled");
  await page.selectOption("#clip-axis", "0");
  await setClipPosition(0);
  await serverClipAt(0, -0.5);

  // A quarter turn about S/I: x now spans the file's y extent, 32, about the centre.
  seq = await shownSeq(page);
  await page.click("#orientation-turn-si");
  await finalWith(seq, TURN_SI);
  // The slices turn too: the block, centred 16.5 mm towards +x and 0.5 mm towards +y of the
  // centre, is drawn 16.5 mm towards +y (posterior: the lower half) and 0.5 mm towards −x.
  const turnedSlice = await axialBlock();
  assert.ok(Math.abs(turnedSlice.row - 16.5) <= 1 && Math.abs(turnedSlice.column + 0.5) <= 1,
    `axial slice after the quarter turn: ${JSON.stringify(turnedSlice)}`);
  await serverClipAt(0, 23.5 - 16);
  assert.equal(await page.inputValue("#clip-position"), "0", "the slider kept its place");
  assert.equal(await page.textContent("#clip-position-out"), "7.5");
  await setClipPosition(1);
  await serverClipAt(0, 23.5 + 16);
  await setClipPosition(0.25);
  await serverClipAt(0, 23.5 - 16 + 8);
  // y spans the file's x extent, 48.
  await page.selectOption("#clip-axis", "1");
  await setClipPosition(1);
  await serverClipAt(1, 15.5 + 24);
  assert.deepEqual(problems, [], problems.join("\n"));
});
