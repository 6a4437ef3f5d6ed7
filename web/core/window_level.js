// Window/level dragging (Alt-drag on the view), in the data's own units. Pure functions.
//
// The level moves by a fixed share of the current window per pixel, bounded below by a
// share of the data's range (so a very narrow window can still be moved across the data);
// the window grows or shrinks by a fixed factor per pixel. Both scale with the data's
// units: the same drag does the same to a CT in HU, an 8-bit scan and an MR.

export const WINDOW_LOG_PER_PX = 0.004;   // horizontal: window × exp(0.004 · dx), ×1.35 per 75 px
export const LEVEL_WINDOW_PER_PX = 1 / 1000;   // vertical: level moves 0.1 % of the window per px
export const LEVEL_RANGE_PER_PX_MIN = 1 / 20000;   // ... and at least 0.005 % of the data range per px

// Bone (W 2000 HU) on a CT of range −1024 … 3071: 2 HU per px, 150 HU for a 75 px drag.
export function windowLevelStep({ window, level }, dxPx, dyPx, range) {
  const span = Math.max((range?.[1] ?? 1) - (range?.[0] ?? 0), 1e-6);
  const levelPerPx = Math.max(window * LEVEL_WINDOW_PER_PX, span * LEVEL_RANGE_PER_PX_MIN);
  return {
    window: Math.max(window * Math.exp(dxPx * WINDOW_LOG_PER_PX), 1e-6 * span),
    level: level + dyPx * levelPerPx,
  };
}

// A window or level as the user reads it: whole Hounsfield units for CT in HU (radiology
// windows are whole numbers), else three significant digits, but never finer than a whole
// unit above 100 (176.896 → 177, 0.04567 → 0.0457, 12345.6 → 12346): short enough for its field.
export function displayNumber(x, { hounsfield = false } = {}) {
  const n = Number(x);
  if (!Number.isFinite(n)) return n;
  if (hounsfield || Math.abs(n) >= 100) return Math.round(n) + 0;   // + 0: no "-0"
  return Number(n.toPrecision(3)) + 0;
}
