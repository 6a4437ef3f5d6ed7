// The slice panes (web/app/slice_views.js) in headless Chromium against a real
// volcast-server: three slices appear beside the 3D view, a click in one pane moves the
// crosshair so the other two are re-sliced through it, window/level changes the grey, and
// the crosshair point is drawn over the 3D view where the frame's camera projects it.
import { after, before, test } from "node:test";
import assert from "node:assert/strict";

import { ARTIFACTS, checkPrerequisites, launchBrowser, openPage, screenshot, startServer, updateDocScreenshot, waitForFinal } from "./harness.mjs";

const missing = checkPrerequisites();
if (missing.length) throw new Error(`cannot run the browser tests:\n  ${missing.join("\n  ")}`);

let server, browser, page, problems;

before(async () => {
  server = await startServer(0);
  browser = await launchBrowser();
  ({ page, problems } = await openPage(browser.context, server.url));
}, { timeout: 180000 });

after(async () => {
  await browser?.close();
  await server?.stop();
  console.log(`artifacts in ${ARTIFACTS}`);
});

const AXES = ["axial", "coronal", "sagittal"];

// Each pane's slice header and how much of its canvas is lit.
function panes(page) {
  return page.evaluate((axes) => Object.fromEntries(axes.map((axis) => {
    const pane = window.volcast.slices.panes[axis];
    const c = pane.canvas;
    let lit = 0, sum = 0;
    if (c.width > 1) {
      const { data } = c.getContext("2d").getImageData(0, 0, c.width, c.height);
      for (let i = 0; i < data.length; i += 4) { if (data[i] > 12) lit++; sum += data[i]; }
    }
    const n = Math.max(1, c.width * c.height);
    return [axis, { header: pane.header, lit: lit / n, mean: sum / n, inFlight: pane.inFlight }];
  })), AXES);
}

const waitSettled = (page) => page.waitForFunction((axes) => axes.every((a) => {
  const p = window.volcast.slices.panes[a];
  return p.header && !p.inFlight && !p.dirty;
}), AXES, { timeout: 30000, polling: 50 });

test("three slices of the demo volume appear beside the 3D view", async () => {
  await page.waitForFunction(() => window.volcast.session.volume?.name === "builtin:demo", null, { timeout: 60000 });
  await waitForFinal(page);
  await waitSettled(page);
  const p = await panes(page);
  for (const axis of AXES) {
    assert.equal(p[axis].header.axis, axis);
    // The demo phantom fills a good part of each central plane: a blank pane is broken.
    assert.ok(p[axis].lit > 0.05, `${axis}: lit fraction ${p[axis].lit}`);
  }
  // The panes sit beside the view, not over it.
  const boxes = await page.evaluate(() => ({
    view: document.getElementById("view").getBoundingClientRect().toJSON(),
    slices: document.getElementById("slices").getBoundingClientRect().toJSON(),
  }));
  assert.ok(boxes.slices.left >= boxes.view.right - 1, JSON.stringify(boxes));
  assert.deepEqual(problems, []);
});

test("a click in the axial pane moves the crosshair and re-slices the other two through it", async () => {
  const before = await panes(page);
  const box = await page.$eval('.slice-pane[data-axis="axial"] canvas', (el) => el.getBoundingClientRect().toJSON());
  // A point off the centre: a quarter of the way in from the top left.
  await page.mouse.click(box.x + box.width * 0.3, box.y + box.height * 0.35);
  await page.waitForFunction((b) => {
    const s = window.volcast.slices;
    return s.panes.coronal.header?.point[0] !== b && !s.panes.coronal.inFlight && !s.panes.sagittal.inFlight;
  }, before.coronal.header.point[0], { timeout: 30000, polling: 50 });
  await waitSettled(page);
  const point = await page.evaluate(() => window.volcast.slices.point);
  const after = await panes(page);
  // The clicked point lies in the axial plane (its z), and the other planes pass through it.
  assert.ok(Math.abs(point[2] - before.axial.header.point[2]) < 1e-9, `z changed: ${point}`);
  assert.ok(Math.abs(after.coronal.header.origin[1] - point[1]) < 1e-6, "the coronal plane passes through the point's y");
  assert.ok(Math.abs(after.sagittal.header.origin[0] - point[0]) < 1e-6, "the sagittal plane passes through the point's x");
  // Left of the centre in the axial image is the patient's right: smaller x than the centre.
  assert.ok(point[0] < before.axial.header.point[0], `x ${point[0]} not right of the centre`);
  // The axial pane was not re-sliced, only its crosshair moved.
  assert.deepEqual(after.axial.header, before.axial.header);
  await screenshot(page, "slices-01-crosshair.png");
});

test("the crosshair point is drawn over the 3D view where the camera projects it", async () => {
  const r = await page.evaluate(() => {
    const s = window.volcast.slices;
    const view = document.getElementById("view").getBoundingClientRect();
    const m = s.marker;
    const dpr = devicePixelRatio;
    const at = s.markerAt;
    // The marker's ring: pixels 6 px from its centre are drawn.
    const ctx = m.getContext("2d");
    const px = ctx.getImageData(Math.round((at.x + 6) * dpr), Math.round(at.y * dpr), 1, 1).data;
    return { at, view: { width: view.width, height: view.height }, alpha: px[3] };
  });
  assert.ok(r.at, "no marker position");
  assert.ok(r.at.x > 0 && r.at.x < r.view.width && r.at.y > 0 && r.at.y < r.view.height, JSON.stringify(r));
  assert.ok(r.alpha > 0, "the marker's ring is not drawn");
});

test("window/level changes the slices' grey", async () => {
  const before = await panes(page);
  await page.fill('.slices-bar input[data-wl="window"]', "40");
  await page.dispatchEvent('.slices-bar input[data-wl="window"]', "change");
  await page.waitForFunction(() => window.volcast.slices.panes.axial.header?.window === 40, null, { timeout: 30000 });
  await waitSettled(page);
  const after = await panes(page);
  assert.notEqual(Math.round(after.axial.mean), Math.round(before.axial.mean), "a narrow window should change the grey");
  await screenshot(page, "slices-02-window.png");
  assert.deepEqual(problems, []);
});

test("a screenshot for web/README.md", async () => {
  await page.fill('.slices-bar input[data-wl="window"]', "200");
  await page.dispatchEvent('.slices-bar input[data-wl="window"]', "change");
  await page.waitForFunction(() => window.volcast.slices.panes.axial.header?.window === 200, null, { timeout: 30000 });
  await waitSettled(page);
  await screenshot(page, "slices-03-readme.png");
  updateDocScreenshot("slices-03-readme.png", "slices.png");
});
