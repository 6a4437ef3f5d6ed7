// Refinement at rest in the page, against a real volcast-server that does it (the other suites
// turn it off): after the view's final frame, passes at rest of the same view follow; the stats
// say which pass is shown, and the error chart's series goes on past the final frame, falling.
import { test } from "node:test";
import assert from "node:assert/strict";

import { pageUnderTest } from "./page_setup.mjs";

let page;
pageUnderTest({ serverOptions: () => ({ restRefinement: true }), ready: (s) => ({ page } = s) });

test("passes at rest follow the final frame: labelled, estimated, and the error chart goes on falling", async () => {
  const handle = await page.waitForFunction(() => {
    const h = window.volcast.shown;
    return h && h.rest_pass > 0 ? h : null;
  }, null, { timeout: 120000, polling: 50 });
  const rest = await handle.jsonValue();
  assert.equal(rest.final, false, "a pass at rest is not the final level's frame");
  assert.equal(rest.codec, "png");
  assert.equal(rest.error?.method, "rmse_vs_previous_pass_over_3");
  await page.waitForTimeout(400);   // the overlay refreshes every 250 ms
  assert.match(await page.textContent("#stat-level"), new RegExp(`· at rest, pass ${rest.rest_pass} · step ${rest.quality.step} `));
  // The chart's series: this view's frames with an estimate, the pass among them, drawn as a
  // final-quality point; any final-quality points before it (the final frame once calibrated,
  // earlier passes) had higher estimates.
  const points = await page.evaluate(() => window.volcast.session.stats.series.points.map((p) => ({ value: p.value, final: p.final })));
  assert.ok(points.length >= 1, "the pass is in the error chart's series");
  assert.ok(points.at(-1).final, "the pass is drawn as a final-quality point");
  assert.equal(points.at(-1).value, rest.error.value);
  for (const p of points.slice(0, -1).filter((p) => p.final))
    assert.ok(p.value >= rest.error.value, `the estimates do not fall: ${JSON.stringify(points)}`);
});
