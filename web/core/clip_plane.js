// The clip plane the quality panel's slider moves: axis-aligned, through the box the volume
// is drawn in (orientation.js's correctedBounds: after a quarter turn of the volume that is
// not the file's box), the slider's 0 and 1 on its faces. Pure functions, no DOM.

// The plane at fraction t of `bounds` along `axis` (0, 1, 2), through the box's centre on
// the other axes; it keeps the half-space its normal points into (+, or − when flipped).
export function axisClipPlane(bounds, axis, t, flipped) {
  const { lo, hi, center } = bounds;
  const point = [...center];
  point[axis] = lo[axis] + t * (hi[axis] - lo[axis]);
  const normal = [0, 0, 0];
  normal[axis] = flipped ? -1 : 1;
  return { point: point.map((x) => Number(x.toPrecision(8))), normal };
}

// An axis-aligned plane (one the server reports) as {axis, t, flipped}, or null for any
// other; t is where it cuts `bounds`, kept to [0, 1].
export function sliderOfPlane(bounds, plane) {
  const axis = plane.normal.findIndex((n) => Math.abs(n) > 0.999);
  if (axis < 0) return null;
  const { lo, hi } = bounds;
  const t = (plane.point[axis] - lo[axis]) / (hi[axis] - lo[axis]);
  return { axis, t: Math.min(1, Math.max(0, t)), flipped: plane.normal[axis] < 0 };
}
