// Opening a file from the user's disk, in headless Chromium against a real volcast-server:
// a small NRRD written here is dropped on the page (a drop event holding a File), uploaded
// with POST /api/volumes and opened, and a frame is drawn; the same through "Open file…";
// the page's address then reopens the upload while it lives; an expired (unknown) upload
// says so in words; a file the server cannot read, one over the upload limit (the server
// runs with --max-upload-mib 1) and one it does not open show why. The server runs with
// --token and the page is opened with ?token=: uploads carry it, and one without is refused.
// On a throttled connection the upload's progress shows over the view.
// Saves open-file-drop.png (the drop overlay) and open-file.png in the artifacts, and with
// VOLCAST_UPDATE_DOC_SCREENSHOTS=1 over docs/images/web/open-file-drop.png and open-file-progress.png.
import { test } from "node:test";
import assert from "node:assert/strict";

import { canvasSummary, screenshot, shownSeq, updateDocScreenshot, waitForFinal } from "./harness.mjs";
import { pageUnderTest } from "./page_setup.mjs";

const UPLOAD_LIMIT_MIB = 1;   // the server's --max-upload-mib here: the big file below is over it
const TOKEN = "open-file-test-token";

// An 8 × 8 × 8 uint8 NRRD: a bright ball (200) in the middle of dark voxels.
function smallNrrd() {
  const header = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 8 8 8\nencoding: raw\n\n";
  const voxels = Buffer.alloc(512);
  for (let z = 0; z < 8; z++) for (let y = 0; y < 8; y++) for (let x = 0; x < 8; x++) {
    voxels[(z * 8 + y) * 8 + x] = Math.hypot(x - 3.5, y - 3.5, z - 3.5) < 3 ? 200 : 0;
  }
  return Buffer.concat([Buffer.from(header, "latin1"), voxels]);
}

let page, problems, server;
pageUnderTest({
  serverOptions: () => ({ extraArgs: ["--max-upload-mib", String(UPLOAD_LIMIT_MIB), "--token", TOKEN] }),
  query: `?token=${TOKEN}`,
  finalFrame: true,
  ready: (s) => ({ page, problems, server } = s),
});

// The uploads the page sends, as the server receives them (method, address, file name header).
const uploads = [];
const watchUploads = () => page.on("request", (r) => {
  if (new URL(r.url()).pathname === "/api/volumes") {
    uploads.push({ method: r.method(), url: r.url(), filename: r.headers()["x-volcast-filename"], authorization: r.headers().authorization });
  }
});

// Drop `bytes` as a file called `name` on the view, as a person dragging it from their desktop would.
async function dropFile(name, bytes, { screenshotName } = {}) {
  await page.evaluate(({ name, data }) => {
    const dt = new DataTransfer();
    dt.items.add(new File([new Uint8Array(data)], name, { type: "application/octet-stream" }));
    const target = document.getElementById("view-canvas");
    for (const type of ["dragenter", "dragover"]) target.dispatchEvent(new DragEvent(type, { dataTransfer: dt, bubbles: true, cancelable: true }));
    window.droppedFile = dt;
  }, { name, data: [...bytes] });
  assert.ok(await page.isVisible("#drop-overlay"), "dragging a file over the page says what a drop does");
  if (screenshotName) await screenshot(page, screenshotName);
  await page.evaluate(() => {
    document.getElementById("view-canvas").dispatchEvent(new DragEvent("drop", { dataTransfer: window.droppedFile, bubbles: true, cancelable: true }));
  });
  assert.ok(await page.isHidden("#drop-overlay"), "the overlay goes with the drop");
}

const uploadState = () => page.evaluate(() => ({ state: window.volcast.opener.upload?.state, volume: window.volcast.opener.upload?.volume ?? null, message: window.volcast.opener.upload?.message ?? "" }));

async function waitForUploadEnd() {
  await page.waitForFunction(() => ["opened", "failed", "cancelled"].includes(window.volcast.opener.upload?.state), null, { timeout: 60000 });
  return uploadState();
}

const bannerTexts = () => page.$$eval("#errors .error", (els) => els.map((e) => `${e.dataset.code}: ${e.querySelector(".text").textContent}`));

test("a NRRD dropped on the page is uploaded, opened, and drawn", async () => {
  watchUploads();
  const before = await shownSeq(page);
  await dropFile("ball.nrrd", smallNrrd(), { screenshotName: "open-file-drop.png" });
  updateDocScreenshot("open-file-drop.png", "open-file-drop.png");
  const u = await waitForUploadEnd();
  assert.equal(u.state, "opened", `the upload ended ${u.state}: ${u.message}; banners: ${await bannerTexts()}`);
  assert.match(u.volume, /^upload:[0-9a-f]{32}$/, "the server's name for the upload");
  assert.deepEqual(uploads.at(-1), { method: "POST", url: `${server.url}api/volumes`, filename: "ball.nrrd", authorization: `Bearer ${TOKEN}` });
  assert.equal(await page.evaluate(() => window.volcast.session.volume?.name), u.volume);
  const frame = await waitForFinal(page, { afterSeq: before });
  assert.ok(frame.final);
  const summary = await canvasSummary(page);
  assert.ok(summary.litFraction > 0.005, `the ball is drawn: ${(summary.litFraction * 100).toFixed(2)} % of the view lit`);
  // The picker names the file, not the opaque id; the address keeps the id in its fragment only.
  assert.match(await page.$eval("#volume-select", (s) => s.selectedOptions[0]?.textContent ?? ""), /ball\.nrrd \(uploaded\)/);
  const url = new URL(page.url());
  assert.equal(url.searchParams.get("volume"), null, "an upload's id stays out of the query string (server logs)");
  assert.equal(new URLSearchParams(url.hash.slice(1)).get("volume"), u.volume);
  await screenshot(page, "open-file.png");
});

test("the page's address reopens the upload while it lives", async () => {
  const name = await page.evaluate(() => window.volcast.session.volume.name);
  await page.reload();
  await page.waitForFunction((n) => window.volcast?.session?.volume?.name === n, name, { timeout: 60000 });
  await waitForFinal(page, { afterSeq: 0 });
});

test("'Open file…' takes a file through the file chooser the same way", async () => {
  const before = await shownSeq(page);
  const [chooser] = await Promise.all([page.waitForEvent("filechooser"), page.click("#open-file")]);
  await chooser.setFiles({ name: "chosen.nrrd", mimeType: "application/octet-stream", buffer: smallNrrd() });
  const u = await waitForUploadEnd();
  assert.equal(u.state, "opened", u.message);
  assert.equal(uploads.at(-1).filename, "chosen.nrrd");
  await waitForFinal(page, { afterSeq: before });
});

test("a link to an upload the server no longer has says it expired, in words", async () => {
  const gone = `upload:${"0".repeat(32)}`;
  await page.goto("about:blank");   // else a link that differs in its fragment only is no new page
  await page.goto(`${server.url}?token=${TOKEN}#volume=${encodeURIComponent(gone)}`);
  await page.waitForFunction(() => window.volcast?.session);
  await page.waitForSelector("#view-message[data-kind='error']", { timeout: 30000 });
  assert.equal(await page.textContent("#view-message-title"), "This uploaded file has expired; open it again.");
  assert.ok((await bannerTexts()).some((t) => t.startsWith("not_found: This uploaded file has expired")), await bannerTexts());
  await page.waitForFunction(() => window.volcast.session.ready);
  await page.evaluate(() => window.volcast.session.openVolume("builtin:demo"));
  await waitForFinal(page);
});

test("a file the server cannot read shows the server's reason; nothing else changes", async () => {
  const before = await page.evaluate(() => window.volcast.session.volume?.name);
  await dropFile("garbage.nrrd", Buffer.from("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 8 8 8\nencoding: raw\n\nshort"));
  const u = await waitForUploadEnd();
  assert.equal(u.state, "failed");
  assert.match(u.message, /^The server could not read garbage\.nrrd: \S/, u.message);
  assert.ok((await bannerTexts()).some((t) => t.startsWith("upload: The server could not read garbage.nrrd")), await bannerTexts());
  assert.equal(await page.evaluate(() => window.volcast.session.volume?.name), before, "the open volume stays");
});

test("a file over the server's upload limit is refused with 413, and the page says so", async () => {
  const header = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 128 128 96\nencoding: raw\n\n";   // 1.5 MiB of voxels
  const big = Buffer.concat([Buffer.from(header, "latin1"), Buffer.alloc(128 * 128 * 96)]);
  const [chooser] = await Promise.all([page.waitForEvent("filechooser"), page.click("#open-file")]);
  await chooser.setFiles({ name: "big.nrrd", mimeType: "application/octet-stream", buffer: big });
  const u = await waitForUploadEnd();
  assert.equal(u.state, "failed");
  assert.match(u.message, /^big\.nrrd is over the server's upload limit/, u.message);
});

test("an upload without the server's token is refused with 401, in words", async () => {
  const message = await page.evaluate(async () => {
    const { Upload, uploadUrl } = await import("/core/upload.js");
    const u = new Upload(new File([new Uint8Array(600)], "a.nrrd"), { url: uploadUrl(window.volcast.session.connection.url) });
    const end = new Promise((resolve) => u.on("state", (s) => { if (s.state === "failed" || s.state === "opening") resolve(u.message || s.state); }));
    u.start();
    return end;
  });
  assert.match(message, /^The server needs a token to take uploads/, message);
});

// A 96³ NRRD of 885 kB: at 300 kB/s up it takes about 3 s, long enough to see the bar move.
function slowNrrd() {
  const header = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 96 96 96\nencoding: raw\n\n";
  const voxels = Buffer.alloc(96 * 96 * 96);
  for (let z = 0; z < 96; z++) for (let y = 0; y < 96; y++) for (let x = 0; x < 96; x++) {
    voxels[(z * 96 + y) * 96 + x] = Math.hypot(x - 47.5, y - 47.5, z - 47.5) < 36 ? 120 + ((x + y + z) % 64) : 0;
  }
  return Buffer.concat([Buffer.from(header, "latin1"), voxels]);
}

// Run fn with the page's uploads throttled to 300 kB/s (Chromium's network emulation).
async function throttled(fn) {
  const cdp = await page.context().newCDPSession(page);
  await cdp.send("Network.enable");
  await cdp.send("Network.emulateNetworkConditions", { offline: false, latency: 0, downloadThroughput: -1, uploadThroughput: 300000 });
  try { return await fn(); } finally {
    await cdp.send("Network.emulateNetworkConditions", { offline: false, latency: 0, downloadThroughput: -1, uploadThroughput: -1 });
    await cdp.detach();
  }
}

async function chooseSlowFile(name) {
  const [chooser] = await Promise.all([page.waitForEvent("filechooser"), page.click("#open-file")]);
  await chooser.setFiles({ name, mimeType: "application/octet-stream", buffer: slowNrrd() });
  await page.waitForFunction(() => {
    const u = window.volcast.opener.upload;
    return u?.state === "uploading" && u.fraction > 0.2 && u.fraction < 0.9;
  }, null, { timeout: 30000, polling: 50 });
}

test("on a slow connection the upload's progress shows over the view, then the volume opens", async () => {
  await throttled(async () => {
    await chooseSlowFile("slow.nrrd");
    assert.match(await page.textContent("#view-message-title"), /^Uploading slow\.nrrd$/);
    assert.match(await page.textContent("#view-message-detail"), /^\d+ kB of 885 kB · \d+ %$/);
    assert.equal(await page.textContent("#open-file"), "Cancel upload", "the button cancels the upload meanwhile");
    await page.evaluate(() => document.getElementById("errors").replaceChildren());   // earlier tests' banners, for a clean picture
    await screenshot(page, "open-file-progress.png");
    updateDocScreenshot("open-file-progress.png", "open-file-progress.png");
  });
  const u = await waitForUploadEnd();
  assert.equal(u.state, "opened", u.message);
  assert.equal(await page.textContent("#open-file"), "Open file…");
});

test("'Cancel upload' stops an upload on its way; the open volume stays", async () => {
  const before = await page.evaluate(() => window.volcast.session.volume?.name);
  await throttled(async () => {
    await chooseSlowFile("cancelled.nrrd");
    await page.click("#open-file");
    const u = await waitForUploadEnd();
    assert.equal(u.state, "cancelled");
  });
  assert.ok((await bannerTexts()).some((t) => t === "upload: The upload of cancelled.nrrd was cancelled"), await bannerTexts());
  assert.equal(await page.textContent("#open-file"), "Open file…");
  assert.equal(await page.evaluate(() => window.volcast.session.volume?.name), before);
  assert.ok(await page.isHidden("#view-message") || !/Uploading/.test(await page.textContent("#view-message-title")), "no upload message left over the view");
});

test("a file the server does not open is refused before any upload", async () => {
  const sent = uploads.length;
  await dropFile("notes.txt", Buffer.from("hello"));
  const u = await uploadState();
  assert.equal(u.state, "failed");
  assert.match(u.message, /notes\.txt: not a file the server opens/);
  assert.equal(uploads.length, sent, "no request went");
});

test("no page errors", () => {
  assert.deepEqual(problems.filter((p) => !/Failed to load resource: the server responded with a status of (401|404|413|422)/.test(p)), []);
});
