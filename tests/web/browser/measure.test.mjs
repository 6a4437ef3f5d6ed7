// Measurements, slabs, the projection window and the crop handles (web/app/measure_tools.js,
// web/app/crop_handles.js, web/app/slice_views.js, web/app/crop_panel.js) in headless
// Chromium against a real volcast-server, on a CT volume the test writes itself so that every
// number has a known answer:
//
//   32 × 32 × 24 int16 voxels, spacing 0.8 × 0.8 × 2 mm, origin 0, left-posterior-superior;
//   air (−1000 HU) everywhere but a block of index x 8…23, y 8…23, z 6…17, which is soft
//   tissue (40 HU) for x < 16 and bone (1000 HU) for x ≥ 16.
//
// World point of index (i, j, k) = (0.8 i, 0.8 j, 2 k) mm.
import { test } from "node:test";
import assert from "node:assert/strict";
import { mkdirSync, mkdtempSync, rmSync, writeFileSync } from "node:fs";
import os from "node:os";
import path from "node:path";

import { VIEWPORT, screenshot, shownSeq, updateDocScreenshot, waitForFinal } from "./harness.mjs";
import { pageUnderTest } from "./page_setup.mjs";

const SCAN = "measure/ct.nrrd";
const DIMS = [32, 32, 24], SPACING = [0.8, 0.8, 2];
const AIR = -1000, SOFT = 40, BONE = 1000;
const BLOCK = { lo: [8, 8, 6], hi: [23, 23, 17] };   // inclusive index ranges
const BONE_FROM_X = 16;
const valueAt = (x, y, z) => {
  const inBlock = [x, y, z].every((v, a) => v >= BLOCK.lo[a] && v <= BLOCK.hi[a]);
  return !inBlock ? AIR : x >= BONE_FROM_X ? BONE : SOFT;
};
const world = (i, j, k) => [i * SPACING[0], j * SPACING[1], k * SPACING[2]];
const CENTRE = world((DIMS[0] - 1) / 2, (DIMS[1] - 1) / 2, (DIMS[2] - 1) / 2);

let dataDir;
function writeScan() {
  dataDir = mkdtempSync(path.join(os.tmpdir(), "volcast-measure-data-"));
  const [nx, ny, nz] = DIMS;
  const voxels = Buffer.alloc(nx * ny * nz * 2);
  for (let z = 0; z < nz; z++) for (let y = 0; y < ny; y++) for (let x = 0; x < nx; x++) {
    voxels.writeInt16LE(valueAt(x, y, z), 2 * ((z * ny + y) * nx + x));
  }
  const header = "NRRD0004\ntype: int16\ndimension: 3\nspace: left-posterior-superior\n" +
    `sizes: ${nx} ${ny} ${nz}\nspace directions: (${SPACING[0]},0,0) (0,${SPACING[1]},0) (0,0,${SPACING[2]})\n` +
    "space origin: (0,0,0)\nendian: little\nencoding: raw\nmodality:=CT\n\n";
  mkdirSync(path.join(dataDir, "measure"), { recursive: true });
  writeFileSync(path.join(dataDir, SCAN), Buffer.concat([Buffer.from(header, "latin1"), voxels]));
}

let page, problems;
pageUnderTest({
  setUp: writeScan,
  tearDown: () => dataDir && rmSync(dataDir, { recursive: true, force: true }),
  serverOptions: () => ({ extraArgs: ["--data", dataDir] }),
  query: `?volume=${encodeURIComponent(SCAN)}`,
  volume: SCAN,
  finalFrame: true,
  ready: (s) => ({ page, problems } = s),
});

const AXES = ["axial", "coronal", "sagittal"];
const closeTo = (a, b, tol, what) => assert.ok(Math.abs(a - b) <= tol, `${what}: ${a} vs ${b} (±${tol})`);

const waitSettled = () => page.waitForFunction((axes) => axes.every((a) => {
  const p = window.volcast.slices.panes[a];
  return p.header && !p.inFlight && !p.dirty;
}), AXES, { timeout: 30000, polling: 50 });

// The CSS position (page coordinates) of a world point on a pane, with its fit.
const paneSpot = (axis, p) => page.evaluate(({ axis, p }) => {
  const s = window.volcast.slices, pane = s.panes[axis], h = pane.header;
  const rect = pane.canvas.getBoundingClientRect();
  const fit = s.fitOf(pane);
  const d = [0, 1, 2].map((i) => p[i] - h.origin[i]);
  const c = (d[0] * h.column[0] + d[1] * h.column[1] + d[2] * h.column[2]) / h.pixel_spacing;
  const r = (d[0] * h.row[0] + d[1] * h.row[1] + d[2] * h.row[2]) / h.pixel_spacing;
  return { x: rect.left + fit.x + (c + 0.5) * fit.scale, y: rect.top + fit.y + (r + 0.5) * fit.scale,
    mmPerCssPx: h.pixel_spacing / fit.scale };
}, { axis, p });

const lastMeasurement = () => page.evaluate(() => {
  const m = window.volcast.measure.last;
  return m && { kind: m.kind, mm: m.mm, text: m.text, answer: m.answer, point: m.point, center: m.center, radii: m.radii };
});

// Wait for the latest measurement to be of this kind and complete (answered by the server).
async function measureDone(kind) {
  await page.waitForFunction((kind) => {
    const m = window.volcast.measure.last;
    return m && m.kind === kind && (kind === "distance" || m.answer);
  }, kind, { timeout: 30000, polling: 50 });
  return lastMeasurement();
}

test("the crosshair starts at the new volume's centre, also after switching quickly", async () => {
  await waitSettled();
  let point = await page.evaluate(() => window.volcast.slices.point);
  CENTRE.forEach((v, i) => closeTo(point[i], v, 1e-9, `centre[${i}]`));
  // Open the demo phantom and, before its slices come back, this volume again: the slices
  // and the crosshair are this volume's (an answer about the demo is dropped).
  await page.evaluate((scan) => { window.volcast.session.openVolume("builtin:demo"); setTimeout(() => window.volcast.session.openVolume(scan), 30); }, SCAN);
  await page.waitForFunction((scan) => window.volcast.session.volume?.name === scan && !window.volcast.session.loading, SCAN, { timeout: 60000 });
  await waitSettled();
  point = await page.evaluate(() => window.volcast.slices.point);
  CENTRE.forEach((v, i) => closeTo(point[i], v, 1e-9, `centre after switching[${i}]`));
  const headers = await page.evaluate((axes) => axes.map((a) => window.volcast.slices.panes[a].header.point), AXES);
  for (const h of headers) CENTRE.forEach((v, i) => closeTo(h[i], v, 1e-9, "each pane cut through the centre"));
});

test("after the quick switch the view still refines to a final frame", async () => {
  try {
    await waitForFinal(page);
  } catch (e) {
    const seen = await page.evaluate(async () => ({ frames: window.volcast.frames.slice(-5).map((h) => ({ seq: h.seq, final: h.final, request: h.request, level: h.level, limited: h.limited, codec: h.codec, width: h.width, height: h.height, quality: h.quality })),
      sent: window.sentLog.slice(-12), state: await window.volcast.session.getState().then((s) => ({ interacting: s.interacting, volume: s.volume?.name }), (x) => String(x)) }));
    throw new Error(`no final frame after switching volumes: ${JSON.stringify(seen)} (${e.message})`);
  }
});

test("the wheel steps the axial pane one slice (2 mm) at a time; the other panes keep their planes", async () => {
  await waitSettled();
  const before = await page.evaluate(() => ({ coronal: window.volcast.slices.panes.coronal.header, z: window.volcast.slices.point[2] }));
  const box = await page.$eval('.slice-pane[data-axis="axial"] canvas', (el) => el.getBoundingClientRect().toJSON());
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.wheel(0, 100);   // one notch down
  await page.waitForFunction((z) => Math.abs(window.volcast.slices.panes.axial.header.point[2] - z) > 1e-6, before.z, { timeout: 30000 });
  await waitSettled();
  let after = await page.evaluate(() => ({ coronal: window.volcast.slices.panes.coronal.header, axialZ: window.volcast.slices.panes.axial.header.point[2], z: window.volcast.slices.point[2] }));
  closeTo(after.z - before.z, SPACING[2], 1e-9, "one notch = the z spacing");
  closeTo(after.axialZ, after.z, 1e-9, "the axial pane is cut at the new z");
  assert.deepEqual(after.coronal, before.coronal, "the coronal pane was not re-sliced (the point moved within its plane)");
  // Many notches up stop at the last slice's centre: index 23 → z 46 mm.
  await page.mouse.wheel(0, 100 * 30);
  await page.waitForFunction(() => Math.abs(window.volcast.slices.point[2] - 46) < 1e-6, null, { timeout: 30000 });
  await page.mouse.wheel(0, -100 * 30);
  await page.waitForFunction(() => Math.abs(window.volcast.slices.point[2] - 0) < 1e-6, null, { timeout: 30000 });
  // By keyboard on the focused pane: ↓ one slice up the normal, as a notch down.
  await page.focus('.slice-pane[data-axis="axial"] canvas');
  await page.keyboard.press("ArrowDown");
  await page.waitForFunction(() => Math.abs(window.volcast.slices.point[2] - 2) < 1e-6, null, { timeout: 30000 });
  // Back to the centre for the tests below.
  await page.evaluate((c) => window.volcast.slices.setPoint(c), CENTRE);
  await waitSettled();
  assert.deepEqual(problems, []);
});

test("a distance dragged on the axial pane is the pixel distance times the pixel spacing", async () => {
  await page.click('.slices-tools button[data-tool="distance"]');
  const a = world(6, 10, 11.5), b = world(26, 25, 11.5);   // 16 mm along x, 12 along y: 20 mm
  const pa = await paneSpot("axial", a), pb = await paneSpot("axial", b);
  await page.mouse.move(pa.x, pa.y);
  await page.mouse.down();
  await page.mouse.move((pa.x + pb.x) / 2, (pa.y + pb.y) / 2);
  await page.mouse.move(pb.x, pb.y);
  await page.mouse.up();
  const m = await measureDone("distance");
  // The pointer lands on the spots to within a CSS pixel each end (event coordinates).
  closeTo(m.mm, 20, Math.SQRT2 * pa.mmPerCssPx * 2, "distance in mm");
  assert.equal(await page.textContent(".measure-readout"), `Distance ${m.text}`);
  await screenshot(page, "measure-distance.png");
});

test("the value probe shows the known voxel values, in HU", async () => {
  await page.click('.slices-tools button[data-tool="probe"]');
  // Soft tissue at index (12, 12) and bone at (20, 12), both 3+ voxels from any edge, so the
  // trilinear value is the voxels' own wherever within a CSS pixel the click lands.
  for (const [i, expected] of [[12, SOFT], [20, BONE], [3, AIR]]) {
    const spot = await paneSpot("axial", world(i, 12, 11.5));
    const since = await page.evaluate(() => window.volcast.measure.last);
    await page.mouse.click(spot.x, spot.y);
    await page.waitForFunction(() => window.volcast.measure.last?.kind === "probe" && window.volcast.measure.last.answer &&
      !window.volcast.measure.readout.textContent.includes("asking"), null, { timeout: 30000 });
    await page.waitForFunction((p) => window.volcast.measure.last?.point?.[0] !== p?.point?.[0], since, { timeout: 30000 });
    const m = await lastMeasurement();
    assert.equal(m.answer.inside, true);
    assert.equal(m.answer.value, expected, `value at index x ${i}`);
    assert.equal(m.answer.unit, "HU", "a CT in Hounsfield units");
    assert.equal(m.text, `${expected} HU`);
    assert.match(await page.textContent(".measure-readout"), new RegExp(`: ${expected} HU$`));
  }
  // The server's probe at an exact voxel centre, through the session.
  const direct = await page.evaluate((p) => window.volcast.session.probe(p), world(20, 9, 7));
  assert.equal(direct.value, BONE);
  const outside = await page.evaluate(() => window.volcast.session.probe([-50, 0, 0]));
  assert.deepEqual([outside.inside, outside.value], [false, null]);
  await screenshot(page, "measure-probe.png");
});

test("an ROI ellipse gives the mean, SD and area of the region inside it", async () => {
  await page.click('.slices-tools button[data-tool="roi"]');
  // Inside the soft tissue: x index 9…14, y index 9…21 → mean 40, SD 0.
  const p0 = world(9, 9, 11.5), p1 = world(14, 21, 11.5);
  const s0 = await paneSpot("axial", p0), s1 = await paneSpot("axial", p1);
  await page.mouse.move(s0.x, s0.y);
  await page.mouse.down();
  await page.mouse.move(s1.x, s1.y);
  await page.mouse.up();
  let m = await measureDone("roi");
  assert.equal(m.answer.mean, SOFT);
  assert.equal(m.answer.std, 0);
  assert.deepEqual([m.answer.min, m.answer.max], [SOFT, SOFT]);
  assert.equal(m.answer.unit, "HU");
  // The area is the ellipse's, π·a·b, to within the sample grid: cells of at most half the
  // smallest spacing (0.4 mm) a side along the perimeter (< its length × 0.4 mm).
  const [a, b] = m.radii;
  closeTo(a, 2, s0.mmPerCssPx, "radius a (mm)");
  closeTo(b, 4.8, s0.mmPerCssPx, "radius b (mm)");
  const perimeter = Math.PI * (3 * (a + b) - Math.sqrt((3 * a + b) * (a + 3 * b)));   // Ramanujan
  closeTo(m.answer.area_mm2, Math.PI * a * b, perimeter * 0.4, "area");
  assert.match(await page.textContent(".measure-readout"), /^ROI mean 40 ± 0 HU · /);

  // Across the soft tissue / bone boundary: both values inside, so SD > 0.
  const q0 = await paneSpot("axial", world(12, 10, 11.5)), q1 = await paneSpot("axial", world(20, 14, 11.5));
  await page.mouse.move(q0.x, q0.y);
  await page.mouse.down();
  await page.mouse.move(q1.x, q1.y);
  await page.mouse.up();
  await page.waitForFunction(() => window.volcast.measure.last?.kind === "roi" && window.volcast.measure.last.center?.[0] > 12, null, { timeout: 30000 });
  await page.waitForFunction(() => window.volcast.measure.last.answer, null, { timeout: 30000 });
  m = await lastMeasurement();
  assert.deepEqual([m.answer.min, m.answer.max], [SOFT, BONE]);
  assert.ok(m.answer.std > 0 && m.answer.mean > SOFT && m.answer.mean < BONE, JSON.stringify(m.answer));
  await screenshot(page, "measure-roi.png");
  // The distance, the three values and the two ellipses on the axial pane, for web/README.md,
  // in a 1600 × 900 window with a 600 px column: two columns of panes.
  const seq = await shownSeq(page);
  await page.setViewportSize({ width: 1600, height: 900 });
  await page.evaluate(() => window.volcast.slices.setWidth(600));
  await page.waitForFunction(() => document.querySelector(".slice-panes").classList.contains("two-columns"), null, { timeout: 10000 });
  await page.waitForTimeout(300);   // the panes' resize observer asks for the new sizes
  await waitSettled();
  await waitForFinal(page, { afterSeq: seq });
  await screenshot(page, "measure-readme.png");
  updateDocScreenshot("measure-readme.png", "measure.png");
  await page.setViewportSize({ width: VIEWPORT.width, height: VIEWPORT.height });
  await page.evaluate(() => window.volcast.slices.setWidth(300));
  await page.waitForTimeout(300);
  await waitSettled();
  await page.click('.slices-tools button[data-tool="clear"]');
  await page.click('.slices-tools button[data-tool="crosshair"]');
});

// The grey of the axial pane's pixel at a world point (the slice image's own pixel).
const slicePixel = (axis, p) => page.evaluate(({ axis, p }) => {
  const pane = window.volcast.slices.panes[axis], h = pane.header;
  const d = [0, 1, 2].map((i) => p[i] - h.origin[i]);
  const c = Math.round((d[0] * h.column[0] + d[1] * h.column[1] + d[2] * h.column[2]) / h.pixel_spacing);
  const r = Math.round((d[0] * h.row[0] + d[1] * h.row[1] + d[2] * h.row[2]) / h.pixel_spacing);
  return pane.image.data[4 * (r * h.width + c)];
}, { axis, p });

test("a thick slab projects the axial pane: MIP finds the bone 1 slice away, MinIP the air", async () => {
  // z index 19 (38 mm) is above the block: the plane alone is air, black at W 400 / L 40.
  const above = world(20, 12, 19);
  await page.evaluate((p) => window.volcast.slices.setPoint(p), above);
  await waitSettled();
  assert.equal(await slicePixel("axial", above), 0, "air at the plane");
  // 10 mm slab: z 33…43 mm reaches index 16.5, inside the bone (1000 HU ≥ L + W/2: white).
  await page.fill('.slices-bar input[data-slab="thickness"]', "10");
  await page.dispatchEvent('.slices-bar input[data-slab="thickness"]', "change");
  await page.waitForFunction(() => window.volcast.slices.panes.axial.header?.slab?.thickness === 10, null, { timeout: 30000 });
  await waitSettled();
  const header = await page.evaluate(() => window.volcast.slices.panes.axial.header.slab);
  assert.equal(header.mode, "mip");
  assert.equal(await slicePixel("axial", above), 255, "MIP: the bone below");
  await page.selectOption('.slices-bar select[data-slab="mode"]', "minip");
  await page.waitForFunction(() => window.volcast.slices.panes.axial.header?.slab?.mode === "minip", null, { timeout: 30000 });
  await waitSettled();
  assert.equal(await slicePixel("axial", above), 0, "MinIP: the air");
  await page.selectOption('.slices-bar select[data-slab="mode"]', "mean");
  await page.waitForFunction(() => window.volcast.slices.panes.axial.header?.slab?.mode === "mean", null, { timeout: 30000 });
  await waitSettled();
  // The mean over z 33…43 mm: 1 mm of bone (to index 17), 2 mm of the linear ramp from 1000 to
  // −1000 HU (mean 0), 7 mm of air: (1000 − 7000) / 10 = −600 HU, at W 4000 / L 0 a grey of
  // 0.35 · 255. Tolerance: the planes are sampled at most 0.4 mm apart (half the smallest
  // spacing), 26 or more across 10 mm, so each end plane weighs at most 1/25 of a 2000 HU
  // step: 80 HU, 5.1 grey levels.
  await page.fill('.slices-bar input[data-wl="window"]', "4000");
  await page.dispatchEvent('.slices-bar input[data-wl="window"]', "change");
  await page.fill('.slices-bar input[data-wl="level"]', "0");
  await page.dispatchEvent('.slices-bar input[data-wl="level"]', "change");
  await page.waitForFunction(() => window.volcast.slices.panes.axial.header?.window === 4000 && window.volcast.slices.panes.axial.header.level === 0, null, { timeout: 30000 });
  await waitSettled();
  closeTo(await slicePixel("axial", above), 0.35 * 255, 5.1, "mean slab grey");
  await page.fill('.slices-bar input[data-wl="window"]', "400");
  await page.dispatchEvent('.slices-bar input[data-wl="window"]', "change");
  await page.fill('.slices-bar input[data-wl="level"]', "40");
  await page.dispatchEvent('.slices-bar input[data-wl="level"]', "change");
  await screenshot(page, "measure-slab.png");
  await page.fill('.slices-bar input[data-slab="thickness"]', "0");
  await page.dispatchEvent('.slices-bar input[data-slab="thickness"]', "change");
  await page.evaluate((c) => window.volcast.slices.setPoint(c), CENTRE);
  await waitSettled();
  assert.equal(await page.evaluate(() => window.volcast.slices.panes.axial.header.slab ?? null), null);
});

// The view canvas's grey levels: the largest, and whether every pixel is grey (r = g = b).
const canvasGrey = () => page.evaluate(() => {
  const c = document.getElementById("view-canvas");
  const { data } = c.getContext("2d").getImageData(0, 0, c.width, c.height);
  let max = 0, colour = 0;
  for (let i = 0; i < data.length; i += 4) {
    max = Math.max(max, data[i]);
    if (Math.abs(data[i] - data[i + 1]) > 1 || Math.abs(data[i] - data[i + 2]) > 1) colour++;
  }
  return { max, colour };
});

test("MIP in 3D is greyscale, windowed by the projection's W/L fields", async () => {
  let seq = await shownSeq(page);
  await page.selectOption("#compositing", "mip");
  assert.equal(await page.isVisible("#projection-window"), true, "the fields show for a projection");
  // W 400 / L 40: bone white (255).
  await page.fill("#projection-window", "400");
  await page.dispatchEvent("#projection-window", "change");
  await page.fill("#projection-level", "40");
  await page.dispatchEvent("#projection-level", "change");
  let final = await page.waitForFunction((seq) => {
    const h = window.volcast.shown;
    return h?.final && h.seq > seq && h.quality?.projection_window?.window === 400 && h.quality.projection_window.level === 40 ? h : null;
  }, seq, { timeout: 90000, polling: 100 }).then((h) => h.jsonValue());
  assert.equal(final.quality.compositing, "mip");
  let grey = await canvasGrey();
  assert.equal(grey.colour, 0, "every pixel grey");
  assert.equal(grey.max, 255, "bone at L + W/2 or above is white");
  // W 4000 / L 0: bone (1000) at (1000 + 2000) / 4000 = 0.75 → 191 (±1 for 8-bit rounding).
  seq = final.seq;
  await page.fill("#projection-window", "4000");
  await page.dispatchEvent("#projection-window", "change");
  await page.fill("#projection-level", "0");
  await page.dispatchEvent("#projection-level", "change");
  final = await page.waitForFunction((seq) => {
    const h = window.volcast.shown;
    return h?.final && h.seq > seq && h.quality?.projection_window?.window === 4000 && h.quality.projection_window.level === 0 ? h : null;
  }, seq, { timeout: 90000, polling: 100 }).then((h) => h.jsonValue());
  grey = await canvasGrey();
  assert.equal(grey.colour, 0, "every pixel grey");
  closeTo(grey.max, 0.75 * 255, 1, "bone's grey at W 4000 / L 0");
  const state = await page.evaluate(async () => (await window.volcast.session.getState()).scene.quality);
  assert.deepEqual(state.projection_window, { level: 0, window: 4000 });
  await screenshot(page, "measure-mip-window.png");
  seq = final.seq;
  await page.selectOption("#compositing", "emission_absorption");
  await waitForFinal(page, { afterSeq: seq });
});

test("a 3D point picked on the bone's face, and a distance between two picked points", async () => {
  // Look along −x at the block's bone face (index x 23 → 24: the 500 HU crossing at x 18.6 mm),
  // with a transfer function opaque from 520 HU.
  const camera = { eye: [300, CENTRE[1], CENTRE[2]], target: [...CENTRE], up: [0, 0, 1], projection: "perspective", fov_y_deg: 20 };
  await page.evaluate(({ camera }) => {
    const s = window.volcast.session;
    s.setTransferFunction({ points: [[-1000, 0, 0, 0, 0], [500, 1, 1, 1, 0], [520, 1, 1, 1, 1], [3000, 1, 1, 1, 1]] });
    s.setCamera(camera);
  }, { camera });
  await page.waitForFunction(() => window.volcast.shown?.final && window.volcast.shown.camera?.eye?.[0] === 300, null, { timeout: 90000, polling: 100 });
  await page.click('.slices-tools button[data-tool="pick"]');
  const view = await page.$eval("#view", (el) => el.getBoundingClientRect().toJSON());
  // The 500 HU level between index 23 (1000) and 24 (−1000) lies at index 23.25: x = 18.6 mm.
  const ISO_X = 23.25 * SPACING[0];
  const spotOf = (p) => page.evaluate(({ p, camera, w, h }) => {
    // docs/design.md's camera, as core/measure.js's projectToView.
    const sub = (a, b) => a.map((v, i) => v - b[i]);
    const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    const norm = (a) => { const l = Math.hypot(...a); return a.map((v) => v / l); };
    const f = norm(sub(camera.target, camera.eye)), r = norm(cross(f, camera.up)), u = cross(r, f);
    const v = sub(p, camera.eye), z = dot(v, f), halfH = z * Math.tan((camera.fov_y_deg * Math.PI) / 360), halfW = halfH * w / h;
    return { x: (dot(v, r) / halfW + 1) * w / 2, y: (1 - dot(v, u) / halfH) * h / 2 };
  }, { p, camera, w: view.width, h: view.height });
  const first = [ISO_X, CENTRE[1], CENTRE[2]], second = [ISO_X, world(0, 20, 0)[1], world(0, 0, 14)[2]];
  const picks = [];
  for (const target of [first, second]) {
    const s = await spotOf(target);
    const before = await page.evaluate(() => window.volcast.measure.picked.length);
    await page.mouse.click(view.x + s.x, view.y + s.y);
    await page.waitForFunction((n) => window.volcast.measure.picked.length !== n, before, { timeout: 30000 });
    const m = await lastMeasurement();
    assert.equal(m.answer.hit, true);
    picks.push(m.answer.point);
    // On the face to within a voxel (0.8 mm: the opacity reaches ½ within one sample step of
    // the 500 HU crossing), and where the click's ray meets it to within a CSS pixel there.
    closeTo(m.answer.point[0], ISO_X, SPACING[0], "picked x on the bone face");
    closeTo(m.answer.point[1], target[1], 0.5, "picked y");
    closeTo(m.answer.point[2], target[2], 0.5, "picked z");
  }
  const m = await lastMeasurement();
  assert.equal(m.kind, "distance3d");
  const expected = Math.hypot(...picks[0].map((v, i) => v - picks[1][i]));
  closeTo(m.mm, expected, 1e-9, "the distance between the two picked points");
  closeTo(m.mm, Math.hypot(first[1] - second[1], first[2] - second[2]), 1.2, "about the distance between the targets");
  assert.match(await page.textContent(".measure-readout"), /^3D distance \d+\.\d+ mm/);
  await screenshot(page, "measure-pick.png");
  await page.click('.slices-tools button[data-tool="clear"]');
  await page.click('.slices-tools button[data-tool="crosshair"]');
});

test("dragging a crop handle on the axial pane moves that face, bracketed by interaction_start/end", async () => {
  await page.check("#crop-handles");
  await waitSettled();
  const sentBefore = await page.evaluate(() => window.sentLog.length);
  // The x-max handle sits at the middle of the box's right edge in the axial pane (x 25.2 mm
  // = index 31.5, the outer face of the last cell); drag it 8 mm to the left (−x).
  const from = await paneSpot("axial", [31.5 * SPACING[0], CENTRE[1], CENTRE[2]]);
  const dx = 8 / from.mmPerCssPx;
  // The face lies on the slice image's edge, which may be the canvas's: press 2 px inside
  // (within the handle's 9 px reach); the face follows the pointer's displacement.
  from.x -= 2;
  await page.mouse.move(from.x, from.y);
  await page.mouse.down();
  for (let i = 1; i <= 4; i++) { await page.mouse.move(from.x - (dx * i) / 4, from.y); await new Promise((r) => setTimeout(r, 60)); }
  await page.mouse.up();
  const crop = await page.evaluate(() => window.volcast.crop.crop);
  // 8 mm of the 25.6 mm extent: max x 1 − 0.3125, to within a CSS pixel of pointer rounding.
  closeTo(crop.max[0], 1 - 8 / (DIMS[0] * SPACING[0]), (2 * from.mmPerCssPx) / (DIMS[0] * SPACING[0]), "crop max x");
  assert.deepEqual([crop.min, crop.max.slice(1)], [[0, 0, 0], [1, 1]], "only the dragged face moved");
  await page.waitForFunction(() => window.sentLog.at(-1)?.type === "interaction_end", null, { timeout: 10000 });
  const sent = await page.evaluate((n) => window.sentLog.slice(n).map((m) => m.type), sentBefore);
  assert.equal(sent[0], "interaction_start", sent.join(", "));
  assert.ok(sent.includes("quality_policy"), sent.join(", "));
  assert.equal(sent.at(-1), "interaction_end");
  await page.waitForFunction((x) => window.volcast.shown?.final && window.volcast.shown.quality?.crop?.max?.[0] === x, crop.max[0], { timeout: 90000, polling: 100 });
  const state = await page.evaluate(async () => (await window.volcast.session.getState()).scene.quality.crop);
  assert.deepEqual(state.max, crop.max);
  await screenshot(page, "measure-crop-slice.png");
});

test("the crop box's handles in the 3D view: six drawn, one dragged moves its face", async () => {
  const handles = await page.evaluate(() => window.volcast.cropHandles.shown3d);
  assert.equal(handles.length, 6);
  const view = await page.$eval("#view", (el) => el.getBoundingClientRect().toJSON());
  // The camera looks along −x: the z-max handle (top face) is above the centre; dragging it
  // down lowers the top face.
  const top = handles.find((h) => h.axis === 2 && h.side === "max");
  const before = await page.evaluate(() => window.volcast.crop.crop);
  const sentBefore = await page.evaluate(() => window.sentLog.length);
  await page.mouse.move(view.x + top.x, view.y + top.y);
  await page.mouse.down();
  for (let i = 1; i <= 4; i++) await page.mouse.move(view.x + top.x, view.y + top.y + 10 * i);
  await page.mouse.up();
  const after = await page.evaluate(() => window.volcast.crop.crop);
  assert.ok(after.max[2] < before.max[2] - 0.05, `top face ${before.max[2]} → ${after.max[2]}`);
  assert.deepEqual([after.min, after.max.slice(0, 2)], [before.min, before.max.slice(0, 2)], "only the top face moved");
  const sent = await page.evaluate((n) => window.sentLog.slice(n).map((m) => m.type), sentBefore);
  assert.ok(!sent.includes("camera"), `a handle drag does not turn the view: ${sent.join(", ")}`);
  assert.equal(sent[0], "interaction_start");
  await page.waitForFunction(() => window.sentLog.at(-1)?.type === "interaction_end", null, { timeout: 10000 });
  await screenshot(page, "measure-crop-3d.png");
  await page.click("#crop-reset");
  await page.uncheck("#crop-handles");
  assert.deepEqual(problems, []);
});

test("the slice column is resized by dragging its left edge, and the panes ask for the new size", async () => {
  const before = await page.evaluate(() => ({ width: document.getElementById("slices").getBoundingClientRect().width, slice: window.volcast.slices.panes.axial.header.width }));
  const grip = await page.$eval(".slices-grip", (el) => el.getBoundingClientRect().toJSON());
  await page.mouse.move(grip.x + grip.width / 2, grip.y + 200);
  await page.mouse.down();
  await page.mouse.move(grip.x + grip.width / 2 - 60, grip.y + 200);
  await page.mouse.move(grip.x + grip.width / 2 - 120, grip.y + 200);
  await page.mouse.up();
  const width = await page.evaluate(() => document.getElementById("slices").getBoundingClientRect().width);
  closeTo(width, before.width + 120, 1, "column width");
  await page.waitForFunction((w) => window.volcast.slices.panes.axial.header.width > w, before.slice, { timeout: 30000 });
  await screenshot(page, "measure-resized.png");
  assert.deepEqual(problems, []);
});
