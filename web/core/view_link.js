// A view link: the volume, camera and transfer function in the page address's fragment
// (after #, so it never reaches a server log), e.g.
//
//   #volume=cranium_ct.nhdr&eye=100,-400,60&target=100,100,60&up=0,0,1&fov=30&tf=preset:ct_bone
//   #volume=builtin:demo&eye=…&target=…&up=…&height=240&tf=0,0,0,0,0;0.5,1,0.8,0.6,0.4&opacity_unit=2
//
// A link is hostile input: parseViewLink bounds its length and every field, rebuilds the
// view from checked numbers and names only, and refuses the whole link, saying why, when
// any part is wrong. The server still judges what it is sent (an up parallel to the view).

export const MAX_LINK_CHARS = 8192;     // the whole fragment
export const MAX_NAME_CHARS = 1024;     // the server's max_volume_name_bytes
export const MAX_POINTS = 64;           // transfer-function points in a link
const MAX_ABS = 1e12;                   // |coordinate|: world units of any scan fit far inside
const DIGITS = 7;                       // significant digits written: 1e-7 of the scene's size

const num = (x) => Number(x.toPrecision(DIGITS));
const list = (v) => v.map(num).join(",");

// The fragment (without "#") for a view {volume, camera, transfer_function}.
export function formatViewLink({ volume, camera, transfer_function: tf }) {
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

// {view: {volume?, camera?, transfer_function?} | null, error: string | null}; an empty
// fragment is no view and no error.
export function parseViewLink(fragment) {
  const text = (fragment ?? "").replace(/^#/, "");
  if (!text) return { view: null, error: null };
  try {
    if (text.length > MAX_LINK_CHARS) refuse(`longer than ${MAX_LINK_CHARS} characters`);
    let p;
    try { p = new URLSearchParams(text); } catch { refuse("not a list of key=value pairs"); }
    for (const key of new Set(p.keys())) if (p.getAll(key).length > 1) refuse(`${key} given twice`);
    const view = {};
    if (p.has("volume")) view.volume = volumeName(p.get("volume"));
    if (p.has("eye") || p.has("target") || p.has("up") || p.has("fov") || p.has("height")) view.camera = camera(p);
    if (p.has("tf")) view.transfer_function = transferFunction(p.get("tf"), p.get("opacity_unit"));
    else if (p.has("opacity_unit")) refuse("opacity_unit without tf");
    if (!Object.keys(view).length) refuse("names no volume, camera or transfer function");
    return { view, error: null };
  } catch (e) {
    if (e instanceof LinkError) return { view: null, error: `view link: ${e.message}` };
    throw e;
  }
}
