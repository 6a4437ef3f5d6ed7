// The set-up every browser suite shares: check the prerequisites, start a volcast-server on
// a free port and headless chromium, open the client page, wait for its first volume (and
// frame); afterwards close both. Registers node:test's before and after hooks, so a suite
// calls it once at the top:
//
//   let page, problems;
//   const setup = pageUnderTest({ finalFrame: true, ready: (s) => ({ page, problems } = s) });
//
// setup.server may be replaced (a test that restarts the server): after() stops the one there.
import { after, before } from "node:test";

import { ARTIFACTS, checkPrerequisites, launchBrowser, openPage, startServer, waitForFinal } from "./harness.mjs";

// options:
//   serverOptions() startServer's options, asked for once setUp() has run (extra --data folders)
//   volume          the volume to wait for once the page is open (null: do not wait)
//   finalFrame      also wait for its first final frame
//   setUp()         before the server starts (write a data folder); tearDown() after it stops
//   ready(setup)    once the page is ready, with {server, browser, page, problems}
//   query           the page address's query string ("?token=T"), for a server run with --token
export function pageUnderTest({ serverOptions = () => ({}), volume = "builtin:demo", finalFrame = false,
  setUp = () => {}, tearDown = () => {}, ready = () => {}, timeout = 240000, query = "" } = {}) {
  const missing = checkPrerequisites();
  if (missing.length) throw new Error(`cannot run the browser tests:\n  ${missing.join("\n  ")}`);
  const t = { server: null, browser: null, page: null, problems: null };
  before(async () => {
    await setUp();
    t.server = await startServer(0, serverOptions());
    t.browser = await launchBrowser();
    ({ page: t.page, problems: t.problems } = await openPage(t.browser.context, `${t.server.url}${query}`));
    if (volume) await t.page.waitForFunction((n) => window.volcast.session.volume?.name === n, volume, { timeout: 60000 });
    if (finalFrame) await waitForFinal(t.page);
    ready(t);
  }, { timeout });
  after(async () => {
    await t.browser?.close();
    await t.server?.stop();
    await tearDown();
    console.log(`artifacts in ${ARTIFACTS}`);
  });
  return t;
}
