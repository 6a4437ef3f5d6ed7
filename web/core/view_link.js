// A view link: the whole view in the page address's fragment (after #, so it never reaches
// a server log): the volume, camera and transfer function, and what else decides what the
// reader sees — the orientation correction and whether the patient axes were set by hand,
// the crop box, clip planes, compositing and the projections' window, and the slice panes'
// window/level, crosshair and slab. E.g.
//
//   #volume=cranium_ct.nhdr&eye=100,-400,60&target=100,100,60&up=0,0,1&fov=30&tf=preset:ct_bone
//   #volume=builtin:demo&eye=…&target=…&up=…&height=240&tf=0,0,0,0,0;0.5,1,0.8,0.6,0.4&opacity_unit=2
//   …&orientation=1,0,0,0,-1,0,0,0,1&axes=hand&crop=0,0,0.2,1,1,0.8&clip=10,20,30,0,0,1
//   …&compositing=mip&projection_window=400,40&slice_window=2000,400&crosshair=1.5,-3,40&slab=10,mip
//
// A link is hostile input: parseViewLink bounds its length and every field, rebuilds the
// view from checked numbers and names only, and refuses the whole link, saying why, when
// any part is wrong. The server still judges what it is sent (an up parallel to the view).

export const MAX_LINK_CHARS = 8192;     // the whole fragment
export const MAX_NAME_CHARS = 1024;     // the server's max_volume_name_bytes
export const MAX_POINTS = 64;           // transfer-function points in a link
const MAX_ABS = 1e12;                   // |coordinate|: world units of any scan fit far inside

export const MAX_CLIP_PLANES = 6;      // the scene file's limit
export const MAX_SLAB_MM = 1e4;        // a slab thicker than 10 m is a typo
export const COMPOSITING = Object.freeze(["emission_absorption", "mip", "minip"]);
export const SLAB_MODES = Object.freeze(["mip", "minip", "mean"]);

// Numbers are written as JavaScript's shortest text that reads back as the same double: a
// reopened link draws the same rays (a camera rounded to 7 digits moves a ray by 1e-7 of
// the scene, enough to turn a pixel on a clip plane's or crop face's edge).
const num = (x) => x;
const list = (v) => v.map(num).join(",");

// The fragment (without "#") for a view {volume, camera, transfer_function, orientation,
// crop, clip_planes, compositing, projection_window, slice_window, crosshair, slab}; every
// part is optional, and one left out is not written.
//   orientation        {correction: 3×3 signed permutation (rows), setByHand: bool}
//   crop               {min: [x, y, z], max: [x, y, z]} in [0, 1], the volume's own axes
//   clip_planes        [{point, normal}] (world mm)
//   compositing        "emission_absorption" | "mip" | "minip"
//   projection_window  {window, level}: data units, window > 0
//   slice_window       {window, level}: the slice panes', data units
//   crosshair          [x, y, z]: the point the slice panes pass through (world mm)
//   slab               {thickness: mm ≥ 0, mode: "mip" | "minip" | "mean"}
export function formatViewLink({ volume, camera, transfer_function: tf, orientation, crop, clip_planes: clips,
  compositing, projection_window: pw, slice_window: sw, crosshair, slab }) {
  const p = new URLSearchParams();
  if (volume) p.set("volume", volume);
  if (camera) {
    p.set("eye", list(camera.eye));
    p.set("target", list(camera.target));
    p.set("up", list(camera.up));
    if (camera.projection === "orthographic") p.set("height", String(num(camera.height)));
    else p.set("fov", String(num(camera.fov_y_deg)));
  }
  if (tf?.preset) p.set("tf", `preset:${tf.preset}`);
  else if (Array.isArray(tf?.points)) p.set("tf", tf.points.map(list).join(";"));
  if (tf && Number.isFinite(tf.opacity_unit)) p.set("opacity_unit", String(num(tf.opacity_unit)));
  if (orientation) {
    const c = orientation.correction ?? [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
    const identity = c.every((row, r) => row.every((v, k) => v === (r === k ? 1 : 0)));
    if (!identity) p.set("orientation", c.flat().join(","));
    if (orientation.setByHand) p.set("axes", "hand");
  }
  if (crop) p.set("crop", list([...crop.min, ...crop.max]));
  if (clips?.length) p.set("clip", clips.map((c) => list([...c.point, ...c.normal])).join(";"));
  if (compositing) p.set("compositing", compositing);
  if (pw) p.set("projection_window", list([pw.window, pw.level]));
  if (sw) p.set("slice_window", list([sw.window, sw.level]));
  if (crosshair) p.set("crosshair", list(crosshair));
  if (slab) p.set("slab", `${num(slab.thickness)},${slab.mode}`);
  return p.toString();
}

class LinkError extends Error {}
const refuse = (why) => { throw new LinkError(why); };

function numbers(text, key, count) {
  if (text.length > 64 * count) refuse(`${key}: too long`);
  const parts = text.split(",");
  if (parts.length !== count) refuse(`${key}: needs ${count} numbers, got ${parts.length}`);
  return parts.map((s) => {
    // Plain decimal numbers only: no hex, no "Infinity", no empty strings that Number() takes as 0.
    if (!/^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$/.test(s.trim())) refuse(`${key}: "${s.slice(0, 20)}" is not a number`);
    const x = Number(s);
    if (!Number.isFinite(x) || Math.abs(x) > MAX_ABS) refuse(`${key}: ${s.slice(0, 20)} is out of range`);
    return x;
  });
}

function volumeName(text) {
  if (!text || text.length > MAX_NAME_CHARS) refuse(`volume: must have 1 to ${MAX_NAME_CHARS} characters`);
  // eslint-disable-next-line no-control-regex
  if (/[\u0000-\u001f\u007f\\]/.test(text)) refuse("volume: control characters or a backslash");
  if (text.startsWith("/") || text.startsWith("~") || /^[A-Za-z]:/.test(text) || text.split("/").some((c) => c === "" || c === "." || c === ".."))
    refuse("volume: must be a name relative to the server's data folders");
  return text;
}

function transferFunction(text, unitText) {
  let tf;
  if (text.startsWith("preset:")) {
    const name = text.slice(7);
    if (!/^[a-z0-9_]{1,64}$/.test(name)) refuse("tf: a preset name is lowercase letters, digits and _");
    tf = { preset: name };
  } else {
    const rows = text.split(";");
    if (rows.length < 2 || rows.length > MAX_POINTS) refuse(`tf: needs 2 to ${MAX_POINTS} points`);
    const points = rows.map((r, i) => numbers(r, `tf point ${i + 1}`, 5));
    points.forEach((p, i) => {
      if (p.slice(1).some((c) => c < 0 || c > 1)) refuse(`tf point ${i + 1}: colour and opacity must be in [0, 1]`);
      if (i > 0 && !(p[0] > points[i - 1][0])) refuse(`tf point ${i + 1}: values must increase`);
    });
    tf = { points };
  }
  if (unitText !== null) {
    const [u] = numbers(unitText, "opacity_unit", 1);
    if (!(u > 0)) refuse("opacity_unit: must be positive");
    tf.opacity_unit = u;
  }
  return tf;
}

function camera(p) {
  const [eye, target, up] = ["eye", "target", "up"].map((k) => numbers(p.get(k) ?? refuse(`camera: ${k} missing`), k, 3));
  if (eye.every((x, i) => x === target[i])) refuse("camera: eye and target are the same point");
  if (up.every((x) => x === 0)) refuse("camera: up is zero");
  const fov = p.get("fov"), height = p.get("height");
  if ((fov === null) === (height === null)) refuse("camera: give either fov (perspective) or height (orthographic)");
  if (fov !== null) {
    const [f] = numbers(fov, "fov", 1);
    if (!(f > 0 && f < 180)) refuse("fov: must be in (0, 180) degrees");
    return { eye, target, up, projection: "perspective", fov_y_deg: f };
  }
  const [h] = numbers(height, "height", 1);
  if (!(h > 0)) refuse("height: must be positive");
  return { eye, target, up, projection: "orthographic", height: h };
}

// A signed permutation (flips and quarter turns, docs/design.md's
// quality.orientation_correction): nine integers −1, 0, 1, one non-zero per row and column.
function correction(text) {
  const m = numbers(text, "orientation", 9);
  if (!m.every((v) => v === -1 || v === 0 || v === 1)) refuse("orientation: entries must be -1, 0 or 1");
  const rows = [m.slice(0, 3), m.slice(3, 6), m.slice(6, 9)];
  for (let i = 0; i < 3; i++) {
    if (rows[i].filter((v) => v !== 0).length !== 1) refuse(`orientation: row ${i + 1} must have one non-zero entry`);
    if (rows.filter((r) => r[i] !== 0).length !== 1) refuse(`orientation: column ${i + 1} must have one non-zero entry`);
  }
  return rows;
}

function cropBox(text) {
  const v = numbers(text, "crop", 6);
  if (v.some((x) => x < 0 || x > 1)) refuse("crop: faces must be in [0, 1]");
  const min = v.slice(0, 3), max = v.slice(3);
  if (min.some((x, i) => !(x < max[i]))) refuse("crop: each min must be below its max");
  return { min, max };
}

function clipPlanes(text) {
  const rows = text.split(";");
  if (rows.length > MAX_CLIP_PLANES) refuse(`clip: at most ${MAX_CLIP_PLANES} planes`);
  return rows.map((r, i) => {
    const v = numbers(r, `clip plane ${i + 1}`, 6);
    const normal = v.slice(3);
    if (normal.every((x) => x === 0)) refuse(`clip plane ${i + 1}: the normal is zero`);
    return { point: v.slice(0, 3), normal };
  });
}

function windowLevel(text, key) {
  const [window, level] = numbers(text, key, 2);
  if (!(window > 0)) refuse(`${key}: the window must be positive`);
  return { window, level };
}

function slabOf(text) {
  const parts = text.split(",");
  if (parts.length !== 2) refuse("slab: needs a thickness and a mode");
  const [thickness] = numbers(parts[0], "slab thickness", 1);
  if (!(thickness >= 0 && thickness <= MAX_SLAB_MM)) refuse(`slab: the thickness must be 0 to ${MAX_SLAB_MM} mm`);
  if (!SLAB_MODES.includes(parts[1])) refuse(`slab: the mode must be one of ${SLAB_MODES.join(", ")}`);
  return { thickness, mode: parts[1] };
}

// Keys a link may hold; any other is refused (a typo must not pass as a view that is not there).
const KEYS = new Set(["volume", "eye", "target", "up", "fov", "height", "tf", "opacity_unit", "orientation", "axes",
  "crop", "clip", "compositing", "projection_window", "slice_window", "crosshair", "slab"]);

// {view: {volume?, camera?, transfer_function?, orientation?, crop?, clip_planes?,
// compositing?, projection_window?, slice_window?, crosshair?, slab?} | null, error: string
// | null}; an empty fragment is no view and no error.
export function parseViewLink(fragment) {
  const text = (fragment ?? "").replace(/^#/, "");
  if (!text) return { view: null, error: null };
  try {
    if (text.length > MAX_LINK_CHARS) refuse(`longer than ${MAX_LINK_CHARS} characters`);
    let p;
    try { p = new URLSearchParams(text); } catch { refuse("not a list of key=value pairs"); }
    for (const key of new Set(p.keys())) {
      if (!KEYS.has(key)) refuse(`unknown key "${key.slice(0, 40)}"`);
      if (p.getAll(key).length > 1) refuse(`${key} given twice`);
    }
    const view = {};
    if (p.has("volume")) view.volume = volumeName(p.get("volume"));
    if (p.has("eye") || p.has("target") || p.has("up") || p.has("fov") || p.has("height")) view.camera = camera(p);
    if (p.has("tf")) view.transfer_function = transferFunction(p.get("tf"), p.get("opacity_unit"));
    else if (p.has("opacity_unit")) refuse("opacity_unit without tf");
    if (p.has("orientation") || p.has("axes")) {
      const axes = p.get("axes");
      if (axes !== null && axes !== "hand") refuse('axes: the only value is "hand" (the patient axes were set by hand)');
      view.orientation = {
        correction: p.has("orientation") ? correction(p.get("orientation")) : [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
        setByHand: axes === "hand",
      };
    }
    if (p.has("crop")) view.crop = cropBox(p.get("crop"));
    if (p.has("clip")) view.clip_planes = clipPlanes(p.get("clip"));
    if (p.has("compositing")) {
      const c = p.get("compositing");
      if (!COMPOSITING.includes(c)) refuse(`compositing: must be one of ${COMPOSITING.join(", ")}`);
      view.compositing = c;
    }
    if (p.has("projection_window")) view.projection_window = windowLevel(p.get("projection_window"), "projection_window");
    if (p.has("slice_window")) view.slice_window = windowLevel(p.get("slice_window"), "slice_window");
    if (p.has("crosshair")) view.crosshair = numbers(p.get("crosshair"), "crosshair", 3);
    if (p.has("slab")) view.slab = slabOf(p.get("slab"));
    if (!Object.keys(view).length) refuse("names no volume, camera or transfer function");
    return { view, error: null };
  } catch (e) {
    if (e instanceof LinkError) return { view: null, error: `view link: ${e.message}` };
    throw e;
  }
}
