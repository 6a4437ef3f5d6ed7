// Geometry of the measurements and the crop box, in world millimetres (docs/design.md's LPS
// world). Pure functions, no DOM, so that every number the page shows can be checked under
// Node against closed forms.
//
// A slice pane shows a slice image (protocol/README.md's slice header: pixel (c, r) shows
// origin + c·s·column + r·s·row) scaled to fit its canvas; a pane position (CSS px from the
// canvas's top left) maps to a slice pixel and so to a world point.

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const length = (a) => Math.hypot(a[0], a[1], a[2]);
const normalize = (a) => { const l = length(a) || 1; return [a[0] / l, a[1] / l, a[2] / l]; };
const IDENTITY = [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
const mulMat = (m, v) => [dot(m[0], v), dot(m[1], v), dot(m[2], v)];

export const vec3 = { sub, add, scale, dot, cross, length, normalize };

// --- slice panes -------------------------------------------------------------------------

// Pixel (fractional, centre-based) of a world point on a slice, and back.
export function pixelOf(header, p) {
  const d = sub(p, header.origin);
  return { c: dot(d, header.column) / header.pixel_spacing, r: dot(d, header.row) / header.pixel_spacing };
}
export function worldOf(header, c, r) {
  const s = header.pixel_spacing;
  return [0, 1, 2].map((i) => header.origin[i] + c * s * header.column[i] + r * s * header.row[i]);
}

// The slice image drawn centred at its own aspect in a canvas of width × height CSS px.
export function paneFit(header, width, height) {
  const s = Math.min(width / header.width, height / header.height);
  return { scale: s, x: (width - header.width * s) / 2, y: (height - header.height * s) / 2 };
}
// A canvas position (CSS px) → slice pixel (centre-based: pixel 0's centre is 0), and back.
export function paneToPixel(fit, x, y) {
  return { c: (x - fit.x) / fit.scale - 0.5, r: (y - fit.y) / fit.scale - 0.5 };
}
export function pixelToPane(fit, c, r) {
  return { x: fit.x + (c + 0.5) * fit.scale, y: fit.y + (r + 0.5) * fit.scale };
}
// A canvas position → world point on the slice.
export function paneToWorld(header, fit, x, y) {
  const { c, r } = paneToPixel(fit, x, y);
  return worldOf(header, c, r);
}

// The plane's normal: column × row (axial +z, coronal +y, sagittal −x… whatever the header
// says; only its line matters to the callers).
export const sliceNormal = (header) => normalize(cross(header.column, header.row));

// --- the 3D view ----------------------------------------------------------------------------

// A world point in the 3D view's CSS pixels, with docs/design.md's camera (image x along
// forward × up, y up, row 0 at the top); null behind the eye.
export function projectToView(camera, p, width, height) {
  const forward = normalize(sub(camera.target, camera.eye));
  const right = normalize(cross(forward, camera.up));
  const up = cross(right, forward);
  const v = sub(p, camera.eye);
  const z = dot(v, forward);
  let halfH;
  if (camera.projection === "orthographic") {
    halfH = camera.height / 2;
  } else {
    if (z <= 0) return null;
    halfH = z * Math.tan((camera.fov_y_deg * Math.PI) / 360);
  }
  const halfW = halfH * (width / height);
  return { x: (dot(v, right) / halfW + 1) * width / 2, y: (1 - dot(v, up) / halfH) * height / 2 };
}

// A screen drag (dx, dy CSS px) of a handle at world point p that moves along the unit world
// direction `dir`: the world displacement along dir whose projection best follows the drag
// (least squares on the projection's derivative). Zero where dir points at the viewer.
export function dragAlong(camera, p, dir, dx, dy, width, height, h = 1) {
  const p0 = projectToView(camera, p, width, height), p1 = projectToView(camera, add(p, scale(dir, h)), width, height);
  if (!p0 || !p1) return [0, 0, 0];
  const jx = (p1.x - p0.x) / h, jy = (p1.y - p0.y) / h;
  const jj = jx * jx + jy * jy;
  if (jj < 1e-6) return [0, 0, 0];
  return scale(dir, (dx * jx + dy * jy) / jj);
}

// --- measurements --------------------------------------------------------------------------

export function distanceMm(a, b) { return length(sub(a, b)); }

// An ROI dragged on a slice from world point p0 to p1 (the bounding box's corners): centre
// and radii along the slice's column (a) and row (b) directions, as roi_stats takes them.
export function roiFromCorners(header, p0, p1) {
  const d = sub(p1, p0);
  return {
    center: scale(add(p0, p1), 0.5),
    radii: [Math.abs(dot(d, header.column)) / 2, Math.abs(dot(d, header.row)) / 2],
  };
}

export function shapeArea(shape, [a, b]) {
  return shape === "rectangle" ? 4 * a * b : Math.PI * a * b;
}

// Numbers for people: "12.3 mm", a value with its unit ("HU" or none), "mean ± SD".
export function formatMm(mm) {
  if (!Number.isFinite(mm)) return "–";
  return `${mm < 10 ? mm.toFixed(2) : mm.toFixed(1)} mm`;
}
export function formatArea(mm2) {
  if (!Number.isFinite(mm2)) return "–";
  return mm2 >= 100 ? `${(mm2 / 100).toPrecision(3)} cm²` : `${mm2.toPrecision(3)} mm²`;
}
// HU are integers to a radiologist; other data keeps 4 significant digits.
export function formatValue(v, unit) {
  if (v === null || v === undefined || !Number.isFinite(v)) return "–";
  if (unit === "HU") return `${Math.round(v)} HU`;
  return `${Number(v.toPrecision(4))}`;
}
export function formatRoi(stats) {
  if (!stats || !(stats.samples > 0)) return "no samples inside the volume";
  const u = stats.unit === "HU";
  const f = (v) => (u ? String(Math.round(v)) : String(Number(v.toPrecision(4))));
  return `mean ${f(stats.mean)} ± ${f(stats.std)}${u ? " HU" : ""} · ${formatArea(stats.area_mm2)} · min ${f(stats.min)} max ${f(stats.max)}`;
}

// --- scrolling through slices --------------------------------------------------------------

// The voxel spacing along a world direction: the spacing of the index axis the direction
// lies along most (what one "slice" is to the user for that pane).
export function spacingAlong(volume, dir) {
  const s = volume?.spacing ?? [1, 1, 1];
  const D = volume?.direction ?? IDENTITY;
  let best = 0, bestK = 0;
  for (let k = 0; k < 3; k++) {
    const col = [D[0][k], D[1][k], D[2][k]];
    const v = Math.abs(dot(normalize(col), dir));
    if (v > best) { best = v; bestK = k; }
  }
  return s[bestK];
}

// The crosshair moved `steps` slices along the pane's normal, kept inside [lo, hi] (the
// volume's bounds along that normal, world mm).
export function scrolledPoint(point, normal, steps, step, lo, hi) {
  const along = dot(point, normal);
  const target = Math.min(hi, Math.max(lo, along + steps * step));
  return add(point, scale(normal, target - along));
}

// --- the crop box ---------------------------------------------------------------------------
//
// quality.crop is in the volume's own index axes, normalised: 0 and 1 the outer faces of the
// outermost cells, so f on an axis of n samples is index −½ + f·n, at world
// origin + D·(index·s); the orientation correction C then places it at c + C·(x − c), c the
// volume's centre (renderer/model/orientation_correction.hpp).

export function cropGeometry(volume, correction) {
  const n = volume.dims, s = volume.spacing ?? [1, 1, 1], o = volume.origin ?? [0, 0, 0];
  const D = volume.direction ?? IDENTITY;
  const C = correction ?? IDENTITY;
  const raw = (idx) => [0, 1, 2].map((w) => o[w] + D[w][0] * idx[0] * s[0] + D[w][1] * idx[1] * s[1] + D[w][2] * idx[2] * s[2]);
  const center = raw(n.map((d) => (d - 1) / 2));
  const place = (x) => add(center, mulMat(C, sub(x, center)));
  // World position of normalised box coordinates f = [fx, fy, fz].
  const at = (f) => place(raw(f.map((v, a) => -0.5 + v * n[a])));
  // Unit world direction of +f along each index axis, and the axis's full extent (mm).
  const axes = [0, 1, 2].map((a) => {
    const e = [0, 0, 0]; e[a] = 1;
    return normalize(sub(at(e), at([0, 0, 0])));
  });
  const extents = [0, 1, 2].map((a) => n[a] * s[a]);
  return { at, axes, extents, center };
}

export const FULL_CROP = Object.freeze({ min: [0, 0, 0], max: [1, 1, 1] });

// The eight corners (world) of the crop box, corner k has bit a set for the max face of axis a.
export function cropCorners(geometry, crop) {
  const out = [];
  for (let k = 0; k < 8; k++) out.push(geometry.at([0, 1, 2].map((a) => ((k >> a) & 1 ? crop.max[a] : crop.min[a]))));
  return out;
}
// The 12 edges as corner index pairs.
export const BOX_EDGES = Object.freeze([[0, 1], [2, 3], [4, 5], [6, 7], [0, 2], [1, 3], [4, 6], [5, 7], [0, 4], [1, 5], [2, 6], [3, 7]]);

// The six faces' centres: {axis, side ("min" | "max"), point}.
export function cropFaces(geometry, crop) {
  const faces = [];
  for (let a = 0; a < 3; a++) for (const side of ["min", "max"]) {
    const f = [0, 1, 2].map((b) => (b === a ? crop[side][a] : (crop.min[b] + crop.max[b]) / 2));
    faces.push({ axis: a, side, point: geometry.at(f) });
  }
  return faces;
}

export const MIN_CROP_GAP = 0.01;   // the smallest box, of the extent per axis (as crop_panel's sliders)

// A face moved by a world displacement: only its component along the face's axis counts.
// The face stops MIN_CROP_GAP short of its opposite and inside [0, 1]; values are rounded to
// 1e-4 (a tenth of a slider step) so the crop travels as short JSON.
export function movedCrop(geometry, crop, face, displacement) {
  const a = face.axis;
  const df = dot(displacement, geometry.axes[a]) / geometry.extents[a];
  const next = { min: [...crop.min], max: [...crop.max] };
  const round = (v) => Math.round(v * 1e4) / 1e4;
  if (face.side === "min") next.min[a] = round(Math.min(crop.max[a] - MIN_CROP_GAP, Math.max(0, crop.min[a] + df)));
  else next.max[a] = round(Math.max(crop.min[a] + MIN_CROP_GAP, Math.min(1, crop.max[a] + df)));
  return next;
}

// Where the crop box cuts a slice's plane: the polygon's vertices as slice pixels (c, r), in
// order around it; [] when the plane misses the box.
export function cropOnSlice(header, corners) {
  const n = sliceNormal(header);
  const d0 = dot(header.origin, n);
  const side = corners.map((p) => dot(p, n) - d0);
  const pts = [];
  for (const [i, j] of BOX_EDGES) {
    const a = side[i], b = side[j];
    if ((a < 0 && b < 0) || (a > 0 && b > 0) || a === b) {
      if (a === 0 && b === 0) pts.push(corners[i], corners[j]);
      continue;
    }
    const t = a / (a - b);
    pts.push(add(corners[i], scale(sub(corners[j], corners[i]), t)));
  }
  if (pts.length < 3) return [];
  const px = pts.map((p) => pixelOf(header, p));
  const cx = px.reduce((s, p) => s + p.c, 0) / px.length, cy = px.reduce((s, p) => s + p.r, 0) / px.length;
  px.sort((p, q) => Math.atan2(p.r - cy, p.c - cx) - Math.atan2(q.r - cy, q.c - cx));
  // Drop repeats (a plane through a corner or along a face).
  return px.filter((p, i) => i === 0 || Math.hypot(p.c - px[i - 1].c, p.r - px[i - 1].r) > 1e-6);
}

// The handles of the crop box on a slice: each face whose axis lies in the plane, at its
// centre moved into the plane; in slice pixels.
export function cropHandlesOnSlice(header, geometry, crop) {
  const n = sliceNormal(header);
  const onPlane = (p) => sub(p, scale(n, dot(sub(p, header.origin), n)));
  return cropFaces(geometry, crop)
    .filter((f) => Math.abs(dot(geometry.axes[f.axis], n)) < 1e-6)
    .map((f) => ({ ...f, pixel: pixelOf(header, onPlane(f.point)) }));
}
