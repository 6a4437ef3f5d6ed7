// Search → open against a real PACS, in headless Chromium: the test starts Orthanc with its
// DICOMweb plugin on loopback (tests/web/lib/orthanc.mjs), stores a small CT series it
// writes itself (tests/web/lib/dicom.mjs), and starts volcast-server with
// --dicomweb pacs=<Orthanc's DICOMweb root>. The studies panel appears with the source;
// a search by the start of the patient's name finds the study, which expands to its
// series; a click retrieves and opens it, with progress, and a frame is drawn; the view
// link reopens it in a new page; a search by the start of the name (`doe` → `doe*`) finds it; a search that matches nothing says so; a bad date is
// refused in the panel before any request; with Orthanc stopped, opening a series not
// retrieved yet and a search say the archive did not answer, in the panel, and the page
// carries on. The patient's name is shown and
// never written to the browser's console.
// Saves studies.png (the panel, the study open, its series drawn) in the artifacts, and
// with VOLCAST_UPDATE_DOC_SCREENSHOTS=1 over docs/images/web/studies.png.
import { test } from "node:test";
import assert from "node:assert/strict";

import { SERVER_EXE, canvasSummary, openPage, run, screenshot, shownSeq, updateDocScreenshot, waitForFinal } from "./harness.mjs";
import { pageUnderTest } from "./page_setup.mjs";
import { ctSeries } from "../lib/dicom.mjs";
import { orthancMissing, startOrthanc } from "../lib/orthanc.mjs";

const PATIENT = "DOE^JANE";
const SIDE = 48, SLICES = 32;   // a 48 × 48 × 32 series, 1 × 1 × 1.5 mm voxels: 147 kB
// A hollow ball of bone (1000 HU) round soft tissue (60 HU) in air (−1000 HU), so CT bone shows a shell.
const ball = (x, y, z) => {
  const r = Math.hypot(x - 23.5, y - 23.5, (z - 15.5) * 1.5);
  return r < 14 ? 60 : r < 19 ? 1000 : -1000;
};

let orthanc, series;
let page, problems;
const consoleText = [];

pageUnderTest({
  async setUp() {
    const missing = orthancMissing();
    const help = await run(SERVER_EXE, ["--help"]);
    if (!/--dicomweb/.test(help.out + help.err)) missing.push(`${SERVER_EXE} has no --dicomweb option yet`);
    if (missing.length) throw new Error(`cannot run the studies test:\n  ${missing.join("\n  ")}`);
    orthanc = await startOrthanc();
    series = ctSeries({ patientName: PATIENT, patientId: "VOLCAST-0001", studyDate: "20240131",
      studyDescription: "Synthetic head", seriesDescription: "Axial ball", columns: SIDE, rows: SIDE, slices: SLICES,
      spacing: [1, 1, 1.5], voxel: ball });
    await orthanc.store(series.files);
    // A second patient's study, never opened: retrieving it once the archive is down must fail.
    await orthanc.store(ctSeries({ patientName: "ROE^RICHARD", patientId: "VOLCAST-0002", studyDate: "20231105",
      studyDescription: "Second study", seriesDescription: "Never opened", slices: 4 }).files);
  },
  serverOptions: () => ({ extraArgs: ["--dicomweb", `pacs=${orthanc.dicomWeb}`] }),
  tearDown: async () => { await orthanc?.stop(); },
  ready: (s) => {
    ({ page, problems } = s);
    page.on("console", (m) => consoleText.push(m.text()));
  },
});

const volumeName = () => `dicomweb:pacs/${series.studyUid}/${series.seriesUid}`;

// Waits (up to 120 s) until page `p` shows the series, or its panel reports an error. Either
// way short of the series shown fails saying what the page knew: the panel's progress line,
// the progress messages, the connection's state and what is open instead.
async function waitForSeriesOpen(p) {
  await p.waitForFunction((n) => window.volcast.session.volume?.name === n ||
      document.querySelector("#study-open-status[data-kind='error']") !== null,
    volumeName(), { timeout: 120000 }).catch(() => {});   // the assertion below says why
  const state = await p.evaluate(() => ({
    open: window.volcast.session.volume?.name ?? null,
    panel: document.getElementById("study-open-status")?.textContent ?? null,
    connection: document.getElementById("connection")?.dataset.state ?? null,
    progress: window.progressLog ?? null,
  }));
  assert.equal(state.open, volumeName(), `the series did not open within 120 s: ${JSON.stringify(state)}`);
}

async function search({ name = "", id = "", date = "", modality = "" } = {}) {
  await page.fill("#study-patient-name", name);
  await page.fill("#study-patient-id", id);
  await page.fill("#study-date", date);
  await page.selectOption("#study-modality", modality);
  await page.click("#study-search-button");
  await page.waitForFunction(() => !document.getElementById("study-search-button").disabled, null, { timeout: 60000 });
  return page.textContent("#study-status");
}

test("the panel shows the server's DICOMweb source", async () => {
  await page.waitForSelector("#studies-card:not([hidden])", { timeout: 30000 });
  assert.deepEqual(await page.$$eval("#study-source option", (o) => o.map((x) => x.value)), ["pacs"]);
});

// The page log of progress messages and of what the panel's progress line says.
async function watchOpening() {
  await page.evaluate(() => {
    window.progressLog = [];
    window.volcast.session.on("progress", (p) => window.progressLog.push({ stage: p.stage, instances: p.instances ?? null, bytes: p.bytes ?? null, fraction: p.fraction }));
    window.openTexts = [];
    new MutationObserver(() => window.openTexts.push(document.querySelector("#study-open-status .text").textContent))
      .observe(document.getElementById("study-open-status"), { subtree: true, childList: true, characterData: true });
  });
}

// The one study found, as the list shows it, unfolded; returns its series buttons.
async function checkFoundStudy(status) {
  assert.equal(status, "1 study");
  const study = page.locator("#study-list .study").first();
  assert.equal(await study.locator(".patient").textContent(), "DOE, JANE");
  assert.equal(await study.locator(".date").textContent(), "2024-01-31");
  assert.equal(await study.locator(".pid").textContent(), "ID VOLCAST-0001");
  assert.equal(await study.locator(".line2 .desc").textContent(), "Synthetic head");
  assert.equal(await study.locator(".mods").textContent(), "CT");
  assert.ok(await study.locator(".series-list").isHidden(), "series stay folded until asked for");
  await study.locator(".study-head").click();
  const s = study.locator("button.series");
  assert.equal(await s.count(), 1);
  assert.equal(await s.getAttribute("data-volume"), volumeName());
  assert.deepEqual([await s.locator(".mod").textContent(), await s.locator(".desc").textContent(), await s.locator(".count").textContent()],
    ["CT", "Axial ball", `${SLICES} images`]);
}

test("a search by patient ID, date range and modality finds the study, which lists its series", async () => {
  await watchOpening();
  await checkFoundStudy(await search({ id: "VOLCAST-0001", date: "2024-01-01 – 2024-02-29", modality: "CT" }));
});

test("a click on the series retrieves it with progress, opens it, and draws a frame", async () => {
  const before = await shownSeq(page);
  await page.click("#study-list button.series");
  await waitForSeriesOpen(page);
  const frame = await waitForFinal(page, { afterSeq: before });
  assert.ok(frame.final);
  const summary = await canvasSummary(page);
  assert.ok(summary.litFraction > 0.005, `the ball is drawn: ${(summary.litFraction * 100).toFixed(2)} % of the view lit`);
  const log = await page.evaluate(() => window.progressLog);
  const retrieving = log.filter((p) => p.stage === "retrieving");
  assert.ok(retrieving.length > 0, `the server reported retrieval: ${JSON.stringify(log)}`);
  const last = retrieving.at(-1);
  if (last.instances) assert.equal(last.instances[1], SLICES, "the total is the series' images");
  const texts = await page.evaluate(() => window.openTexts);
  assert.ok(texts.some((t) => /^Retrieving (\d+ of \d+ )?images/.test(t)), `the panel said what it was retrieving: ${JSON.stringify(texts)}`);
  assert.ok(await page.isHidden("#study-open-status"), "the progress line goes once the series is open");
  assert.equal(await page.locator("#study-list button.series.current").count(), 1, "the open series is marked");
  await page.evaluate(() => document.getElementById("studies-card").scrollIntoView({ block: "start" }));
  await screenshot(page, "studies.png");
  updateDocScreenshot("studies.png", "studies.png");
});

test("the view link reopens the DICOMweb series in a new page", async () => {
  await page.click("#copy-link");
  const link = page.url();
  assert.match(new URL(link).hash, /volume=dicomweb%3Apacs%2F/, "the name is encoded in the fragment");
  assert.equal(new URL(link).searchParams.get("volume"), null, "a study's UIDs stay out of the query string (server logs)");
  const other = await openPage(page.context(), link);
  try {
    await waitForSeriesOpen(other.page);
    await waitForFinal(other.page);
    assert.deepEqual(other.problems, []);
  } finally {
    await other.page.close();
  }
});

test("a search by the start of the patient's name, in lower case, finds the study", async () => {
  await checkFoundStudy(await search({ name: "doe" }));
});

test("a search that matches nothing says so; a bad date is refused in the panel, before any request", async () => {
  assert.equal(await search({ name: "NOBODY" }), "No studies match.");
  assert.equal(await page.locator("#study-list .study").count(), 0);
  const sent = await page.evaluate(() => window.sentLog.filter((m) => m.type === "find_studies").length);
  await page.fill("#study-date", "2023-02-30");
  await page.click("#study-search-button");
  assert.match(await page.textContent("#study-status"), /study date: 2023-02-30 is not a date/);
  assert.equal(await page.getAttribute("#study-date", "aria-invalid"), "true");
  assert.equal(await page.evaluate(() => window.sentLog.filter((m) => m.type === "find_studies").length), sent);
});

test("with the archive down, opening a series not yet retrieved says so in the panel", async () => {
  assert.equal(await search({}), "2 studies");
  const second = page.locator("#study-list .study", { hasText: "ROE, RICHARD" });
  await second.locator(".study-head").click();
  await orthanc.stop();
  orthanc = null;
  await second.locator("button.series").click();
  await page.waitForSelector("#study-open-status[data-kind='error']", { timeout: 120000 });
  const said = await page.textContent("#study-open-status");
  // The words name the archive; the server's reason under them says it could not be reached.
  assert.match(said, /^(The image archive "pacs" did not answer as expected\.|The series from "pacs" could not be opened\.)/, said);
  assert.match(said, /unreachable|connect/i, said);
  assert.equal((said.match(/could not be opened|did not answer/g) ?? []).length, 1, `said once: ${said}`);
  assert.equal(await page.evaluate(() => window.volcast.session.volume?.name), volumeName(), "the open series stays open");
  assert.equal(await page.locator("#errors .error[data-request-type='open_volume']").count(), 0, "said in the panel, not over the view too");
  await page.evaluate(() => document.getElementById("studies-card").scrollIntoView({ block: "start" }));
  await screenshot(page, "studies-archive-down.png");
});

test("with the archive down a search says so in the panel, and the page carries on", async () => {
  await search({ name: "doe" });
  assert.equal(await page.getAttribute("#study-status", "data-kind"), "error");
  assert.equal(await page.getAttribute("#study-status", "data-code"), "source_failed");
  assert.match(await page.textContent("#study-status"), /The image archive "pacs" did not answer as expected\./);
  assert.equal(await page.$eval("#connection", (el) => el.dataset.state), "ready");
  // The volume already open still turns.
  const before = await shownSeq(page);
  await page.evaluate(() => window.volcast.session.setCamera({ ...window.volcast.session.scene.camera, fov_y_deg: 25 }));
  await waitForFinal(page, { afterSeq: before });
});

test("the patient's name never reached the browser's console; no page errors", () => {
  assert.ok(!consoleText.some((t) => /DOE|JANE/.test(t)), "no console line names the patient");
  assert.deepEqual(problems, []);
});
