// Measurement and crop-box geometry (web/core/measure.js) against closed forms, and the
// request builders of probe, roi_stats, pick and slice slabs (web/core/protocol.js).
// Tolerances are float rounding of a few operations on numbers below 1e3 (1e-9).
import assert from "node:assert/strict";
import { test } from "node:test";

import {
  FULL_CROP, MIN_CROP_GAP, cropCorners, cropGeometry, cropHandlesOnSlice, cropOnSlice, distanceMm, dragAlong,
  formatArea, formatMm, formatRoi, formatValue, movedCrop, paneFit, paneToPixel, paneToWorld, pixelToPane,
  projectToView, roiFromCorners, scrolledPoint, shapeArea, sliceNormal, spacingAlong,
} from "../../../web/core/measure.js";
import { requests } from "../../../web/core/protocol.js";

const EPS = 1e-9;
const close = (a, b, what) => assert.ok(Math.abs(a - b) < EPS, `${what}: ${a} vs ${b}`);
const closeVec = (a, b, what) => a.forEach((v, i) => close(v, b[i], `${what}[${i}]`));

// An axial slice (protocol/README.md: columns +x, rows +y) of 200 × 100 pixels, 0.5 mm apart.
const AXIAL = { width: 200, height: 100, pixel_spacing: 0.5, origin: [-50, -25, 7], column: [1, 0, 0], row: [0, 1, 0], point: [0, 0, 7] };

test("pane positions, slice pixels and world points are inverse", () => {
  const fit = paneFit(AXIAL, 400, 400);   // scale 2 (width-bound), 100 px bars above and below
  assert.deepEqual(fit, { scale: 2, x: 0, y: 100 });
  const px = paneToPixel(fit, 201, 201);
  assert.deepEqual(px, { c: 100, r: 50 });
  assert.deepEqual(pixelToPane(fit, px.c, px.r), { x: 201, y: 201 });
  closeVec(paneToWorld(AXIAL, fit, 201, 201), [0, 0, 7], "pixel (100, 50) is 50 mm along +x, 25 along +y from the origin");
  closeVec(sliceNormal(AXIAL), [0, 0, 1], "axial normal");
});

test("a distance dragged on a pane is its pixel distance times the pixel spacing", () => {
  const fit = paneFit(AXIAL, 400, 400);
  const a = paneToWorld(AXIAL, fit, 40, 150), b = paneToWorld(AXIAL, fit, 40 + 60, 150 + 80);
  // 100 CSS px = 50 slice pixels (scale 2) = 25 mm at 0.5 mm a pixel.
  close(distanceMm(a, b), (Math.hypot(60, 80) / fit.scale) * AXIAL.pixel_spacing, "distance");
  close(distanceMm(a, b), 25, "distance");
  assert.equal(formatMm(25), "25.0 mm");
  assert.equal(formatMm(3.14159), "3.14 mm");
});

test("an ROI from its corners: centre and radii along the pane's column and row", () => {
  const { center, radii } = roiFromCorners(AXIAL, [10, 20, 7], [4, 28, 7]);
  closeVec(center, [7, 24, 7], "centre");
  closeVec(radii, [3, 4], "radii");
  close(shapeArea("ellipse", radii), Math.PI * 12, "ellipse area");
  close(shapeArea("rectangle", radii), 48, "rectangle area");
  assert.equal(formatArea(Math.PI * 12), "37.7 mm²");
  assert.equal(formatArea(1234), "12.3 cm²");
});

test("values: HU as integers, other data 4 significant digits, empty ROI said", () => {
  assert.equal(formatValue(39.6, "HU"), "40 HU");
  assert.equal(formatValue(0.123456, null), "0.1235");
  assert.equal(formatValue(null, null), "–");
  assert.equal(formatRoi({ samples: 0, mean: null }), "no samples inside the volume");
  assert.equal(formatRoi({ samples: 9, mean: 100, std: 0, min: 100, max: 100, area_mm2: 50, unit: "HU" }),
    "mean 100 ± 0 HU · 50.0 mm² · min 100 max 100");
});

test("scrolling steps by the spacing of the index axis along the pane's normal, within the volume", () => {
  // Index axis 2 (spacing 3) lies along world x in this permuted volume.
  const volume = { dims: [4, 5, 6], spacing: [1, 2, 3], direction: [[0, 0, 1], [1, 0, 0], [0, 1, 0]] };
  assert.equal(spacingAlong(volume, [1, 0, 0]), 3);
  assert.equal(spacingAlong(volume, [0, 0, -1]), 2);
  assert.equal(spacingAlong({ spacing: [0.7, 0.8, 2.5] }, [0, 0, 1]), 2.5);
  closeVec(scrolledPoint([1, 2, 3], [0, 0, 1], 2, 2.5, 0, 100), [1, 2, 8], "two slices up");
  closeVec(scrolledPoint([1, 2, 3], [0, 0, 1], -5, 2.5, 0, 100), [1, 2, 0], "stops at the first slice");
});

// A 10 × 20 × 30 volume, spacing 1 × 2 × 3, origin 0: its cell box spans −½·s to (n − ½)·s.
const VOLUME = { dims: [10, 20, 30], spacing: [1, 2, 3], origin: [0, 0, 0] };

test("crop box corners: normalised box coordinates to world mm, with and without a flip", () => {
  const g = cropGeometry(VOLUME, null);
  closeVec(g.at([0, 0, 0]), [-0.5, -1, -1.5], "min corner");
  closeVec(g.at([1, 1, 1]), [9.5, 39, 88.5], "max corner");
  closeVec(g.center, [4.5, 19, 43.5], "centre");
  assert.deepEqual(g.extents, [10, 40, 90]);
  // A left/right flip about the centre: x → 2·4.5 − x, and +f along x points to −x.
  const flipped = cropGeometry(VOLUME, [[-1, 0, 0], [0, 1, 0], [0, 0, 1]]);
  closeVec(flipped.at([0, 0, 0]), [9.5, -1, -1.5], "flipped min corner");
  closeVec(flipped.axes[0], [-1, 0, 0], "flipped x axis");
  assert.equal(cropCorners(g, FULL_CROP).length, 8);
});

test("a face moves by the displacement along its axis over the extent, never past its opposite", () => {
  const g = cropGeometry(VOLUME, null);
  const crop = { min: [0, 0, 0], max: [1, 1, 1] };
  // 2.5 mm along +x on a 10 mm extent: the x-min face moves a quarter; y and z components are ignored.
  assert.deepEqual(movedCrop(g, crop, { axis: 0, side: "min" }, [2.5, 7, -3]), { min: [0.25, 0, 0], max: [1, 1, 1] });
  // 9 mm along −y on 40 mm: the y-max face moves 0.225 in.
  assert.deepEqual(movedCrop(g, crop, { axis: 1, side: "max" }, [0, -9, 0]), { min: [0, 0, 0], max: [1, 0.775, 1] });
  const tight = movedCrop(g, { min: [0, 0, 0.5], max: [1, 1, 1] }, { axis: 2, side: "min" }, [0, 0, 1000]);
  close(tight.min[2], 1 - MIN_CROP_GAP, "stops short of its opposite");
  assert.equal(movedCrop(g, crop, { axis: 0, side: "min" }, [-50, 0, 0]).min[0], 0, "stays inside the box");
});

test("the crop box on an axial slice: its rectangle and the four handles of the faces crossing it", () => {
  const g = cropGeometry(VOLUME, null);
  const crop = { min: [0.2, 0.25, 0], max: [0.8, 0.75, 1] };
  // Axial plane z = 40 (inside), 1 mm pixels, origin at world (−0.5, −1).
  const header = { width: 10, height: 40, pixel_spacing: 1, origin: [-0.5, -1, 40], column: [1, 0, 0], row: [0, 1, 0] };
  const poly = cropOnSlice(header, cropCorners(g, crop));
  assert.equal(poly.length, 4);
  // x from −0.5 + 0.2·10 = 1.5 to 7.5 → c 2 … 8; y from −1 + 0.25·40 = 9 to 29 → r 10 … 30.
  const cs = poly.map((p) => p.c).sort((a, b) => a - b), rs = poly.map((p) => p.r).sort((a, b) => a - b);
  closeVec([cs[0], cs[3], rs[0], rs[3]], [2, 8, 10, 30], "rectangle");
  const handles = cropHandlesOnSlice(header, g, crop);
  assert.deepEqual(handles.map((h) => `${h.axis}${h.side}`).sort(), ["0max", "0min", "1max", "1min"]);
  const xmin = handles.find((h) => h.axis === 0 && h.side === "min");
  closeVec([xmin.pixel.c, xmin.pixel.r], [2, 20], "x-min handle at the middle of its edge");
  assert.deepEqual(cropOnSlice({ ...header, origin: [-0.5, -1, 500] }, cropCorners(g, crop)), [], "a plane outside the box");
});

test("the 3D view: projection and a drag along an axis", () => {
  // Orthographic, looking down −z with +y up: 100 mm tall in 200 px, so 0.5 mm a pixel.
  const camera = { eye: [0, 0, 100], target: [0, 0, 0], up: [0, 1, 0], projection: "orthographic", height: 100 };
  assert.deepEqual(projectToView(camera, [0, 0, 0], 300, 200), { x: 150, y: 100 });
  closeVec(dragAlong(camera, [0, 0, 0], [1, 0, 0], 10, 0, 300, 200), [5, 0, 0], "10 px right = 5 mm along +x");
  closeVec(dragAlong(camera, [0, 0, 0], [0, 1, 0], 3, -8, 300, 200), [0, 4, 0], "8 px up = 4 mm along +y; x drag ignored");
  closeVec(dragAlong(camera, [0, 0, 0], [0, 0, 1], 10, 10, 300, 200), [0, 0, 0], "an axis towards the viewer does not move");
});

test("probe, roi_stats, pick and slab requests carry exactly the protocol's fields", () => {
  assert.deepEqual(requests.probe([1, 2, 3]), { type: "probe", point: [1, 2, 3] });
  assert.deepEqual(requests.roiStats("coronal", [1, 2, 3], [4, 5]),
    { type: "roi_stats", axis: "coronal", center: [1, 2, 3], radii: [4, 5], shape: "ellipse" });
  assert.deepEqual(requests.pick(10.5, 20.5, 640, 480), { type: "pick", x: 10.5, y: 20.5, width: 640, height: 480 });
  assert.deepEqual(requests.slice("axial", 8, 8, { slab: { thickness: 5, mode: "minip" } }),
    { type: "slice", axis: "axial", width: 8, height: 8, slab: { thickness: 5, mode: "minip" } });
  assert.deepEqual(requests.slice("axial", 8, 8, { slab: { thickness: 0, mode: "mip" } }),
    { type: "slice", axis: "axial", width: 8, height: 8 }, "thickness 0 is the plane: no slab sent");
});
