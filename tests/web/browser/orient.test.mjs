// Orientation and presets in the web client, in headless Chromium against a real
// volcast-server: a CT in Hounsfield units opens on the CT bone preset with
// shading on and its radiology window, says why; the orientation marker turns with the
// view; the six standard views and the turns set the camera; a volume without patient axes
// says so and names no patient direction anywhere on the page; an Alt-drag moves the level by a share of the window. Screenshots for
// web/README.md go to the artifacts folder (orient-*.png).
import { after, before, test } from "node:test";
import assert from "node:assert/strict";
import { existsSync } from "node:fs";
import path from "node:path";

import { DATA_DIR, checkPrerequisites, launchBrowser, openPage, screenshot, startServer, updateDocScreenshot, waitForFinal } from "./harness.mjs";
import { assertNoAnatomy, directionLabels } from "./labels.mjs";

const missing = checkPrerequisites();
if (missing.length) throw new Error(`cannot run the browser tests:\n  ${missing.join("\n  ")}`);

const CT_SCAN = "cranium_ct.nhdr";   // int16 Hounsfield units, no patient space in its header
const haveScan = Boolean(DATA_DIR) && existsSync(path.join(DATA_DIR, CT_SCAN));
const skip = !haveScan && `no ${CT_SCAN} in VOLCAST_DATA_DIR`;

let server, browser, page, problems;

before(async () => {
  if (!haveScan) return;
  server = await startServer(0);
  browser = await launchBrowser();
  ({ page, problems } = await openPage(browser.context, `${server.url}?volume=${encodeURIComponent(CT_SCAN)}`));
}, { timeout: 180000 });

after(async () => {
  await browser?.close();
  await server?.stop();
});

const marker = () => page.$eval("#orientation-marker", (el) => ({ ...el.dataset, hidden: el.hidden }));

// Send nothing more until the view shows a final frame answering the latest request.
async function settle() {
  const id = await page.evaluate(() => window.sentLog.filter((m) => typeof m.id === "number").at(-1)?.id ?? 0);
  return waitForFinal(page, { minRequest: id, timeout: 120000 });
}

test("a CT in Hounsfield units opens on the CT bone preset, shaded, at W 2000 / L 400, and says why", { skip }, async () => {
  await page.waitForFunction((name) => window.volcast.session.volume?.name === name, CT_SCAN, { timeout: 120000 });
  assert.equal(await page.$eval("#tf-preset", (el) => el.value), "ct.bone");
  const labels = await page.$$eval("#tf-preset option", (os) => os.map((o) => o.value));
  for (const name of ["ct.bone", "ct.soft_tissue", "ct.lung", "ct.angiography"]) assert.ok(labels.includes(name), `${name} in ${labels}`);
  assert.equal(await page.inputValue("#tf-window"), "2000", "bone's radiology window");
  assert.equal(await page.inputValue("#tf-level"), "400");
  assert.ok(await page.isChecked("#q-shading"), "the preset turns shading on");
  const reason = await page.textContent("#preset-reason");
  assert.match(reason, /^CT \(inferred\)/, reason);
  assert.match(reason, /-1000 \(air\)/, reason);
  // The final frame is rendered with shading: the preset's switch reached the server.
  const final = await page.waitForFunction(() => {
    const h = window.volcast.shown;
    return h?.final && h.quality?.shading === true ? h : null;
  }, null, { timeout: 120000 }).then((h) => h.jsonValue());
  assert.equal(final.quality.shading, true, JSON.stringify(final.quality));
  await screenshot(page, "orient-ct-bone-preset.png");
});


test("a scan file that names no patient axes shows no anatomical label anywhere on the page", { skip }, async () => {
  await page.waitForFunction((name) => window.volcast.session.volume?.name === name, CT_SCAN, { timeout: 120000 });
  assert.equal(await page.evaluate(() => window.volcast.session.volume.orientation_known), false);
  await page.waitForFunction(() => document.querySelectorAll(".slice-pane .edge").length === 12);
  assertNoAnatomy(await directionLabels(page), CT_SCAN);
});
test("a volume without patient axes says its orientation is unknown and offers turns", { skip }, async () => {
  assert.ok(await page.isVisible("#orientation-note"), "the note over the view");
  assert.match(await page.textContent("#orientation-note"), /Orientation unknown/);
  assert.ok(await page.isVisible("#orientation-turns"));
  assert.equal((await page.evaluate(() => window.volcast.session.volume.orientation_known)), false);
});

// The file names no patient axes: the marker speaks of the file's axes (LPS's L is +x …).
const FILE_AXES = { L: "+x", R: "−x", P: "+y", A: "−y", S: "+z", I: "−z" };
const inFileAxes = (letters) => letters.map((l) => FILE_AXES[l]);

test("the marker starts on the anterior view, in the file's axes: +x on the right, +z up", { skip }, async () => {
  const m = await marker();
  assert.equal(m.hidden, false);
  // The starting view is slightly oblique (from −y, a little towards +x and above).
  assert.deepEqual([m.right, m.up, m.toward], inFileAxes(["L", "S", "A"]), JSON.stringify(m));
});

test("each standard view sets the camera, and the marker turns with it", { skip }, async () => {
  const expected = Object.fromEntries(Object.entries({
    anterior: ["L", "S", "A"], posterior: ["R", "S", "P"], left: ["P", "S", "L"],
    right: ["A", "S", "R"], superior: ["R", "A", "S"], inferior: ["L", "A", "I"],
  }).map(([k, v]) => [k, inFileAxes(v)]));
  const target = await page.evaluate(() => window.volcast.session.scene.camera.target);
  for (const [name, labels] of Object.entries(expected)) {
    await page.click(`#view-${name}`);
    const m = await marker();
    assert.deepEqual([m.right, m.up, m.toward], labels, `${name}: ${JSON.stringify(m)}`);
    const cam = await page.evaluate(() => window.volcast.session.scene.camera);
    assert.deepEqual(cam.target, target, `${name} looks at the volume's centre`);
    if (name === "anterior" || name === "superior") {
      await settle();
      await screenshot(page, `orient-view-${name}.png`);
    }
  }
});

test("turning the view is kept by the session and saved in the scene's camera", { skip }, async () => {
  await page.click("#view-anterior");
  await page.click('#orientation-turns button[data-degrees="180"]');
  const m = await marker();
  assert.equal(m.up, "−z", "upside down");
  await settle();
  const scene = await page.evaluate(() => window.volcast.session.sceneFile());
  assert.ok(scene.camera.up[2] < -0.99, `the saved camera is turned: up ${scene.camera.up}`);
  await page.click('#orientation-turns button[data-degrees="180"]');
  assert.equal((await marker()).up, "+z");
});

test("an Alt-drag of 75 px moves the level by 150 HU on bone (a share of the window), not 750", { skip }, async () => {
  await page.selectOption("#tf-preset", "ct.bone");
  assert.equal(await page.inputValue("#tf-level"), "400");
  const box = await page.$eval("#view-canvas", (el) => { const r = el.getBoundingClientRect(); return { x: r.x + r.width / 2, y: r.y + r.height / 2 }; });
  await page.keyboard.down("Alt");
  await page.mouse.move(box.x, box.y);
  await page.mouse.down();
  for (let i = 1; i <= 15; i++) await page.mouse.move(box.x, box.y + i * 5);
  await page.mouse.up();
  await page.keyboard.up("Alt");
  const level = Number(await page.inputValue("#tf-level"));
  assert.ok(Math.abs(level - 550) < 1, `level ${level}: 400 + 75 px × 2 HU/px`);
  assert.equal(await page.inputValue("#tf-window"), "2000", "a vertical drag leaves the window");
  assert.equal(await page.$eval("#tf-preset", (el) => el.value), "", "an edited curve is custom");
  await page.selectOption("#tf-preset", "ct.soft_tissue");
  assert.equal(await page.inputValue("#tf-window"), "400");
  assert.equal(await page.inputValue("#tf-level"), "40");
  await settle();
  await page.locator("aside.panel").screenshot({ path: (await import("./harness.mjs")).artifact("orient-preset-picker.png") });
  updateDocScreenshot("orient-preset-picker.png", "orient-preset-picker.png");
  assert.deepEqual(problems, []);
});
