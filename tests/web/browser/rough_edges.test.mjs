// The web client's rough edges, in headless Chromium against a real
// volcast-server that also serves a small scan this test writes into a data folder of its
// own: the picker, errors that clear, fields that show what is applied, honest stats, the
// stats toggle, full screen, the view link, the focus ring, keyboard transfer-function
// points, the phone layout, a saved scene that volcast-render --data reproduces, and
// reconnection within 1 s of a restarted server answering.
import { after, afterEach, before, test } from "node:test";
import assert from "node:assert/strict";
import { mkdirSync, mkdtempSync, readFileSync, rmSync, writeFileSync } from "node:fs";
import os from "node:os";
import path from "node:path";

import {
  ARTIFACTS, RENDER_EXE, artifact, checkPrerequisites, download, launchBrowser, openPage, run,
  screenshot, startServer, updateDocScreenshot, waitForFinal,
} from "./harness.mjs";
import { compareBytes, decodePng, overBlack } from "../lib/png.mjs";

const missing = checkPrerequisites();
if (missing.length) throw new Error(`cannot run the browser tests:\n  ${missing.join("\n  ")}`);

const SCAN = "tiny/ball.nrrd";   // server-relative name of the scan written below
let dataDir, server, browser, page, problems;

// A 24³ uint8 ball (255 at the centre falling to 0 at radius 11) as a raw NRRD.
function writeScan(folder) {
  const n = 24, voxels = new Uint8Array(n * n * n);
  for (let z = 0; z < n; z++) for (let y = 0; y < n; y++) for (let x = 0; x < n; x++) {
    const r = Math.hypot(x - 11.5, y - 11.5, z - 11.5);
    voxels[(z * n + y) * n + x] = Math.round(255 * Math.max(0, 1 - r / 11));
  }
  const header = `NRRD0004\ntype: uint8\ndimension: 3\nsizes: ${n} ${n} ${n}\nspacings: 1 1 1\nencoding: raw\n\n`;
  mkdirSync(path.join(folder, "tiny"), { recursive: true });
  writeFileSync(path.join(folder, SCAN), Buffer.concat([Buffer.from(header, "latin1"), Buffer.from(voxels)]));
}

const serverArgs = () => ({ extraArgs: ["--data", dataDir] });

before(async () => {
  dataDir = mkdtempSync(path.join(os.tmpdir(), "volcast-rough-data-"));
  writeScan(dataDir);
  server = await startServer(0, serverArgs());
  browser = await launchBrowser();
  ({ page, problems } = await openPage(browser.context, server.url));
  await page.waitForFunction(() => window.volcast.session.volume?.name === "builtin:demo", null, { timeout: 60000 });
  await waitForFinal(page);
}, { timeout: 180000 });

// Each test leaves the page as it found it, even when it fails: not in full screen (where the
// view covers every control, so the next test's clicks would land on it) and with the stats
// shown (the choice is remembered, also by the pages later tests open).
afterEach(async () => {
  if (!page || page.isClosed()) return;
  await page.evaluate(() => (document.fullscreenElement ? document.exitFullscreen() : undefined));
  await waitForFullscreenButton("false");
  if (await page.isHidden("#stats")) await page.click("#toggle-stats");
  await page.waitForFunction(() => !document.getElementById("stats").hidden, null, { timeout: 5000 });
});

after(async () => {
  await browser?.close();
  await server?.stop();
  if (dataDir) rmSync(dataDir, { recursive: true, force: true });
  console.log(`artifacts in ${ARTIFACTS}`);
});

// The Full screen button follows the page's fullscreenchange event, which Chromium fires a
// frame or more after document.fullscreenElement changes (on a loaded machine the button
// was seen a poll behind the element in 2 of 80 changes): wait for the button itself.
const waitForFullscreenButton = (pressed) => page.waitForFunction(
  (p) => document.getElementById("fullscreen").getAttribute("aria-pressed") === p, pressed, { timeout: 5000 });

const lastSentId = (page, type) => page.evaluate((t) => window.sentLog.filter((m) => m.type === t).at(-1)?.id ?? 0, type);

async function openFromPicker(name) {
  await page.selectOption("#volume-select", name);
  await page.waitForFunction((n) => window.volcast.session.volume?.name === n, name, { timeout: 60000 });
  return waitForFinal(page, { minRequest: await lastSentId(page, "open_volume") });
}

test("the picker lists the server's volumes: scans first, the phantoms in a group apart, names only", async () => {
  const groups = await page.$$eval("#volume-select optgroup", (gs) => gs.map((g) => ({ label: g.label, names: [...g.children].map((o) => o.value) })));
  assert.equal(groups.length, 2, JSON.stringify(groups));
  assert.match(groups[0].label, /^Scans/);
  assert.ok(groups[0].names.includes(SCAN), `the scans list ${SCAN}: ${groups[0].names}`);
  assert.ok(groups[0].names.every((n) => !n.startsWith("builtin:")), "no phantom among the scans");
  assert.ok(groups[1].names.length > 0 && groups[1].names.every((n) => n.startsWith("builtin:")), `phantoms: ${groups[1].names}`);
  const all = groups.flatMap((g) => g.names);
  assert.ok(all.every((n) => !n.startsWith("/") && !n.includes(dataDir)), "no server path in the list");
  assert.equal(await page.inputValue("#volume-select"), "builtin:demo", "the picker shows the open volume");
  // For the README: the list drawn open (a native drop-down is not in screenshots).
  await page.$eval("#volume-select", (el) => { el.size = 8; });
  await page.locator(".topbar").screenshot({ path: artifact("rough-01-picker.png") });
  updateDocScreenshot("rough-01-picker.png", "client-picker.png");
  await page.$eval("#volume-select", (el) => { el.size = 0; });

  const final = await openFromPicker(SCAN);
  assert.equal(final.codec, "png");
  assert.equal(await page.inputValue("#volume-select"), SCAN);
});

test("an error clears when the next open succeeds", async () => {
  await page.fill("#volume-name", "no_such_volume.nrrd");
  await page.click("#open-volume");
  const error = page.locator("#errors .error").first();
  await error.waitFor({ state: "visible", timeout: 30000 });
  assert.equal(await error.getAttribute("data-code"), "not_found");
  await openFromPicker("builtin:demo");
  assert.equal(await page.locator("#errors .error").count(), 0, "the not_found banner went with the volume that opened");
});

test("the stats state the size a frame was rendered at, and its level", async () => {
  const policies = await page.evaluate(() => window.sentLog.filter((m) => m.type === "quality_policy").length);
  await page.check('input[name="quality-mode"][value="explicit"]');
  await page.fill("#q-scale", "0.5");
  await page.dispatchEvent("#q-scale", "change");
  await page.waitForFunction((n) => window.sentLog.filter((m) => m.type === "quality_policy").length > n, policies);
  const final = await waitForFinal(page, { minRequest: await lastSentId(page, "quality_policy") });
  assert.equal(final.quality.image_scale, 0.5);
  await page.waitForTimeout(400);   // the overlay refreshes every 250 ms
  // Sent at its ray grid's size, lround(view · ½) a side, with the view's size beside it.
  const rw = Math.max(1, Math.round(final.view_width * 0.5)), rh = Math.max(1, Math.round(final.view_height * 0.5));
  assert.deepEqual([final.width, final.height], [rw, rh]);
  assert.equal(await page.textContent("#stat-image"), `${rw}×${rh} (½ scale of ${final.view_width}×${final.view_height})`);
  assert.match(await page.textContent("#stat-level"), new RegExp(`^${final.level} · final · step ${final.quality.step}`));
});

test("a field shows what is applied: a refused value is not sent, the applied one comes back, marked", async () => {
  const sent = await page.evaluate(() => window.sentLog.length);
  await page.focus("#q-scale");
  await page.fill("#q-scale", "7");   // image_scale is at most 1
  await page.dispatchEvent("#q-scale", "change");
  await page.waitForTimeout(600);     // longer than the panel's settling time
  assert.equal(await page.inputValue("#q-scale"), "0.5", "the field shows the scale in use");
  assert.equal(await page.getAttribute("#q-scale", "aria-invalid"), "true");
  assert.match(await page.getAttribute("#q-scale", "title"), /"7" refused: at least 0\.1, at most 1/);
  const types = await page.evaluate((n) => window.sentLog.slice(n).map((m) => m.type), sent);
  assert.ok(!types.includes("quality_policy"), `nothing sent: ${types}`);
  assert.equal(await page.locator("#errors .error").count(), 0);
  // Typing again takes the mark away.
  await page.fill("#q-scale", "1");
  assert.equal(await page.getAttribute("#q-scale", "aria-invalid"), null);
  await page.dispatchEvent("#q-scale", "change");
  await page.check('input[name="quality-mode"][value="automatic"]');
});

test("transfer-function points by keyboard: select, move, add, delete", async () => {
  await page.focus("#tf-editor");
  const points = () => page.evaluate(() => window.volcast.tfEditor.points.map((p) => [...p]));
  const selected = () => page.evaluate(() => window.volcast.tfEditor.selected);
  const start = await points();
  await page.keyboard.press("ArrowRight");
  assert.equal(await selected(), 0);
  await page.keyboard.press("ArrowRight");
  assert.equal(await selected(), 1);
  assert.equal(Number(await page.inputValue("#tf-point-value")), Number(start[1][0].toPrecision(6)));
  const range = await page.evaluate(() => window.volcast.tfEditor.range);
  await page.keyboard.press("Shift+ArrowRight");
  await page.keyboard.press("ArrowUp");
  const moved = await points();
  // One step: 1 % of the value range (kept short of the next point), and +0.01 opacity.
  assert.ok(Math.abs(moved[1][0] - Math.min(start[1][0] + 0.01 * (range[1] - range[0]), start[2][0])) < 1e-9 * (range[1] - range[0]) + 1e-3 * (range[1] - range[0]),
    `value ${start[1][0]} → ${moved[1][0]}`);
  assert.ok(Math.abs(moved[1][4] - Math.min(1, start[1][4] + 0.01)) < 1e-12, `opacity ${start[1][4]} → ${moved[1][4]}`);
  await page.keyboard.press("Insert");
  assert.equal((await points()).length, start.length + 1);
  assert.equal(await selected(), 2, "the new point, halfway to the next, is selected");
  await page.keyboard.press("Delete");
  assert.equal((await points()).length, start.length);
  // What was sent is what the editor holds.
  const tfId = await lastSentId(page, "transfer_function");
  await waitForFinal(page, { minRequest: tfId });
  const sentTf = await page.evaluate(() => window.volcast.session.scene.transfer_function.points);
  assert.deepEqual(sentTf.map((p) => p[0]), (await points()).map((p) => p[0]));
  // A point opacity of 5 is refused by the field's limits: the applied opacity comes back.
  const alpha = await page.inputValue("#tf-point-alpha");
  await page.focus("#tf-point-alpha");
  await page.fill("#tf-point-alpha", "5");
  await page.dispatchEvent("#tf-point-alpha", "change");
  assert.equal(await page.inputValue("#tf-point-alpha"), alpha);
  assert.equal(await page.getAttribute("#tf-point-alpha", "aria-invalid"), "true");
});

// Fraction of the pixels in a CSS rectangle that are the accent colour (#3fb6c8), ±12 a channel.
async function accentFraction(clip) {
  const png = decodePng(await page.screenshot({ clip }));
  let hits = 0;
  const n = png.width * png.height;
  for (let i = 0; i < n; i++) {
    const [r, g, b] = [png.data[i * png.channels], png.data[i * png.channels + 1], png.data[i * png.channels + 2]];
    if (Math.abs(r - 0x3f) <= 12 && Math.abs(g - 0xb6) <= 12 && Math.abs(b - 0xc8) <= 12) hits++;
  }
  return hits / n;
}

test("the view shows a focus ring when reached by the keyboard", async () => {
  const box = await page.$eval("#view-canvas", (el) => { const r = el.getBoundingClientRect(); return { x: r.x, y: r.y, w: r.width, h: r.height }; });
  const edge = { x: box.x, y: box.y + box.h / 2 - 50, width: 3, height: 100 };
  const unfocused = await accentFraction(edge);
  await page.focus("#fullscreen");
  for (let i = 0; i < 5 && (await page.evaluate(() => document.activeElement?.id)) !== "view-canvas"; i++) await page.keyboard.press("Tab");
  assert.equal(await page.evaluate(() => document.activeElement?.id), "view-canvas", "Tab reaches the view");
  const focused = await accentFraction(edge);
  await screenshot(page, "rough-02-focus-ring.png");
  // The ring is 3 px wide inside the canvas edge: the whole strip, but for anti-aliasing.
  assert.ok(unfocused < 0.05 && focused > 0.9, `accent pixels on the view's left edge: ${unfocused} unfocused, ${focused} focused`);
  await page.keyboard.press("Home");   // the view's keys still work
});

test("the stats overlay hides and shows (button and S), and full screen shows the view alone", async () => {
  assert.ok(await page.isVisible("#stats"));
  await page.click("#toggle-stats");
  assert.ok(await page.isHidden("#stats"));
  assert.equal(await page.getAttribute("#toggle-stats", "aria-pressed"), "false");
  await screenshot(page, "rough-03-stats-hidden.png");
  updateDocScreenshot("rough-03-stats-hidden.png", "client-stats-hidden.png");
  await page.focus("#view-canvas");
  await page.keyboard.press("s");
  assert.ok(await page.isVisible("#stats"));
  assert.equal(await page.getAttribute("#toggle-stats", "aria-pressed"), "true");

  await page.click("#fullscreen");
  await page.waitForFunction(() => document.fullscreenElement?.id === "view", null, { timeout: 5000 });
  await waitForFullscreenButton("true");
  await page.evaluate(() => document.exitFullscreen());
  await page.waitForFunction(() => document.fullscreenElement === null, null, { timeout: 5000 });
  await waitForFullscreenButton("false");
});

test("a view link restores the volume, camera and transfer function; a hostile one is refused", async () => {
  await openFromPicker(SCAN);
  // A turned view and a custom transfer function.
  const box = await page.$eval("#view-canvas", (el) => { const r = el.getBoundingClientRect(); return { x: r.x + r.width / 2, y: r.y + r.height / 2 }; });
  await page.mouse.move(box.x, box.y);
  await page.mouse.down();
  for (let i = 1; i <= 8; i++) { await page.mouse.move(box.x + i * 10, box.y + i * 4); await page.waitForTimeout(30); }
  await page.mouse.up();
  await page.focus("#tf-editor");
  await page.keyboard.press("ArrowRight");
  await page.keyboard.press("ArrowRight");
  await page.keyboard.press("Shift+ArrowUp");
  const final = await waitForFinal(page, { minRequest: Math.max(await lastSentId(page, "camera"), await lastSentId(page, "transfer_function")) });
  await page.click("#copy-link");
  const url = await page.evaluate(() => location.href);
  assert.match(url, /#volume=tiny%2Fball\.nrrd&eye=/);
  const want = await page.evaluate(() => ({ camera: window.volcast.session.scene.camera, tf: window.volcast.session.scene.transfer_function }));

  const other = await openPage(browser.context, url);
  try {
    await other.page.waitForFunction((n) => window.volcast.session.volume?.name === n, SCAN, { timeout: 60000 });
    // The link's camera goes out as the volume opens (before this test's send log is hooked
    // up): wait for a final frame that shows it.
    const shown = await (await other.page.waitForFunction((eye) => {
      const h = window.volcast.shown;
      return h?.final && h.camera.eye.every((x, i) => Math.abs(x - eye[i]) <= 1e-6 * Math.abs(eye[i]) + 1e-9) ? h : null;
    }, want.camera.eye, { timeout: 60000, polling: 50 })).jsonValue();
    const got = await other.page.evaluate(async () => (await window.volcast.session.getState()).scene);
    // The link writes each number as the shortest text of the same double: well within 5e-7 of itself.
    for (const k of ["eye", "target", "up"]) got.camera[k].forEach((x, i) => assert.ok(Math.abs(x - want.camera[k][i]) <= 5e-7 * Math.abs(want.camera[k][i]) + 1e-12, `${k}[${i}] ${x} vs ${want.camera[k][i]}`));
    assert.equal(got.transfer_function.points.length, want.tf.points.length);
    got.transfer_function.points.forEach((p, i) => p.forEach((x, k) => assert.ok(Math.abs(x - want.tf.points[i][k]) <= 5e-7 * Math.abs(want.tf.points[i][k]) + 1e-12)));
    assert.deepEqual([shown.width, shown.height], [final.width, final.height]);
    await screenshot(other.page, "rough-04-from-view-link.png");
  } finally {
    await other.page.close();
  }

  const hostile = await openPage(browser.context, `${server.url}#volume=..%2F..%2Fetc%2Fpasswd&eye=1,2,3`);
  try {
    const error = hostile.page.locator('#errors .error[data-code="view_link"]');
    await error.waitFor({ state: "visible", timeout: 30000 });
    assert.match(await error.textContent(), /relative to the server's data folders/);
    // The rest of the page works: the server's default volume opens.
    await hostile.page.waitForFunction(() => window.volcast.session.volume?.name === "builtin:demo", null, { timeout: 60000 });
  } finally {
    await hostile.page.close();
  }
});

test("on a phone-sized screen the stats sit below the image, not over it", async () => {
  const phone = await browser.context.newPage();
  try {
    await phone.setViewportSize({ width: 390, height: 844 });
    await phone.goto(server.url);
    await phone.waitForFunction(() => window.volcast?.shown?.final, null, { timeout: 90000 });
    const rects = await phone.evaluate(() => Object.fromEntries(["view-canvas", "stats"].map((id) => {
      const r = document.getElementById(id).getBoundingClientRect();
      return [id, { left: r.left, top: r.top, right: r.right, bottom: r.bottom }];
    })));
    const a = rects["view-canvas"], b = rects.stats;
    const overlap = Math.max(0, Math.min(a.right, b.right) - Math.max(a.left, b.left)) * Math.max(0, Math.min(a.bottom, b.bottom) - Math.max(a.top, b.top));
    assert.equal(overlap, 0, `stats ${JSON.stringify(b)} over the view ${JSON.stringify(a)}`);
    assert.ok(b.bottom - b.top > 40, "the stats are still shown");
    assert.ok(a.bottom - a.top >= 300 && a.right - a.left >= 380, `the view keeps most of the screen: ${JSON.stringify(a)}`);
    await phone.screenshot({ path: artifact("rough-05-phone.png") });
    updateDocScreenshot("rough-05-phone.png", "client-phone.png");
  } finally {
    await phone.close();
  }
});

test("a scene saved from the server renders with volcast-render --data as it is", async (t) => {
  // One unjittered pass (an averaged jittered final level matches only within its noise).
  await page.check('input[name="quality-mode"][value="explicit"]');
  await page.fill("#q-step", "1");
  await page.dispatchEvent("#q-step", "change");
  await page.uncheck("#q-jitter");
  await page.waitForFunction(() => window.volcast.shown?.final && window.volcast.shown.quality.step === 1 && !window.volcast.shown.quality.jitter, null, { timeout: 60000 });
  const final = await waitForFinal(page, { minRequest: await lastSentId(page, "quality_policy") });
  assert.equal(await page.evaluate(() => window.volcast.session.volume.name), SCAN);
  const pngPath = await download(page, "#save-png", "rough-06-final-frame.png");
  const scenePath = await download(page, "#save-scene", "rough-06-scene.json");
  const scene = JSON.parse(readFileSync(scenePath, "utf8"));
  assert.equal(scene.volume, SCAN, "the scene keeps the server-relative name");

  // Without --data the name is taken relative to the scene file's folder: not there.
  const outPath = artifact("rough-06-volcast-render.png");
  const without = await run(RENDER_EXE, [scenePath, "-o", outPath]);
  assert.notEqual(without.code, 0, "without --data the scan is not found");
  const r = await run(RENDER_EXE, [scenePath, "--data", dataDir, "-o", outPath]);
  assert.equal(r.code, 0, `volcast-render --data failed:\n${r.err}${r.out}`);
  const mine = decodePng(readFileSync(pngPath)), theirs = decodePng(readFileSync(outPath));
  assert.deepEqual([theirs.width, theirs.height], [final.width, final.height]);
  // The same bound as client.test.mjs's saved-scene test (re-premultiplying costs ≤ 1/255,
  // 2 at an exact rounding boundary).
  const d = compareBytes(overBlack(mine), overBlack(theirs));
  t.diagnostic(`final frame vs volcast-render --data: max ${d.maxDiff}/255, ${d.channelsOver1} channels over 1`);
  assert.ok(d.maxDiff <= 1 || (d.maxDiff === 2 && d.channelsOver1 * 1e4 < mine.width * mine.height), `max channel difference ${d.maxDiff}/255`);

  // Confined as the server confines names: a scene naming ../ or an absolute path is refused.
  for (const volume of ["../" + path.basename(dataDir) + "/" + SCAN, path.join(dataDir, SCAN)]) {
    const bad = artifact("rough-06-bad-scene.json");
    writeFileSync(bad, JSON.stringify({ ...scene, volume }));
    const refused = await run(RENDER_EXE, [bad, "--data", dataDir, "-o", outPath]);
    assert.notEqual(refused.code, 0, `volume ${volume} refused`);
    assert.match(refused.err, /must name a volume relative to the data folders/);
  }
});

test("after a server restart the page is connected again within 1 s of the server answering", async () => {
  const port = server.port;
  await page.evaluate(() => {
    window.readyAt = [];
    window.volcast.session.connection.on("state", (s) => { if (s.state === "ready") window.readyAt.push(Date.now()); });
  });
  await server.stop();
  // Long enough down for the WebSocket back-off to pass 2 s (250 + 500 + 1000 + 2000 ms).
  await page.waitForTimeout(5000);
  assert.equal(await page.$eval("#connection", (el) => el.dataset.state), "waiting");

  // Watch /healthz from here: the moment it first answers is when the server is back.
  let answeredAt = null, watching = true;
  const watch = (async () => {
    while (watching && answeredAt === null) {
      try { await fetch(`http://127.0.0.1:${port}/healthz`); answeredAt = Date.now(); } catch { await new Promise((r) => setTimeout(r, 10)); }
    }
  })();
  server = await startServer(port, serverArgs());
  watching = false;
  await watch;
  await page.waitForFunction(() => window.readyAt.length > 0, null, { timeout: 30000 });
  const readyAt = await page.evaluate(() => window.readyAt[0]);
  t_diag(`server answered /healthz at +0 ms; page ready at +${readyAt - answeredAt} ms`);
  assert.ok(answeredAt !== null);
  assert.ok(readyAt - answeredAt <= 1000, `reconnected ${readyAt - answeredAt} ms after the server answered`);
  await waitForFinal(page, { minRequest: await lastSentId(page, "open_volume") });
  assert.deepEqual(problems.filter((p) => !/WebSocket|ERR_CONNECTION_REFUSED|healthz/.test(p)), []);
});

function t_diag(text) { console.log(`# ${text}`); }
