// core/view_link.js: a view survives the round trip through the address, and hostile
// fragments are refused whole, each with a reason.
import { test } from "node:test";
import assert from "node:assert/strict";

import { MAX_LINK_CHARS, MAX_POINTS, formatViewLink, parseViewLink } from "../../../web/core/view_link.js";

const view = {
  volume: "ct/head scan.nrrd",
  camera: { eye: [100.25, -400, 60], target: [100, 100, 60], up: [0, 0, 1], projection: "perspective", fov_y_deg: 30 },
  transfer_function: { points: [[-1000, 0, 0, 0, 0], [300, 0.95, 0.85, 0.7, 0.3], [3000, 1, 1, 1, 0.9]], opacity_unit: 2.5 },
};

test("a view comes back from its link exactly (numbers of up to 7 significant digits)", () => {
  const link = formatViewLink(view);
  assert.deepEqual(parseViewLink(`#${link}`), { view, error: null });
  const ortho = { volume: "builtin:demo", camera: { ...view.camera, projection: "orthographic", height: 240 }, transfer_function: { preset: "ct_bone" } };
  delete ortho.camera.fov_y_deg;
  assert.deepEqual(parseViewLink(formatViewLink(ortho)).view, ortho);
  // Rounding to 7 significant digits moves a coordinate by at most half a unit in the 7th digit: 5e-7 of itself.
  const odd = { camera: { ...view.camera, eye: [1 / 3, 2 / 3, 1e-9] } };
  const back = parseViewLink(formatViewLink(odd)).view.camera.eye;
  back.forEach((x, i) => assert.ok(Math.abs(x - odd.camera.eye[i]) <= 5e-7 * Math.abs(odd.camera.eye[i])));
});

test("no fragment is no view and no error", () => {
  assert.deepEqual(parseViewLink(""), { view: null, error: null });
  assert.deepEqual(parseViewLink("#"), { view: null, error: null });
});

test("hostile or broken links are refused whole, saying why", () => {
  const good = new URLSearchParams(formatViewLink(view));
  const withParam = (k, v) => { const p = new URLSearchParams(good); p.set(k, v); return p.toString(); };
  const cases = [
    ["x".repeat(MAX_LINK_CHARS + 1), /longer than/],
    [withParam("volume", "../../etc/passwd"), /relative to the server's data folders/],
    [withParam("volume", "/etc/passwd"), /relative/],
    [withParam("volume", "a\u0000b"), /control characters/],
    [withParam("volume", "v".repeat(1025)), /1 to 1024/],
    [withParam("eye", "1,2"), /eye: needs 3 numbers/],
    [withParam("eye", "1,2,Infinity"), /not a number/],
    [withParam("eye", "1,2,0x10"), /not a number/],
    [withParam("eye", "1,2,"), /not a number/],
    [withParam("eye", "1,2,1e300"), /out of range/],
    [withParam("up", "0,0,0"), /up is zero/],
    [withParam("eye", "100,100,60"), /same point/],
    [withParam("fov", "180"), /fov/],
    [`${good}&height=3`, /either fov .* or height/],
    [withParam("tf", "preset:<script>"), /preset name/],
    [withParam("tf", "0,0,0,0,0"), /2 to 64 points/],
    [withParam("tf", Array.from({ length: MAX_POINTS + 1 }, (_, i) => `${i},0,0,0,0`).join(";")), /2 to 64 points/],
    [withParam("tf", "0,0,0,0,0;1,2,0,0,0"), /\[0, 1\]/],
    [withParam("tf", "1,0,0,0,0;1,0,0,0,0"), /values must increase/],
    [withParam("opacity_unit", "-1"), /positive/],
    [`${good}&volume=other`, /volume given twice/],
    ["constructor=1&__proto__=2", /names no volume/],
  ];
  for (const [fragment, why] of cases) {
    const r = parseViewLink(fragment);
    assert.equal(r.view, null, `refused: ${fragment.slice(0, 80)}`);
    assert.match(r.error, why, `${fragment.slice(0, 80)} → ${r.error}`);
  }
});

test("a DICOMweb or uploaded volume's name survives the link: its ':' and '/' come back as they were", () => {
  for (const volume of ["dicomweb:my-pacs/1.2.840.113619.2.55.3/1.2.840.113619.2.55.3.604", "upload:0123456789abcdef0123456789abcdef"]) {
    const link = formatViewLink({ ...view, volume });
    assert.ok(!/[:/]/.test(new URLSearchParams(link).toString().split("&")[0].slice("volume=".length)),
      `the name is percent-encoded in the fragment: ${link.slice(0, 60)}`);
    assert.deepEqual(parseViewLink(`#${link}`), { view: { ...view, volume }, error: null });
    // Typed or pasted by hand, unencoded, it means the same.
    assert.equal(parseViewLink(`#volume=${volume}`).view.volume, volume);
  }
});
