// The web client in headless Chromium against a real volcast-server started here on a free
// port. The tests run in order on one page, as a user would: connect, look, drag, change
// the transfer function, save and reproduce the scene, open a volume that does not exist,
// and survive a server restart. Each saves a screenshot into the artifacts folder.
import { test } from "node:test";
import assert from "node:assert/strict";
import { existsSync, readFileSync, writeFileSync } from "node:fs";
import path from "node:path";

import {
  DATA_DIR, RENDER_EXE, VIEWPORT, artifact, canvasSummary, connectionState, download,
  launchBrowser, openPage, run, screenshot, shownSeq, startServer, thumbDifference,
  updateDocScreenshot, waitForFinal,
} from "./harness.mjs";
import { pageUnderTest } from "./page_setup.mjs";
import { compareBytes, decodePng, overBlack } from "../lib/png.mjs";

// The first test waits for the connection and the volume itself.
let page, problems;
const setup = pageUnderTest({ volume: null, ready: (s) => ({ page, problems } = s) });

test("the page loads and connects", async () => {
  await page.waitForFunction(() => document.getElementById("connection").dataset.state === "ready", null, { timeout: 30000 });
  const text = await page.textContent("#connection-text");
  assert.match(text, /^Connected · /);
  assert.match(await page.title(), /volcast$/);
  // The server's default volume opens by itself, and the picker names it.
  await page.waitForFunction(() => window.volcast.session.volume?.name === "builtin:demo", null, { timeout: 60000 });
  assert.equal(await page.inputValue("#volume-select"), "builtin:demo");
  assert.equal(await page.title(), "builtin:demo — volcast");
  await screenshot(page, "01-connected.png");
  assert.deepEqual(problems, []);
});

test("the canvas shows a non-blank rendering of the demo volume", async () => {
  const final = await waitForFinal(page);
  assert.equal(final.codec, "png");
  assert.ok(await page.isHidden("#view-message"), "no message covers a finished image");
  const c = await canvasSummary(page);
  // The phantom fills roughly a third of the view; anything under 5 % lit is a broken
  // image (all black, or only noise), anything over 95 % is not a volume on black.
  assert.ok(c.litFraction > 0.05 && c.litFraction < 0.95, `lit fraction ${c.litFraction}`);
  assert.ok(Math.max(...c.mean) > 8, `mean colour ${c.mean}`);
  // The canvas backing store is the CSS size times devicePixelRatio (1 here).
  const css = await page.$eval("#view-canvas", (el) => [el.clientWidth, el.clientHeight]);
  assert.deepEqual([c.width, c.height], css);
  assert.deepEqual([final.width, final.height], css, "the final frame has the view's size (CSS pixels on a CPU server)");
  // Every frame before it fills the same view (a level of fewer rays comes smaller, with the
  // view's size beside it): the "Connected" text re-wraps the top bar as the session starts,
  // and the size sent then is the view's after that, not the one measured before.
  const sizes = await page.evaluate(() => window.volcast.frames.map((h) => `${h.view_width ?? h.width}×${h.view_height ?? h.height}`));
  assert.deepEqual([...new Set(sizes)], [css.join("×")], "the sizes of the frames since the page connected");
  await screenshot(page, "02-demo-volume.png");
});

test("a mouse drag produces interactive frames and, after release, a final frame", async () => {
  const before = await page.evaluate(() => ({ seq: window.volcast.shown.seq, camera: window.volcast.session.scene.camera, sent: window.sentLog.length }));
  const box = await page.$eval("#view-canvas", (el) => { const r = el.getBoundingClientRect(); return { x: r.x, y: r.y, w: r.width, h: r.height }; });
  const cx = box.x + box.w / 2, cy = box.y + box.h / 2;
  await page.mouse.move(cx, cy);
  await page.mouse.down();
  // ~1.5 s of dragging: on a 2-core CPU an interactive frame takes ~100–400 ms.
  for (let i = 1; i <= 30; i++) {
    await page.mouse.move(cx + i * 6, cy + i * 2);
    await page.waitForTimeout(50);
  }
  // Hold still (button down) until an interactive frame of the drag is on screen.
  await page.waitForFunction((seq) => window.volcast.frames.some((h) => h.seq > seq && !h.final), before.seq, { timeout: 30000 });
  const duringDrag = await page.evaluate((seq) => window.volcast.frames.filter((h) => h.seq > seq), before.seq);
  await screenshot(page, "03-dragging.png");
  await page.mouse.up();
  const released = await page.evaluate(() => window.volcast.frames.at(-1).seq);

  const final = await waitForFinal(page, { afterSeq: released });
  const sent = await page.evaluate((n) => window.sentLog.slice(n), before.sent);
  const types = sent.map((m) => m.type);
  assert.equal(types[0], "interaction_start");
  assert.ok(types.includes("interaction_end"));
  const cameras = sent.filter((m) => m.type === "camera");
  assert.ok(cameras.length >= 5, `${cameras.length} camera messages`);
  assert.ok(types.indexOf("interaction_end") > types.lastIndexOf("camera"), "end comes after the last camera");

  const interactive = duringDrag.filter((h) => !h.final);
  assert.ok(interactive.length >= 1, "at least one interactive frame while dragging");
  for (const h of interactive) {
    assert.equal(h.codec, "jpeg");
    assert.ok(cameras.some((m) => m.id === h.request), `interactive frame ${h.seq} answers one of the drag's cameras`);
  }
  // The final frame shows the last camera sent, losslessly.
  assert.equal(final.codec, "png");
  assert.equal(final.request, cameras.at(-1).id);
  const camera = await page.evaluate(() => window.volcast.session.scene.camera);
  assert.deepEqual(final.camera, camera);
  assert.notDeepEqual(camera, before.camera);
  await screenshot(page, "03-after-drag-final.png");
});

// Distance from the eye to the target of the camera the page holds.
const eyeDistance = (page) => page.evaluate(() => {
  const c = window.volcast.session.scene.camera;
  return Math.hypot(c.eye[0] - c.target[0], c.eye[1] - c.target[1], c.eye[2] - c.target[2]);
});

test("the wheel and a two-finger pinch zoom, each as one interaction", async () => {
  const box = await page.$eval("#view-canvas", (el) => { const r = el.getBoundingClientRect(); return { x: r.x, y: r.y, w: r.width, h: r.height }; });
  const cx = box.x + box.w / 2, cy = box.y + box.h / 2;
  const d0 = await eyeDistance(page);
  const sent0 = await page.evaluate(() => window.sentLog.length);
  await page.mouse.move(cx, cy);
  for (let i = 0; i < 5; i++) { await page.mouse.wheel(0, -100); await page.waitForTimeout(20); }
  await page.waitForFunction((n) => window.sentLog.slice(n).some((m) => m.type === "interaction_end"), sent0, { timeout: 5000 });
  const d1 = await eyeDistance(page);
  // Wheel up zooms in: 500 px at exp(-0.0015 · px) brings the eye to ~47 % of its distance.
  assert.ok(Math.abs(d1 / d0 - Math.exp(-0.0015 * 500)) < 0.01, `distance ${d0} → ${d1}`);
  const wheelTypes = (await page.evaluate((n) => window.sentLog.slice(n), sent0)).map((m) => m.type);
  assert.equal(wheelTypes.filter((t) => t === "interaction_start").length, 1);
  assert.equal(wheelTypes.filter((t) => t === "interaction_end").length, 1);

  // Two fingers moving apart (real touch input through Chrome's DevTools protocol).
  const cdp = await page.context().newCDPSession(page);
  const touch = (type, spread) => cdp.send("Input.dispatchTouchEvent", {
    type, touchPoints: type === "touchEnd" ? [] : [{ x: cx - spread, y: cy, id: 1 }, { x: cx + spread, y: cy, id: 2 }],
  });
  const sent1 = await page.evaluate(() => window.sentLog.length);
  await touch("touchStart", 40);
  for (let spread = 45; spread <= 80; spread += 5) { await touch("touchMove", spread); await page.waitForTimeout(30); }
  await touch("touchEnd", 0);
  await page.waitForFunction((n) => window.sentLog.slice(n).some((m) => m.type === "interaction_end"), sent1, { timeout: 5000 });
  const d2 = await eyeDistance(page);
  // Fingers from 80 to 160 px apart: the view comes twice as close.
  assert.ok(Math.abs(d2 / d1 - 0.5) < 0.02, `pinch: distance ${d1} → ${d2}`);
  const final = await waitForFinal(page, { minRequest: await page.evaluate(() => window.sentLog.filter((m) => m.type === "camera").at(-1).id) });
  assert.deepEqual(final.camera, await page.evaluate(() => window.volcast.session.scene.camera));
  await screenshot(page, "03b-zoomed.png");
  // Keys do the same from the keyboard: an arrow orbits, as one interaction.
  const sent2 = await page.evaluate(() => window.sentLog.length);
  const cam2 = await page.evaluate(() => window.volcast.session.scene.camera);
  await page.focus("#view-canvas");
  await page.keyboard.press("ArrowLeft");
  await page.waitForFunction((n) => window.sentLog.slice(n).some((m) => m.type === "interaction_end"), sent2, { timeout: 5000 });
  const keyed = (await page.evaluate((n) => window.sentLog.slice(n), sent2)).map((m) => m.type);
  assert.deepEqual(keyed, ["interaction_start", "camera", "interaction_end"]);
  assert.notDeepEqual(await page.evaluate(() => window.volcast.session.scene.camera), cam2);
  // Back to the starting view for the tests that follow (and to test the button).
  await page.click("#reset-view");
  await waitForFinal(page, { minRequest: await page.evaluate(() => window.sentLog.filter((m) => m.type === "camera").at(-1).id) });
});

test("the transfer-function editor adds, drags and removes points", async () => {
  const lastTf = () => page.evaluate(() => {
    const m = window.sentLog.filter((x) => x.type === "transfer_function").at(-1);
    return m ? window.volcast.session.scene.transfer_function : null;
  });
  const n0 = await page.evaluate(() => window.volcast.session.scene.transfer_function.points?.length ?? 0);
  // The side panel scrolls (the orientation and preset cards come first): bring the curve into view.
  const box = await page.$eval("#tf-editor", (el) => { el.scrollIntoView({ block: "center" }); const r = el.getBoundingClientRect(); return { x: r.x, y: r.y, w: r.width, h: r.height }; });
  // Click low in the plot, a third of the way along: adds a point there.
  const px = box.x + box.w * 0.33, py = box.y + box.h * 0.6;
  await page.mouse.move(px, py);
  await page.mouse.down();
  await page.mouse.up();
  await page.waitForFunction((n) => window.volcast.session.scene.transfer_function.points?.length === n + 1, n0);
  assert.equal(await page.$eval("#tf-preset", (el) => el.value), "", "an edited curve is custom");
  const added = (await lastTf()).points;
  const i = await page.$eval("#tf-point-value", (el) => Number(el.value)).then((v) => added.findIndex((p) => Math.abs(p[0] - v) < 1e-3 * Math.max(1, Math.abs(v))));
  assert.ok(i > 0, "the new point is selected and shown in the fields");
  // Drag it up: its opacity rises, its value stays between its neighbours.
  await page.mouse.move(px, py);
  await page.mouse.down();
  for (let k = 1; k <= 5; k++) await page.mouse.move(px, py - k * 10);
  await page.mouse.up();
  await page.waitForFunction(([idx, a]) => window.volcast.session.scene.transfer_function.points[idx][4] > a, [i, added[i][4]]);
  const dragged = (await lastTf()).points;
  assert.ok(dragged[i][0] > dragged[i - 1][0] && dragged[i][0] < dragged[i + 1][0]);
  // A colour for it, then remove it with the Delete key.
  await page.$eval("#tf-point-color", (el) => { el.value = "#20c0ff"; el.dispatchEvent(new Event("input", { bubbles: true })); });
  await page.waitForFunction((idx) => window.volcast.session.scene.transfer_function.points[idx][3] > 0.99, i);
  await page.focus("#tf-editor");
  await page.keyboard.press("Delete");
  await page.waitForFunction((n) => window.volcast.session.scene.transfer_function.points.length === n, n0);
  const id = await page.evaluate(() => window.sentLog.filter((m) => m.type === "transfer_function").at(-1).id);
  await waitForFinal(page, { minRequest: id });
  await screenshot(page, "03c-tf-edited.png");
});

test("the quality panel's explicit switches and the clip plane reach the server", async () => {
  const before = await canvasSummary(page);
  const sent0 = await page.evaluate(() => window.sentLog.length);
  await page.check('input[name="quality-mode"][value="explicit"]');
  await page.fill("#q-step", "1");
  await page.dispatchEvent("#q-step", "change");
  await page.check("#clip-enabled");
  await page.selectOption("#clip-axis", "0");
  await page.waitForFunction((n) => ["quality_policy", "clip_planes"].every((t) => window.sentLog.slice(n).some((m) => m.type === t)), sent0, { timeout: 5000 });
  const ids = await page.evaluate((n) => window.sentLog.slice(n).map((m) => m.id), sent0);
  const final = await waitForFinal(page, { minRequest: Math.max(...ids) });
  // An explicit policy has one level, 0, with exactly the switches sent.
  assert.equal(final.level, 0);
  assert.equal(final.quality.step, 1);
  const state = await page.evaluate(() => window.volcast.session.getState());
  assert.equal(state.quality_policy.mode, "explicit");
  assert.equal(state.quality_policy.quality.step, 1);
  assert.equal(state.scene.clip_planes.length, 1);
  assert.deepEqual(state.scene.clip_planes[0].normal, [1, 0, 0]);
  const after = await canvasSummary(page);
  assert.ok(after.litFraction < before.litFraction, `clipping removes part of the volume: ${before.litFraction} → ${after.litFraction}`);
  await screenshot(page, "03d-explicit-clipped.png");
});

test("choosing another transfer-function preset changes the image", async () => {
  const before = await canvasSummary(page);
  const sentBefore = await page.evaluate(() => window.sentLog.length);
  await page.selectOption("#tf-preset", "micro_ct");
  await page.waitForFunction((n) => window.sentLog.slice(n).some((m) => m.type === "transfer_function"), sentBefore);
  const tfId = await page.evaluate((n) => window.sentLog.slice(n).find((m) => m.type === "transfer_function").id, sentBefore);
  await waitForFinal(page, { minRequest: tfId });
  const afterPreset = await canvasSummary(page);
  const diff = thumbDifference(before.thumb, afterPreset.thumb);
  // Another preset recolours and re-weights the whole phantom: a mean change of a few
  // grey levels over the thumbnail is the least that can be called "changed".
  assert.ok(diff > 3, `mean thumbnail difference ${diff.toFixed(2)} / 255`);
  const tf = await page.evaluate(async () => (await window.volcast.session.getState()).scene.transfer_function);
  assert.deepEqual(tf, { preset: "micro_ct" });
  await screenshot(page, "04-preset-micro-ct.png");
});

test("the saved scene renders with volcast-render to the same image", async (t) => {
  const final = await waitForFinal(page);
  const pngPath = await download(page, "#save-png", "05-final-frame.png");
  const scenePath = await download(page, "#save-scene", "05-scene.json");
  const scene = JSON.parse(readFileSync(scenePath, "utf8"));
  assert.equal(scene.volume, "builtin:demo");
  assert.deepEqual(scene.image, { width: final.width, height: final.height });
  assert.deepEqual(scene.camera, final.camera);
  assert.deepEqual(scene.quality, final.quality);
  assert.equal(scene.clip_planes.length, 1, "the clip plane is part of the scene");
  await screenshot(page, "05-saved.png");

  const outPath = artifact("05-volcast-render.png");
  const r = await run(RENDER_EXE, [scenePath, "-o", outPath]);
  assert.equal(r.code, 0, `volcast-render failed:\n${r.err}${r.out}`);
  const mine = decodePng(readFileSync(pngPath));
  const theirs = decodePng(readFileSync(outPath));
  assert.deepEqual([mine.width, mine.height], [theirs.width, theirs.height]);
  // The frame is straight RGBA (premultiplied floats divided by alpha, rounded); volcast-render's
  // PNG is the premultiplied colour over black, rounded. Compared as the viewer shows both:
  // over black. Re-premultiplying the frame's bytes costs at most ~1 step: with R = 255c/a + dr
  // and A = 255a + da (|dr|, |da| <= 1/2), R·A/255 = 255c + da·c/a + dr·a + dr·da/255, off by at
  // most 1.001 (c <= a), so the two rounded values may differ by 1/255 and, at a rounding
  // boundary hit exactly, by 2; anything larger means another image.
  const d = compareBytes(overBlack(mine), overBlack(theirs));
  writeFileSync(artifact("05-comparison.json"), `${JSON.stringify({ ...d, frame: final.seq, quality: final.quality }, null, 2)}\n`);
  t.diagnostic(`final frame vs volcast-render, over black: max ${d.maxDiff}/255, RMSE ${d.rmse.toExponential(2)}, ${d.channelsOver1} channels over 1/255`);
  assert.equal(mine.channels, 4, "the final frame is RGBA");
  assert.ok(d.maxDiff <= 1 || (d.maxDiff === 2 && d.channelsOver1 * 1e4 < mine.width * mine.height),
    `max channel difference ${d.maxDiff}/255 (${d.channelsOver1} channels over 1)`);
});

test("opening an unknown volume shows the server's error", async () => {
  const name = "no_such_volume.nrrd";
  await page.fill("#volume-name", name);
  await page.click("#open-volume");
  const error = page.locator("#errors .error").first();
  await error.waitFor({ state: "visible", timeout: 30000 });
  assert.equal(await error.getAttribute("data-code"), "not_found");
  const text = await error.textContent();
  assert.ok(text.includes(name), `the error names the volume: ${text}`);
  assert.match(text, /open_volume/);
  // The volume that was open stays open, and the view keeps its image.
  assert.equal(await page.evaluate(() => window.volcast.session.volume.name), "builtin:demo");
  assert.ok(await page.isHidden("#view-message"));
  await screenshot(page, "06-unknown-volume.png");
});

test("after the server restarts, the page reconnects by itself and restores the view", async () => {
  const port = setup.server.port;
  const camera = await page.evaluate(() => window.volcast.session.scene.camera);
  const stopped = await setup.server.stop();
  let sentBefore;
  try {
    assert.ok(stopped.code === 0 || stopped.signal === "SIGTERM", `server stopped cleanly: ${JSON.stringify(stopped)}`);
    // The client goes on retrying (waiting, connecting, waiting, ...) and the indicator's
    // state and text change together: read both in one look, not one round trip apart.
    const down = await (await page.waitForFunction(() => {
      const box = document.getElementById("connection");
      return box.dataset.state === "waiting" ? document.getElementById("connection-text").textContent : null;
    }, null, { timeout: 15000 })).jsonValue();
    assert.match(down, /Disconnected · retrying in/);
    assert.ok(await page.isVisible("#view-message"), "the stale image is explained");
    await screenshot(page, "07-server-down.png");
    sentBefore = await page.evaluate(() => window.sentLog.length);
  } finally {
    // Up again whatever failed above: the later tests need a server.
    setup.server = await startServer(port);
  }
  await page.waitForFunction(() => document.getElementById("connection").dataset.state === "ready", null, { timeout: 30000 });
  // Request ids keep counting across connections: the first frame of the new session
  // answers the reopened volume or a later request.
  await page.waitForFunction((n) => window.sentLog.slice(n).some((m) => m.type === "open_volume"), sentBefore, { timeout: 30000 });
  const reopen = await page.evaluate((n) => window.sentLog.slice(n).find((m) => m.type === "open_volume").id, sentBefore);
  const final = await waitForFinal(page, { minRequest: reopen });
  const state = await page.evaluate(async () => (await window.volcast.session.getState()).scene);
  assert.deepEqual(state.camera, camera, "the camera came back");
  assert.deepEqual(state.transfer_function, { preset: "micro_ct" }, "the transfer function came back");
  assert.equal(state.clip_planes?.length, 1, "the clip plane came back");
  assert.equal(final.quality.step, 1, "the explicit quality policy came back");
  assert.deepEqual(final.camera, camera);
  assert.equal(await connectionState(page), "ready");
  const states = await page.evaluate(() => window.stateLog);
  assert.deepEqual(states.slice(-3), ["connecting", "handshaking", "ready"]);
  assert.ok(await page.isHidden("#view-message"));
  await screenshot(page, "07-reconnected.png");
  assert.deepEqual(problems.filter((p) => !/WebSocket|ERR_CONNECTION_REFUSED/.test(p)), []);
});

// The README's screenshot: a real CT scan from VOLCAST_DATA_DIR, opened from the
// picker. Skipped where the scans are not there (they live beside the repository).
const CT_SCAN = "cranium_ct.nhdr";
const haveScan = Boolean(DATA_DIR) && existsSync(path.join(DATA_DIR, CT_SCAN));

test("a real CT scan opens from the picker, with progress, and renders", { skip: !haveScan && `no ${CT_SCAN} in VOLCAST_DATA_DIR` }, async () => {
  const names = await page.evaluate(() => window.volcast.session.volumes.map((v) => v.name));
  assert.ok(names.includes(CT_SCAN), `the server lists ${CT_SCAN}: ${names.join(", ")}`);
  // Back to the automatic policy at the server's default final step, and a clean view.
  const policiesBefore = await page.evaluate(() => window.sentLog.filter((m) => m.type === "quality_policy").length);
  await page.check('input[name="quality-mode"][value="automatic"]');
  await page.fill("#q-step", "0.5");
  await page.dispatchEvent("#q-step", "change");
  for (const close of await page.$$("#errors .error button")) await close.click();
  assert.equal(await page.locator("#errors .error").count(), 0, "errors can be dismissed");
  // The panel coalesces its edits into one quality_policy after a short settling time.
  await page.waitForFunction((n) => window.sentLog.filter((m) => m.type === "quality_policy").length > n, policiesBefore);
  await page.fill("#volume-name", CT_SCAN);
  await page.click("#open-volume");
  // Until its first frame the view says what is happening, with a progress bar.
  assert.match(await page.textContent("#view-message-title"), new RegExp(`Opening ${CT_SCAN}|Rendering ${CT_SCAN}`));
  await page.waitForFunction((name) => window.volcast.session.volume?.name === name, CT_SCAN, { timeout: 120000 });
  // The scan's own final frame: the demo's may still be on show when the volume opens.
  const openId = await page.evaluate(() => window.sentLog.filter((m) => m.type === "open_volume").at(-1).id);
  const final = await waitForFinal(page, { minRequest: openId, timeout: 120000 });
  assert.equal(final.codec, "png");
  assert.equal(await page.$eval("#tf-preset", (el) => el.value), "ct.bone", "a CT in Hounsfield units starts with the server's CT bone preset");
  const c = await canvasSummary(page);
  assert.ok(c.litFraction > 0.05, `lit fraction ${c.litFraction}`);
  assert.equal(final.quality.step, 0.5, JSON.stringify(final.quality));
  assert.ok(await page.isHidden("#clip-enabled:checked"), "a new volume starts unclipped");
  // A larger window for the README's picture: the view follows the window's size.
  const seq = final.seq;
  await page.setViewportSize({ width: 1440, height: 860 });
  await page.$eval(".panel", (el) => { el.scrollTop = 0; });
  const larger = await waitForFinal(page, { afterSeq: seq, timeout: 120000 });
  assert.ok(larger.width > final.width && larger.height > final.height, `${final.width}×${final.height} → ${larger.width}×${larger.height}`);
  await screenshot(page, "08-cranium-ct.png");
  updateDocScreenshot("08-cranium-ct.png", "client-cranium-ct.png");
  await page.setViewportSize(VIEWPORT);
});

test("on a high-density screen the canvas has device pixels and the resolution choice is honoured", async () => {
  const hiDpi = await launchBrowser({ deviceScaleFactor: 2 });
  try {
    const { page: p2, problems: p2problems } = await openPage(hiDpi.context, `${setup.server.url}?volume=builtin:demo`);
    await p2.waitForFunction(() => window.volcast.session.volume?.name === "builtin:demo", null, { timeout: 60000 });
    const css = await p2.$eval("#view-canvas", (el) => [el.clientWidth, el.clientHeight]);
    const backing = await p2.$eval("#view-canvas", (el) => [el.width, el.height]);
    assert.deepEqual(backing, css.map((x) => x * 2), "backing store = CSS size × devicePixelRatio");
    // "automatic" on a CPU device renders CSS pixels (scaled up on the canvas) ...
    await p2.waitForFunction(() => window.volcast.session.viewport);
    assert.deepEqual(await p2.evaluate(() => window.volcast.session.viewport), { width: css[0], height: css[1] });
    // ... and "device pixels" asks for the full resolution.
    await p2.selectOption("#resolution", "device");
    await p2.waitForFunction((w) => window.volcast.session.viewport.width === w, css[0] * 2);
    assert.deepEqual(await p2.evaluate(() => window.volcast.session.viewport), { width: css[0] * 2, height: css[1] * 2 });
    await p2.selectOption("#resolution", "half");
    await p2.waitForFunction((w) => Math.abs(window.volcast.session.viewport.width - w / 2) <= 1, css[0]);
    const viewport = await p2.evaluate(() => window.volcast.session.viewport);
    // Half of the CSS size, rounded from the fractional layout size: within a pixel.
    assert.ok(Math.abs(viewport.height - css[1] / 2) <= 1, `${viewport.height} vs ${css[1]} / 2`);
    // The final frame of the half-resolution request, not a late final of an earlier size.
    const halfId = await p2.evaluate(() => window.sentLog.filter((m) => m.type === "viewport").at(-1).id);
    const final = await waitForFinal(p2, { minRequest: halfId, timeout: 120000 });
    assert.deepEqual({ width: final.width, height: final.height }, viewport);
    await screenshot(p2, "09-high-density-half-resolution.png");
    assert.deepEqual(p2problems, []);
  } finally {
    await hiDpi.close();
  }
});
