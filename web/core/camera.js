// Camera navigation on docs/design.md's scene-file camera {eye, target, up, projection,
// fov_y_deg | height}: orbit, pan, zoom. Pure functions returning new cameras; the up
// vector is kept orthonormal to the view direction, so that the server never sees
// "camera.up: is parallel to the view direction".

export const ORBIT_RAD_PER_PX = Math.PI / 400;   // rad per CSS pixel: 400 px drag = half a turn
export const ZOOM_PER_WHEEL_PX = 0.0015;         // log-scale zoom per wheel pixel
export const MIN_DISTANCE_FRACTION = 0.02;       // of the volume's radius: the eye stops this close
export const MAX_DISTANCE_FRACTION = 50;         // of the volume's radius

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const length = (a) => Math.hypot(a[0], a[1], a[2]);
const normalize = (a) => { const l = length(a); return l > 0 ? scale(a, 1 / l) : a; };

export const vec = { sub, add, scale, dot, cross, length, normalize };

// Rotate v about the unit axis k by angle (rad), Rodrigues' formula.
export function rotate(v, k, angle) {
  const c = Math.cos(angle), s = Math.sin(angle);
  return add(add(scale(v, c), scale(cross(k, v), s)), scale(k, dot(k, v) * (1 - c)));
}

// The camera's orthonormal frame: forward (eye → target), right (forward × up, the image
// x axis of docs/design.md), up (image y), and the eye–target distance.
export function cameraFrame(cam) {
  const toTarget = sub(cam.target, cam.eye);
  const distance = length(toTarget);
  const forward = normalize(toTarget);
  let right = cross(forward, cam.up);
  if (length(right) < 1e-12) right = cross(forward, Math.abs(forward[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0]);
  right = normalize(right);
  const up = cross(right, forward);
  return { forward, right, up, distance };
}

// Round to a few significant digits below the float noise, so that cameras travel as
// short, readable JSON (they land in saved scene files).
const tidy = (v) => v.map((x) => (Math.abs(x) < 1e-12 ? 0 : Number(x.toPrecision(12))));

function withPose(cam, eye, target, up) {
  return { ...cam, eye: tidy(eye), target: tidy(target), up: tidy(up) };
}

// Orbit about the target: a horizontal drag turns about the camera's up axis, a vertical
// drag about its right axis (a trackball without a fixed pole: no gimbal lock, and the
// view can go over the top of the volume, as in ParaView).
export function orbit(cam, dxPx, dyPx, radPerPx = ORBIT_RAD_PER_PX) {
  const f = cameraFrame(cam);
  const yaw = -dxPx * radPerPx;
  const pitch = -dyPx * radPerPx;
  // Turn the offset and the frame together, first about up, then about the turned right.
  let offset = sub(cam.eye, cam.target);
  offset = rotate(offset, f.up, yaw);
  const right = rotate(f.right, f.up, yaw);
  offset = rotate(offset, right, pitch);
  const up = rotate(f.up, right, pitch);
  return withPose(cam, add(cam.target, offset), cam.target, up);
}

// World units per CSS pixel at the target's depth, for a view heightPx tall.
export function worldPerPixel(cam, heightPx) {
  if (cam.projection === "orthographic") return cam.height / heightPx;
  const { distance } = cameraFrame(cam);
  return (2 * distance * Math.tan((cam.fov_y_deg * Math.PI) / 360)) / heightPx;
}

// Pan: the content follows the pointer (drag right moves the volume right).
export function pan(cam, dxPx, dyPx, heightPx) {
  const f = cameraFrame(cam);
  const w = worldPerPixel(cam, heightPx);
  const shift = add(scale(f.right, -dxPx * w), scale(f.up, dyPx * w));
  return withPose(cam, add(cam.eye, shift), add(cam.target, shift), f.up);
}

// Zoom by factor (< 1 closer, > 1 farther): perspective moves the eye along the view
// direction, orthographic scales the view height. radius: the volume's bounding radius,
// which bounds the distance (0: no bound).
export function zoom(cam, factor, radius = 0) {
  if (!(factor > 0) || !Number.isFinite(factor)) return cam;
  if (cam.projection === "orthographic") {
    let height = cam.height * factor;
    if (radius > 0) height = Math.min(Math.max(height, radius * MIN_DISTANCE_FRACTION), radius * MAX_DISTANCE_FRACTION * 2);
    return { ...cam, height: Number(height.toPrecision(12)) };
  }
  const f = cameraFrame(cam);
  let distance = f.distance * factor;
  if (radius > 0) distance = Math.min(Math.max(distance, radius * MIN_DISTANCE_FRACTION), radius * MAX_DISTANCE_FRACTION);
  return withPose(cam, sub(cam.target, scale(f.forward, distance)), cam.target, f.up);
}

export function zoomFactorForWheel(deltaPx) {
  return Math.exp(deltaPx * ZOOM_PER_WHEEL_PX);
}

// World-axis-aligned bounds of a volume object (protocol `volumes`): the box around the
// cell extent of docs/design.md, index −½ to n − ½ per axis, placed by origin + D·(index·s)
// with D the volume's `direction` (rows; the identity where the server sends none). A
// flipped or permuted file's box lies on the other side of its origin or along other axes.
export function volumeBounds(volume) {
  if (!volume?.dims) return null;
  const s = volume.spacing ?? [1, 1, 1];
  const o = volume.origin ?? [0, 0, 0];
  const d = volume.direction ?? [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let corner = 0; corner < 8; corner++) {
    const index = [0, 1, 2].map((a) => ((corner >> a) & 1 ? volume.dims[a] - 0.5 : -0.5) * s[a]);
    for (let w = 0; w < 3; w++) {
      const p = o[w] + d[w][0] * index[0] + d[w][1] * index[1] + d[w][2] * index[2];
      lo[w] = Math.min(lo[w], p);
      hi[w] = Math.max(hi[w], p);
    }
  }
  const center = lo.map((l, i) => (l + hi[i]) / 2);
  const radius = length(sub(hi, lo)) / 2;
  return { lo, hi, center, radius };
}

export function camerasEqual(a, b, tolerance = 1e-9) {
  if (!a || !b || a.projection !== b.projection) return false;
  const close = (x, y) => Math.abs(x - y) <= tolerance * Math.max(1, Math.abs(x), Math.abs(y));
  for (const key of ["eye", "target", "up"]) {
    if (!a[key] || !b[key] || !a[key].every((x, i) => close(x, b[key][i]))) return false;
  }
  return a.projection === "orthographic" ? close(a.height, b.height) : close(a.fov_y_deg, b.fov_y_deg);
}
