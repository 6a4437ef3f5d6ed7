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

test("a view comes back from its link exactly, every number to the last bit", () => {
  const link = formatViewLink(view);
  assert.deepEqual(parseViewLink(`#${link}`), { view, error: null });
  const ortho = { volume: "builtin:demo", camera: { ...view.camera, projection: "orthographic", height: 240 }, transfer_function: { preset: "ct_bone" } };
  delete ortho.camera.fov_y_deg;
  assert.deepEqual(parseViewLink(formatViewLink(ortho)).view, ortho);
  // Numbers no short decimal holds come back as the same doubles (the same rays, the same pixels).
  const odd = { camera: { ...view.camera, eye: [1 / 3, 2 / 3 + 1e-12, 1e-9], fov_y_deg: Math.PI * 10 } };
  assert.deepEqual(parseViewLink(formatViewLink(odd)).view.camera, odd.camera);
});

// The rest of the view: everything that decides what the reader sees.
const full = {
  ...view,
  orientation: { correction: [[0, -1, 0], [-1, 0, 0], [0, 0, 1]], setByHand: true },
  crop: { min: [0, 0.125, 0.2], max: [1, 0.875, 0.55] },
  clip_planes: [{ point: [10.5, -20, 30], normal: [0, 0, -1] }, { point: [0, 0, 0], normal: [0.6, 0.8, 0] }],
  compositing: "mip",
  projection_window: { window: 400, level: 40 },
  slice_window: { window: 2000, level: -600.5 },
  crosshair: [1.5, -3.25, 40],
  slab: { thickness: 12.5, mode: "minip" },
};

test("the whole view comes back from its link: orientation, crop, clip planes, compositing, windows, crosshair, slab", () => {
  const link = formatViewLink(full);
  assert.deepEqual(parseViewLink(`#${link}`), { view: full, error: null });
  assert.ok(link.length < MAX_LINK_CHARS);
  // "Treat as LPS": no correction, the axes set by hand; the identity is not written.
  const lps = { volume: "a.nrrd", orientation: { correction: [[1, 0, 0], [0, 1, 0], [0, 0, 1]], setByHand: true } };
  assert.equal(formatViewLink(lps), "volume=a.nrrd&axes=hand");
  assert.deepEqual(parseViewLink(formatViewLink(lps)).view, lps);
  // A flip of a file that names its axes: a correction, not set by hand.
  const flip = { volume: "a.nrrd", orientation: { correction: [[-1, 0, 0], [0, 1, 0], [0, 0, 1]], setByHand: false } };
  assert.deepEqual(parseViewLink(formatViewLink(flip)).view, flip);
  // No correction and nothing set by hand is no orientation key at all: the page resets it.
  assert.equal(formatViewLink({ volume: "a.nrrd", orientation: { correction: lps.orientation.correction, setByHand: false } }), "volume=a.nrrd");
  // A slab of 0 mm (the plane itself) and emission–absorption are carried as chosen.
  const plain = { volume: "a.nrrd", compositing: "emission_absorption", slab: { thickness: 0, mode: "mean" } };
  assert.deepEqual(parseViewLink(formatViewLink(plain)).view, plain);
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
    ["constructor=1&__proto__=2", /unknown key "constructor"/],
    [withParam("orientation", "1,0,0,0,1,0,0,0"), /orientation: needs 9 numbers/],
    [withParam("orientation", "1,0,0,0,2,0,0,0,1"), /-1, 0 or 1/],
    [withParam("orientation", "1,0,0,1,0,0,0,0,1"), /column 1 must have one non-zero/],
    [withParam("orientation", "1,1,0,0,0,0,0,0,1"), /row 1 must have one non-zero/],
    [withParam("orientation", "0.5,0,0,0,1,0,0,0,1"), /-1, 0 or 1/],
    [withParam("axes", "lps"), /axes: the only value is "hand"/],
    [withParam("crop", "0,0,0,1,1"), /crop: needs 6 numbers/],
    [withParam("crop", "0,0,-0.1,1,1,1"), /\[0, 1\]/],
    [withParam("crop", "0,0,0.5,1,1,0.5"), /min must be below its max/],
    [withParam("crop", "0,0,NaN,1,1,1"), /not a number/],
    [withParam("clip", "0,0,0,0,0,0"), /normal is zero/],
    [withParam("clip", "0,0,0,0,0"), /needs 6 numbers/],
    [withParam("clip", Array.from({ length: 7 }, () => "0,0,0,0,0,1").join(";")), /at most 6 planes/],
    [withParam("compositing", "xray"), /compositing: must be one of/],
    [withParam("compositing", ""), /compositing: must be one of/],
    [withParam("projection_window", "0,40"), /window must be positive/],
    [withParam("projection_window", "-400,40"), /window must be positive/],
    [withParam("slice_window", "400"), /needs 2 numbers/],
    [withParam("slice_window", "400,1e13"), /out of range/],
    [withParam("crosshair", "1,2"), /crosshair: needs 3 numbers/],
    [withParam("crosshair", "1,2,Infinity"), /not a number/],
    [withParam("slab", "10"), /thickness and a mode/],
    [withParam("slab", "-1,mip"), /thickness must be 0 to/],
    [withParam("slab", "20000,mip"), /thickness must be 0 to/],
    [withParam("slab", "10,max"), /mode must be one of mip, minip, mean/],
    [withParam("slab", "10,mip,1"), /thickness and a mode/],
    [`${formatViewLink(full)}&crop=0,0,0,1,1,1`, /crop given twice/],
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
