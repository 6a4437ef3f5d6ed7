// What the browser tests share: a real volcast-server on a free port, headless Debian
// chromium driven by playwright-core, and helpers that read the page's state.
//
// Environment (CTest sets these; see tests/web/CMakeLists.txt):
//   VOLCAST_SERVER_EXE   volcast-server            (default: build/server/volcast-server)
//   VOLCAST_RENDER_EXE   volcast-render            (default: build/renderer/volcast-render)
//   VOLCAST_WEB_ARTIFACTS folder for screenshots, downloads and server logs
//                        (default: build/tests/web/artifacts)
//   VOLCAST_DATA_DIR     the real scans (optional: the tests use builtin:demo)
//   CHROMIUM             the browser (default: /usr/bin/chromium)
//   VOLCAST_LOG_LEVEL    the servers' --log-level (default: info), e.g. debug to follow a failure

import { spawn } from "node:child_process";
import { copyFileSync, existsSync, mkdirSync, mkdtempSync, readFileSync, rmSync, createWriteStream } from "node:fs";
import { createRequire } from "node:module";
import { createServer } from "node:net";
import os from "node:os";
import path from "node:path";
import { fileURLToPath } from "node:url";

export const REPO = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../../..");
export const SERVER_EXE = process.env.VOLCAST_SERVER_EXE || path.join(REPO, "build/server/volcast-server");
export const RENDER_EXE = process.env.VOLCAST_RENDER_EXE || path.join(REPO, "build/renderer/volcast-render");
export const ARTIFACTS = process.env.VOLCAST_WEB_ARTIFACTS || path.join(REPO, "build/tests/web/artifacts");
export const DATA_DIR = process.env.VOLCAST_DATA_DIR || "";
export const CHROMIUM = process.env.CHROMIUM || "/usr/bin/chromium";

export const READY_TIMEOUT_MS = 120000;   // ms for /readyz: the demo volume loads and kernels build
export const FRAME_TIMEOUT_MS = 90000;    // ms for a final frame on a 2-core CPU device (~2 s typical)
export const VIEWPORT = { width: 1100, height: 680 };   // CSS px of the browser window

// Flags that work as root in a container (docs/platform.md).
const CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
  "--disable-background-networking", "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage"];

export function checkPrerequisites() {
  const missing = [];
  if (!existsSync(SERVER_EXE)) missing.push(`volcast-server not found at ${SERVER_EXE} (build target volcast-server, or set VOLCAST_SERVER_EXE)`);
  if (!existsSync(CHROMIUM)) missing.push(`chromium not found at ${CHROMIUM} (apt-get install chromium, or set CHROMIUM)`);
  return missing;
}

// The suite running (its test file's name, "rough_edges" for rough_edges.test.mjs): the logs of
// the servers it starts carry it, so that the next suite's do not overwrite them.
export const SUITE = path.basename(process.argv[1] ?? "suite", ".test.mjs");

export function artifact(name) {
  mkdirSync(ARTIFACTS, { recursive: true });
  return path.join(ARTIFACTS, name);
}

// playwright-core from tests/web/node_modules (npm ci --prefix tests/web).
export async function loadPlaywright() {
  const require = createRequire(path.join(REPO, "tests/web/package.json"));
  let entry;
  try {
    entry = require.resolve("playwright-core");
  } catch {
    throw new Error("playwright-core is not installed: run `npm ci --prefix tests/web` (CTest's web.npm_ci fixture does)");
  }
  return require(entry);
}

export function freePort() {
  return new Promise((resolve, reject) => {
    const s = createServer();
    s.once("error", reject);
    s.listen(0, "127.0.0.1", () => { const { port } = s.address(); s.close(() => resolve(port)); });
  });
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// Start volcast-server on `port` (0: a free one) and wait until /readyz answers 200.
// extraArgs: more command-line arguments (another --data folder). The suites check the final
// frame as the page shows it, so refinement at rest, whose passes would follow it, is off
// unless a test asks for it (restRefinement: true).
let serverRuns = 0;
export async function startServer(port = 0, { extraArgs = [], restRefinement = false } = {}) {
  const dir = mkdtempSync(path.join(os.tmpdir(), "volcast-web-test-"));
  const portFile = path.join(dir, "port");
  const args = ["--port", String(port), "--port-file", portFile, "--web-root", path.join(REPO, "web"), "--log-level", process.env.VOLCAST_LOG_LEVEL || "info"];
  if (!restRefinement) args.push("--rest-refinement-s", "0");
  if (DATA_DIR && existsSync(DATA_DIR)) args.push("--data", DATA_DIR);
  args.push(...extraArgs);
  const log = createWriteStream(artifact(`${SUITE}-server-${++serverRuns}.log`));
  const proc = spawn(SERVER_EXE, args, { stdio: ["ignore", "pipe", "pipe"] });
  proc.stdout.pipe(log);
  proc.stderr.pipe(log);
  const exited = new Promise((resolve) => proc.once("exit", (code, signal) => resolve({ code, signal })));
  let exitedEarly = null;
  exited.then((e) => { exitedEarly = e; });

  const deadline = Date.now() + READY_TIMEOUT_MS;
  let bound = 0;
  while (Date.now() < deadline) {
    if (exitedEarly) throw new Error(`volcast-server exited (${JSON.stringify(exitedEarly)}); log: ${log.path}`);
    if (!bound && existsSync(portFile)) bound = Number(readFileSync(portFile, "utf8").trim()) || 0;
    if (bound) {
      try {
        const r = await fetch(`http://127.0.0.1:${bound}/readyz`);
        if (r.status === 200) break;
      } catch { /* not listening yet */ }
    }
    await sleep(100);
  }
  if (!bound) throw new Error(`volcast-server did not bind within ${READY_TIMEOUT_MS} ms; log: ${log.path}`);
  rmSync(dir, { recursive: true, force: true });
  return {
    port: bound,
    url: `http://127.0.0.1:${bound}/`,
    proc,
    logPath: log.path,
    async stop() {
      if (exitedEarly) return exitedEarly;
      proc.kill("SIGTERM");
      const timer = setTimeout(() => proc.kill("SIGKILL"), 15000);
      const e = await exited;
      clearTimeout(timer);
      return e;
    },
  };
}

export async function launchBrowser({ deviceScaleFactor = 1 } = {}) {
  const { chromium } = await loadPlaywright();
  const profile = mkdtempSync(path.join(os.tmpdir(), "volcast-chromium-"));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: CHROMIUM, headless: true, args: CHROMIUM_ARGS, viewport: VIEWPORT, deviceScaleFactor,
    acceptDownloads: true,
  });
  return {
    context,
    async close() { await context.close(); rmSync(profile, { recursive: true, force: true }); },
  };
}

// A page with its console errors and uncaught exceptions collected, and a record of every
// message the client sends and every connection state it passes through.
export async function openPage(context, url) {
  const page = await context.newPage();
  const problems = [];
  page.on("pageerror", (e) => problems.push(`pageerror: ${e.message}`));
  page.on("console", (m) => { if (m.type() === "error" && !/favicon/.test(m.text())) problems.push(`console: ${m.text()}`); });
  await page.goto(url);
  await page.waitForFunction(() => window.volcast?.session);
  await page.evaluate(() => {
    const c = window.volcast.session.connection;
    window.sentLog = [];
    window.stateLog = [];
    c.on("sent", ({ message }) => window.sentLog.push({ type: message.type, id: message.id }));
    c.on("state", (s) => window.stateLog.push(s.state));
  });
  return { page, problems };
}

export const connectionState = (page) => page.$eval("#connection", (el) => el.dataset.state);

// Wait until the view shows a final frame newer than `afterSeq` (and, if given, one that
// answers request id `request` or a later one). Returns its header.
export async function waitForFinal(page, { afterSeq = 0, minRequest = null, timeout = FRAME_TIMEOUT_MS } = {}) {
  const handle = await page.waitForFunction(({ afterSeq, minRequest }) => {
    const h = window.volcast.shown;
    if (!h || !h.final || h.seq <= afterSeq) return null;
    if (minRequest !== null && !(typeof h.request === "number" && h.request >= minRequest)) return null;
    return h;
  }, { afterSeq, minRequest }, { timeout, polling: 50 });
  return handle.jsonValue();
}

export const shownSeq = (page) => page.evaluate(() => window.volcast.shown?.seq ?? 0);

// The view canvas, reduced to what the tests compare: the fraction of pixels brighter
// than black, the mean colour, and a coarse thumbnail.
export function canvasSummary(page) {
  return page.evaluate(() => {
    const c = document.getElementById("view-canvas");
    const { data } = c.getContext("2d").getImageData(0, 0, c.width, c.height);
    let lit = 0;
    const mean = [0, 0, 0];
    const n = c.width * c.height;
    for (let i = 0; i < data.length; i += 4) {
      if (data[i] + data[i + 1] + data[i + 2] > 24) lit++;
      mean[0] += data[i]; mean[1] += data[i + 1]; mean[2] += data[i + 2];
    }
    // 32 × 32 thumbnail of luminance-ish values, for image-to-image comparisons.
    const thumb = [];
    for (let ty = 0; ty < 32; ty++) for (let tx = 0; tx < 32; tx++) {
      const x = Math.floor(((tx + 0.5) / 32) * c.width), y = Math.floor(((ty + 0.5) / 32) * c.height);
      const i = (y * c.width + x) * 4;
      thumb.push([data[i], data[i + 1], data[i + 2]]);
    }
    return { width: c.width, height: c.height, litFraction: lit / n, mean: mean.map((m) => m / n), thumb };
  });
}

// Mean absolute difference (0…255) between two thumbnails.
export function thumbDifference(a, b) {
  let sum = 0;
  for (let i = 0; i < a.length; i++) for (let k = 0; k < 3; k++) sum += Math.abs(a[i][k] - b[i][k]);
  return sum / (a.length * 3);
}

// The thumbnail mirrored left-right (32 × 32, row-major).
export const mirrored = (thumb) => thumb.map((_, i) => thumb[Math.floor(i / 32) * 32 + (31 - (i % 32))]);

// The view canvas's pixels, kept in the page as window[name].
export const keepCanvas = (page, name) => page.evaluate((name) => {
  const c = document.getElementById("view-canvas");
  window[name] = { width: c.width, height: c.height, data: c.getContext("2d").getImageData(0, 0, c.width, c.height).data };
}, name);

// How many pixels of kept canvas b differ from kept canvas a (mirrored left-right when
// `mirror`) by more than 16 levels in some channel, at full resolution; −1 when their
// sizes differ.
export const pixelsDiffering = (page, a, b, mirror) => page.evaluate(({ a, b, mirror }) => {
  const A = window[a], B = window[b];
  if (A.width !== B.width || A.height !== B.height) return -1;
  let n = 0;
  for (let y = 0; y < A.height; y++)
    for (let x = 0; x < A.width; x++) {
      const i = (y * A.width + x) * 4, j = (y * A.width + (mirror ? A.width - 1 - x : x)) * 4;
      if (Math.abs(B.data[i] - A.data[j]) > 16 || Math.abs(B.data[i + 1] - A.data[j + 1]) > 16 ||
          Math.abs(B.data[i + 2] - A.data[j + 2]) > 16) n++;
    }
  return n;
}, { a, b, mirror });

// The pictures the READMEs show live with the other pages' pictures (docs/images/README.md),
// outside web/, which the server serves.
export const DOC_SCREENSHOTS = path.join(REPO, "docs/images/web");

// With VOLCAST_UPDATE_DOC_SCREENSHOTS=1 an artifact web/README.md shows is copied over its
// file in docs/images/web/ (reviewed in the diff like any change).
export function updateDocScreenshot(artifactName, docName) {
  if (!process.env.VOLCAST_UPDATE_DOC_SCREENSHOTS) return;
  mkdirSync(DOC_SCREENSHOTS, { recursive: true });
  copyFileSync(artifact(artifactName), path.join(DOC_SCREENSHOTS, docName));
}

export async function screenshot(page, name) {
  await page.screenshot({ path: artifact(name) });
}

// Click `selector` and save the download it starts into the artifacts folder.
export async function download(page, selector, name) {
  const [dl] = await Promise.all([page.waitForEvent("download"), page.click(selector)]);
  const target = artifact(name);
  await dl.saveAs(target);
  return target;
}

export function run(exe, args, options = {}) {
  return new Promise((resolve) => {
    const p = spawn(exe, args, { ...options, stdio: ["ignore", "pipe", "pipe"] });
    let out = "", err = "";
    p.stdout.on("data", (d) => { out += d; });
    p.stderr.on("data", (d) => { err += d; });
    p.on("exit", (code) => resolve({ code, out, err }));
  });
}
