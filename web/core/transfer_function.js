// Transfer functions as docs/design.md defines them: control points [value, r, g, b, a] in data
// units, strictly increasing values, components in [0, 1], piecewise linear, clamped
// outside. Pure functions over arrays of points (rows), for the editor and its tests.

// The server resolves presets by name (renderer/model/transfer_function.cpp). The editor needs
// their points to draw and edit them, so they are mirrored here; a preset sent by name
// stays a name on the wire and in saved scenes, so a drift would show only in the editor.
// Values in Hounsfield units for CT; MR and micro-CT are placed on the volume's range.
const HU_PRESETS = {
  ct_bone: [[-1000, 0, 0, 0, 0], [150, 0.9, 0.6, 0.4, 0], [300, 0.95, 0.85, 0.7, 0.3],
    [1000, 1, 1, 0.95, 0.8], [3000, 1, 1, 1, 0.9]],
  ct_soft_tissue: [[-1000, 0, 0, 0, 0], [-600, 0.6, 0.3, 0.25, 0], [-100, 0.8, 0.45, 0.35, 0.05],
    [60, 0.95, 0.6, 0.5, 0.15], [300, 1, 0.9, 0.85, 0.4], [3000, 1, 1, 1, 0.8]],
  ct_angiography: [[-1000, 0, 0, 0, 0], [120, 0.7, 0.1, 0.05, 0], [250, 0.9, 0.3, 0.2, 0.4],
    [500, 1, 0.9, 0.8, 0.8], [3000, 1, 1, 1, 0.9]],
};
const RELATIVE_PRESETS = {
  mr: [[0.0, 0, 0, 0, 0], [0.12, 0.6, 0.4, 0.3, 0], [0.35, 0.9, 0.7, 0.6, 0.15],
    [0.7, 1, 0.95, 0.9, 0.4], [1.0, 1, 1, 1, 0.6]],
  micro_ct: [[0.0, 0, 0, 0, 0], [0.3, 0.8, 0.6, 0.4, 0], [0.5, 0.9, 0.8, 0.7, 0.5], [1.0, 1, 1, 1, 0.95]],
};

export const PRESET_NAMES = Object.freeze([...Object.keys(HU_PRESETS), ...Object.keys(RELATIVE_PRESETS)]);

// Points of a named preset on a volume's value range [min, max].
export function presetPoints(name, range) {
  if (HU_PRESETS[name]) return HU_PRESETS[name].map((p) => [...p]);
  if (!RELATIVE_PRESETS[name]) throw new Error(`unknown transfer function preset "${name}"`);
  const lo = range[0];
  const span = Math.max(range[1] - range[0], 1e-6);
  return RELATIVE_PRESETS[name].map(([f, r, g, b, a]) => [lo + f * span, r, g, b, a]);
}

// The points a scene-file transfer function stands for: its points, or its preset's.
export function resolvePoints(tf, range) {
  if (Array.isArray(tf?.points)) return tf.points.map((p) => [...p]);
  if (typeof tf?.preset === "string") return presetPoints(tf.preset, range);
  throw new Error("transfer function has neither points nor preset");
}

// Colour and opacity at value v: linear between points, clamped outside.
export function evaluate(points, v) {
  const n = points.length;
  if (n === 0) return [0, 0, 0, 0];
  if (v <= points[0][0]) return points[0].slice(1);
  if (v >= points[n - 1][0]) return points[n - 1].slice(1);
  let i = 0;
  while (points[i + 1][0] < v) i++;
  const [v0, ...c0] = points[i];
  const [v1, ...c1] = points[i + 1];
  const t = (v - v0) / (v1 - v0);
  return c0.map((c, k) => c + t * (c1[k] - c));
}

const clamp01 = (x) => Math.min(1, Math.max(0, x));

// The smallest gap kept between neighbouring values, relative to the span of the curve,
// so that "strictly increasing" survives a drag onto a neighbour.
export const MIN_GAP_FRACTION = 1e-4;

function minGap(points, range) {
  const span = Math.max(range ? range[1] - range[0] : 0,
    points.length > 1 ? points[points.length - 1][0] - points[0][0] : 0, 1e-6);
  return span * MIN_GAP_FRACTION;
}

// Move point i to (value, alpha), keeping it strictly between its neighbours.
export function movePoint(points, i, value, alpha, range) {
  const out = points.map((p) => [...p]);
  const gap = minGap(points, range);
  const lo = i > 0 ? out[i - 1][0] + gap : -Infinity;
  const hi = i < out.length - 1 ? out[i + 1][0] - gap : Infinity;
  out[i][0] = Math.min(hi, Math.max(lo, value));
  out[i][4] = clamp01(alpha);
  return out;
}

// Insert a point at value with the curve's colour there; returns {points, index}. A
// value already taken by a point moves that point's opacity instead.
export function addPoint(points, value, alpha) {
  const existing = points.findIndex((p) => p[0] === value);
  if (existing >= 0) return { points: movePoint(points, existing, value, alpha), index: existing };
  const [r, g, b] = evaluate(points, value);
  const out = points.map((p) => [...p]);
  let index = out.findIndex((p) => p[0] > value);
  if (index < 0) index = out.length;
  out.splice(index, 0, [value, r, g, b, clamp01(alpha)]);
  return { points: out, index };
}

// Remove point i; a transfer function keeps at least two points.
export function removePoint(points, i) {
  if (points.length <= 2 || i < 0 || i >= points.length) return points.map((p) => [...p]);
  return points.filter((_, k) => k !== i).map((p) => [...p]);
}

export function setColor(points, i, [r, g, b]) {
  const out = points.map((p) => [...p]);
  out[i] = [out[i][0], clamp01(r), clamp01(g), clamp01(b), out[i][4]];
  return out;
}

// Window/level of a curve: the span from its first to its last point (outside it the curve
// is clamped, as a CT viewer's ramp is outside its window). The server's presets
// (renderer/model/presets.hpp) put their points exactly across their window, so a preset reads
// as its radiology window: bone W 2000 / L 400.
export function windowLevelOf(points) {
  const lo = points[0][0], hi = points[points.length - 1][0];
  return { window: Math.max(hi - lo, 1e-6), level: (lo + hi) / 2 };
}

// Apply a window/level to a curve, as a CT viewer's W/L acts on its greyscale ramp: the
// values map affinely so that the curve's current window/level (windowLevelOf) becomes
// the requested one; colours and opacities stay.
export function applyWindowLevel(points, window, level) {
  const from = windowLevelOf(points);
  const s = Math.max(window, 1e-6) / from.window;
  return points.map(([v, ...c]) => [level + (v - from.level) * s, ...c]);
}

// Check the docs/design.md contract; returns a list of problems (empty when valid).
export function problems(points) {
  const out = [];
  if (!Array.isArray(points) || points.length < 1) return ["needs at least one point"];
  points.forEach((p, i) => {
    if (!Array.isArray(p) || p.length !== 5 || !p.every(Number.isFinite)) out.push(`points[${i}]: not 5 finite numbers`);
    else if (p.slice(1).some((c) => c < 0 || c > 1)) out.push(`points[${i}]: colour or opacity outside [0, 1]`);
    if (i > 0 && !(p[0] > points[i - 1][0])) out.push(`points[${i}]: value not above the previous one`);
  });
  return out;
}

// Rounded for the wire and for saved scenes: values to 8 significant digits, components
// to 4 decimals (below an 8-bit colour step). Values stay unrounded where rounding would
// make two of them equal.
export function tidyPoints(points) {
  const out = points.map(([v, r, g, b, a]) => [Number(v.toPrecision(8)), ...[r, g, b, a].map((c) => Math.round(c * 1e4) / 1e4)]);
  if (out.some((p, i) => i > 0 && !(p[0] > out[i - 1][0]))) out.forEach((p, i) => { p[0] = points[i][0]; });
  return out;
}

// "#rrggbb" ↔ [r, g, b] in [0, 1].
export const toHex = ([r, g, b]) => `#${[r, g, b].map((c) => Math.round(clamp01(c) * 255).toString(16).padStart(2, "0")).join("")}`;
export function fromHex(hex) {
  const m = /^#?([0-9a-f]{2})([0-9a-f]{2})([0-9a-f]{2})$/i.exec(hex);
  if (!m) throw new Error(`not a colour: ${hex}`);
  return [m[1], m[2], m[3]].map((h) => parseInt(h, 16) / 255);
}
