// A view link carries the whole view (core/view_link.js), in headless Chromium against a real
// volcast-server: on builtin:demo (a volume whose file names no patient axes) the patient
// axes are set by hand with a flip, the crop box, a clip plane, a windowed MIP, the slice
// panes' window/level, crosshair and a thick slab are set; the link opens a new page that
// draws the same final frame (to 1/255) and the same three slices, and says the axes were
// set by hand. With VOLCAST_UPDATE_DOC_SCREENSHOTS=1 the reopened page's screenshot goes
// over docs/images/web/view-link.png.
import { test } from "node:test";
import assert from "node:assert/strict";

import { artifact, openPage, screenshot, updateDocScreenshot, waitForFinal } from "./harness.mjs";
import { pageUnderTest } from "./page_setup.mjs";
import { compareBytes, decodePng, overBlack } from "../lib/png.mjs";
import { writeFileSync } from "node:fs";

const FLIP_AP = [[1, 0, 0], [0, -1, 0], [0, 0, 1]];
const SCENE_TYPES = ["camera", "viewport", "transfer_function", "quality_policy", "clip_planes"];

let setup, page, problems;
setup = pageUnderTest({ finalFrame: true, ready: (s) => ({ page, problems } = s) });

// A range or number field set as a user would leave it: input, then change.
const setField = (p, selector, value) => p.$eval(selector, (el, v) => {
  el.value = String(v);
  el.dispatchEvent(new Event("input", { bubbles: true }));
  el.dispatchEvent(new Event("change", { bubbles: true }));
}, value);

// The final frame answering the page's latest scene request (its send log is hooked up by
// openPage; a link's own requests go before that, so `expect` can also name the quality
// the frame must have).
async function settledFinal(p, expect = null) {
  const id = await p.evaluate((types) => window.sentLog.filter((m) => types.includes(m.type)).at(-1)?.id ?? 0, SCENE_TYPES);
  if (!expect) return waitForFinal(p, { minRequest: id, timeout: 120000 });
  const handle = await p.waitForFunction((want) => {
    const h = window.volcast.shown;
    return h?.final && JSON.stringify(h.quality) === JSON.stringify(want) ? h : null;
  }, expect, { timeout: 120000, polling: 100 });
  return handle.jsonValue();
}

// The three slice panes once none has a request in flight or waiting, and each shows the
// crosshair point and slab wanted: headers and grey pixels.
async function settledSlices(p, point) {
  await p.waitForFunction((point) => {
    const s = window.volcast.slices;
    return Object.values(s.panes).every((pane) => pane.header && !pane.inFlight && !pane.dirty &&
      pane.header.point.every((x, i) => Math.abs(x - point[i]) <= 1e-6 * Math.max(1, Math.abs(point[i]))));
  }, point, { timeout: 60000, polling: 100 });
  return p.evaluate(() => Object.fromEntries(Object.entries(window.volcast.slices.panes).map(([axis, pane]) => {
    const grey = [];
    for (let i = 0; i < pane.image.data.length; i += 4) grey.push(pane.image.data[i]);
    return [axis, { header: pane.header, grey }];
  })));
}

const finalImage = (p) => p.evaluate(() => Array.from(new Uint8Array(window.volcast.session.lastFinal.image)));

test("a link reopens the whole view: the same final frame to 1/255 and the same slices", async () => {
  const range = await page.evaluate(() => window.volcast.session.volume.value_range);
  // The patient axes set by hand (a flip), a crop box, a clip plane across x.
  await page.click("#orientation-flip-ap");
  await setField(page, "#crop-min-z", 0.2);
  await setField(page, "#crop-max-x", 0.85);
  await page.check("#clip-enabled");
  await page.selectOption("#clip-axis", "0");
  await setField(page, "#clip-position", 0.35);
  // A MIP windowed to part of the range.
  await page.selectOption("#compositing", "mip");
  const pw = { window: Number(((range[1] - range[0]) * 0.6).toPrecision(4)), level: Number((range[0] + (range[1] - range[0]) * 0.45).toPrecision(4)) };
  await setField(page, "#projection-window", pw.window);
  await setField(page, "#projection-level", pw.level);
  // The slice panes: a window, a crosshair off the centre, a 6 mm mean slab.
  const sw = { window: Number(((range[1] - range[0]) * 0.5).toPrecision(4)), level: Number((range[0] + (range[1] - range[0]) * 0.3).toPrecision(4)) };
  await setField(page, '.slices-bar input[data-wl="window"]', sw.window);
  await setField(page, '.slices-bar input[data-wl="level"]', sw.level);
  await page.fill('.slices-bar input[data-slab="thickness"]', "6");
  await page.dispatchEvent('.slices-bar input[data-slab="thickness"]', "change");
  await page.selectOption('.slices-bar select[data-slab="mode"]', "mean");
  const box = await page.$eval('.slice-pane[data-axis="axial"] canvas', (el) => el.getBoundingClientRect().toJSON());
  await page.mouse.click(box.x + box.width * 0.4, box.y + box.height * 0.6);

  const final = await settledFinal(page);
  assert.equal(final.quality.compositing, "mip");
  assert.deepEqual(final.quality.projection_window, pw);
  assert.deepEqual(final.quality.orientation_correction, FLIP_AP);
  assert.deepEqual(final.quality.crop, { min: [0, 0, 0.2], max: [0.85, 1, 1] });
  // The pane clicked in keeps the image it had (its plane holds the point already); cut all
  // three through the point, as the reopened page does, so that their headers compare.
  const point = await page.evaluate(() => { window.volcast.slices.requestAll(); return window.volcast.slices.point; });
  const slices = await settledSlices(page, point);
  for (const { header } of Object.values(slices)) {
    assert.equal(header.window, sw.window);
    assert.deepEqual({ thickness: header.slab?.thickness, mode: header.slab?.mode }, { thickness: 6, mode: "mean" });
  }
  const image = await finalImage(page);
  const clip = await page.evaluate(() => window.volcast.session.scene.clip_planes);
  assert.equal(clip.length, 1);
  await screenshot(page, "link-source.png");

  await page.click("#copy-link");
  const url = await page.evaluate(() => location.href);
  const hash = new URLSearchParams(new URL(url).hash.slice(1));
  // A correction sets the axes by hand by itself: "axes=hand" is written only for Treat as LPS.
  for (const key of ["volume", "eye", "tf", "orientation", "crop", "clip", "compositing", "projection_window",
    "slice_window", "crosshair", "slab"]) assert.ok(hash.has(key), `the link has ${key}: ${url}`);

  const other = await openPage(setup.browser.context, url);
  try {
    const p = other.page;
    await p.waitForFunction(() => window.volcast.session.volume?.name === "builtin:demo", null, { timeout: 60000 });
    const again = await settledFinal(p, final.quality);
    assert.deepEqual([again.width, again.height], [final.width, final.height]);
    // The link writes each number as the shortest text of the same double: the same camera.
    assert.deepEqual(again.camera, final.camera);
    const state = await p.evaluate(async () => (await window.volcast.session.getState()).scene);
    assert.deepEqual(state.clip_planes, clip);

    // The same final frame: both PNGs over black, to 1/255 per channel (the bound asked of a view link;
    // the same scene through the same renderer gives the same bytes, so any difference at
    // all would be a part of the view the link lost).
    const a = decodePng(Buffer.from(image)), b = decodePng(Buffer.from(await finalImage(p)));
    assert.deepEqual([a.width, a.height], [b.width, b.height]);
    const d = compareBytes(overBlack(a), overBlack(b));
    writeFileSync(artifact("link-comparison.json"), `${JSON.stringify({ frame: d }, null, 2)}\n`);
    assert.ok(d.maxDiff <= 1, `final frames differ by up to ${d.maxDiff}/255 (${d.channelsOver1} channels over 1)`);

    // The same slices: the same crosshair, planes, window and slab, and the same grey levels
    // (the same request to the same slicer).
    const point2 = await p.evaluate(() => window.volcast.slices.point);
    assert.deepEqual(point2, point);
    const slices2 = await settledSlices(p, point2);
    for (const axis of Object.keys(slices)) {
      const h1 = slices[axis].header, h2 = slices2[axis].header;
      for (const k of ["width", "height", "window", "level", "pixel_spacing"]) assert.equal(h2[k], h1[k], `${axis} ${k}`);
      assert.deepEqual(h2.slab, h1.slab, `${axis} slab`);
      assert.deepEqual(h2.origin, h1.origin, `${axis} origin`);
      const g1 = slices[axis].grey, g2 = slices2[axis].grey;
      let differ = 0;
      for (let i = 0; i < g1.length; i++) if (g1[i] !== g2[i]) differ++;
      assert.equal(differ, 0, `${axis}: ${differ} of ${g1.length} pixels differ`);
    }

    // The page says what it shows: axes set by hand, the panels as in the link.
    assert.match(await p.textContent("#orientation-note"), /set by hand \(flipped A\/P\)/);
    assert.equal(await p.inputValue("#compositing"), "mip");
    assert.equal(await p.inputValue("#crop-min-z"), "0.2");
    assert.ok(await p.isChecked("#clip-enabled"));
    assert.equal(await p.inputValue("#clip-axis"), "0");
    assert.equal(Number(await p.inputValue('.slices-bar input[data-slab="thickness"]')), 6);
    await screenshot(p, "link-reopened.png");
    updateDocScreenshot("link-reopened.png", "view-link.png");
    assert.deepEqual(other.problems, [], other.problems.join("\n"));
  } finally {
    await other.page.close();
  }
  assert.deepEqual(problems, [], problems.join("\n"));
});
