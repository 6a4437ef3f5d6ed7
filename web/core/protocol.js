// The wire contract of protocol/README.md, version 1: request builders, server-message
// parsing and binary frame decoding. No DOM, no sockets: runs in browsers and in Node.
//
// Strict out, lenient in: requests carry only the fields the server knows (it refuses any
// other), while server messages and frame headers keep fields, codes and types this client
// does not know, so that a newer server can add them.

export const PROTOCOL_VERSION = 1;
export const FRAME_MAGIC = "VCF1";
export const FRAME_PREAMBLE_BYTES = 8;            // bytes: magic + uint32 little-endian header length
export const MAX_FRAME_HEADER_BYTES = 64 * 1024;  // bytes; real headers are ~600

// Transfer-function presets the server resolves by name (renderer/model/transfer_function.hpp).
export const TF_PRESETS = Object.freeze([
  { name: "ct_bone", label: "CT bone" },
  { name: "ct_soft_tissue", label: "CT soft tissue" },
  { name: "ct_angiography", label: "CT angiography" },
  { name: "mr", label: "MR" },
  { name: "micro_ct", label: "Micro-CT" },
]);

// Error codes a client may act on; unknown codes are errors all the same.
export const FATAL_ERROR_CODES = Object.freeze(["unauthorized", "unsupported_version"]);

export class FrameError extends Error {
  constructor(message) { super(`frame: ${message}`); this.name = "FrameError"; }
}

export class MessageError extends Error {
  constructor(message) { super(`server message: ${message}`); this.name = "MessageError"; }
}

// An `error` message from the server, as an exception for code that awaited an answer.
export class ServerError extends Error {
  constructor(msg) {
    super(`${msg.code}: ${msg.message}`);
    this.name = "ServerError";
    this.code = msg.code;
    this.serverMessage = msg.message;
    this.id = msg.id ?? null;
    this.requestType = msg.request_type ?? null;
    // load_failed of a series of several stacks: each {volume, slices, rows, columns, orientation, localizer}.
    this.stacks = Array.isArray(msg.stacks) ? msg.stacks.filter((s) => isObject(s) && typeof s.volume === "string") : [];
  }
}

const isObject = (x) => x !== null && typeof x === "object" && !Array.isArray(x);

// ---------------------------------------------------------------------------------------
// Requests (client → server). Each returns a plain object without an id; the connection
// numbers it. Only the fields the README lists, so a typo cannot reach the server.

export const requests = {
  hello: ({ client = "", token } = {}) =>
    token ? { type: "hello", protocol: PROTOCOL_VERSION, client, token }
          : { type: "hello", protocol: PROTOCOL_VERSION, client },
  listVolumes: () => ({ type: "list_volumes" }),
  openVolume: (name) => ({ type: "open_volume", name: String(name) }),
  camera: (camera) => ({ type: "camera", camera }),
  interactionStart: () => ({ type: "interaction_start" }),
  interactionEnd: () => ({ type: "interaction_end" }),
  viewport: (width, height) => ({ type: "viewport", image: { width, height } }),
  transferFunction: (tf) => ({ type: "transfer_function", transfer_function: tf }),
  qualityAutomatic: (targetFrameMs, quality) =>
    quality ? { type: "quality_policy", mode: "automatic", target_frame_ms: targetFrameMs, quality }
            : { type: "quality_policy", mode: "automatic", target_frame_ms: targetFrameMs },
  qualityExplicit: (quality) => ({ type: "quality_policy", mode: "explicit", quality }),
  clipPlanes: (planes) => ({ type: "clip_planes", clip_planes: planes }),
  still: (image) => (image ? { type: "still", image } : { type: "still" }),
  getState: () => ({ type: "get_state" }),
  // A search of a DICOMweb source; build it with core/studies.js's buildStudyQuery, which
  // checks the fields first. filters: {patient_name, patient_id, study_date, modality,
  // accession_number}, each optional.
  findStudies: (source, filters = {}, limit) =>
    (limit === undefined ? { type: "find_studies", source, filters } : { type: "find_studies", source, filters, limit }),
  close: () => ({ type: "close" }),
  // A plane of the open volume (protocol/README.md, `slice`): axis "axial" | "coronal" |
  // "sagittal", size in pixels; optional point/center (world mm), pixel_spacing, window, level.
  // slab: {thickness (mm), mode: "mip" | "minip" | "mean"}, a thick slab projected along the
  // plane's normal; thickness 0 or absent is the plane alone.
  slice: (axis, width, height, { point, center, pixelSpacing, window, level, slab } = {}) => {
    const m = { type: "slice", axis, width, height };
    if (point) m.point = point;
    if (center) m.center = center;
    if (pixelSpacing !== undefined) m.pixel_spacing = pixelSpacing;
    if (window !== undefined) m.window = window;
    if (level !== undefined) m.level = level;
    if (slab && slab.thickness > 0) m.slab = { thickness: slab.thickness, mode: slab.mode };
    return m;
  },
  // The volume's value at a world point (mm): answered by `probe` {inside, value, unit}.
  probe: (point) => ({ type: "probe", point: [...point] }),
  // Statistics of an ellipse or rectangle in a pane's plane: centre (world mm), radii [a, b]
  // in mm along the pane's column and row directions. Answered by `roi_stats`.
  roiStats: (axis, center, radii, shape = "ellipse") => ({ type: "roi_stats", axis, center: [...center], radii: [...radii], shape }),
  // The surface point under pixel (x, y) of a width × height image of the current camera
  // (pixel centres at +0.5, origin top left). Answered by `pick` {hit, point, opacity}.
  pick: (x, y, width, height) => ({ type: "pick", x, y, width, height }),
};

// Requests whose effect shows in frames: a frame's `request` names the latest of them.
export const SCENE_CHANGING = Object.freeze(new Set([
  "open_volume", "camera", "viewport", "transfer_function", "quality_policy", "clip_planes", "still",
]));

// The reply type a request waits for; requests absent here are answered by frames only
// (or by an `error`).
export const REPLY_TYPE = Object.freeze({
  hello: "hello",
  list_volumes: "volumes",
  open_volume: "state",
  get_state: "state",
  find_studies: "studies",
  probe: "probe",
  roi_stats: "roi_stats",
  pick: "pick",
});

// ---------------------------------------------------------------------------------------
// Server → client text messages.

// Parse one text message: a JSON object with a string `type`. Everything else is kept as
// sent (lenient in). Throws MessageError for anything that is not a message at all.
export function parseServerMessage(text) {
  let msg;
  try {
    msg = JSON.parse(text);
  } catch (e) {
    throw new MessageError(`not JSON (${e.message})`);
  }
  if (!isObject(msg)) throw new MessageError("not a JSON object");
  if (typeof msg.type !== "string") throw new MessageError("no string \"type\"");
  if (!("id" in msg)) msg.id = null;
  if (msg.type === "error") {
    if (typeof msg.code !== "string") msg.code = "internal";
    if (typeof msg.message !== "string") msg.message = "(the server gave no message)";
  }
  if (msg.type === "progress") {
    const f = Number(msg.fraction);
    msg.fraction = Number.isFinite(f) ? Math.min(1, Math.max(0, f)) : 0;
  }
  return msg;
}

// ---------------------------------------------------------------------------------------
// Frames: "VCF1", uint32 LE header length N, N bytes of JSON header, then the image.

const utf8 = new TextDecoder("utf-8", { fatal: true });

// Decode one binary message (ArrayBuffer or a typed-array view). Returns
// {header, image} where image is a Uint8Array view of the encoded PNG or JPEG bytes.
export function decodeFrame(data) {
  const bytes = data instanceof ArrayBuffer ? new Uint8Array(data)
    : ArrayBuffer.isView(data) ? new Uint8Array(data.buffer, data.byteOffset, data.byteLength)
    : null;
  if (!bytes) throw new FrameError("not binary data");
  if (bytes.length < FRAME_PREAMBLE_BYTES) throw new FrameError("shorter than the 8-byte preamble");
  const magic = String.fromCharCode(bytes[0], bytes[1], bytes[2], bytes[3]);
  if (magic !== FRAME_MAGIC) throw new FrameError(`bad magic ${JSON.stringify(magic)}`);
  const n = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength).getUint32(4, /* littleEndian */ true);
  if (n > MAX_FRAME_HEADER_BYTES) throw new FrameError(`header of ${n} bytes is over ${MAX_FRAME_HEADER_BYTES}`);
  if (FRAME_PREAMBLE_BYTES + n > bytes.length) throw new FrameError("truncated header");
  let header;
  try {
    header = JSON.parse(utf8.decode(bytes.subarray(FRAME_PREAMBLE_BYTES, FRAME_PREAMBLE_BYTES + n)));
  } catch (e) {
    throw new FrameError(`header is not UTF-8 JSON (${e.message})`);
  }
  if (!isObject(header)) throw new FrameError("header is not a JSON object");
  for (const key of ["seq", "width", "height", "image_bytes"]) {
    if (!Number.isInteger(header[key]) || header[key] < 0) throw new FrameError(`header.${key} is not a non-negative integer`);
  }
  if (header.codec !== "png" && header.codec !== "jpeg") throw new FrameError(`unknown codec ${JSON.stringify(header.codec)}`);
  const image = bytes.subarray(FRAME_PREAMBLE_BYTES + n);
  if (image.length !== header.image_bytes) {
    throw new FrameError(`image is ${image.length} bytes, header says ${header.image_bytes}`);
  }
  header.final = header.final === true;
  header.request = header.request ?? null;
  header.error = isObject(header.error) && Number.isFinite(header.error.value) ? header.error : null;
  return { header, image };
}

export const mimeTypeOf = (codec) => (codec === "png" ? "image/png" : "image/jpeg");

// PSNR (dB) of an RMSE over [0, 1] values: 20·log10(1 / rmse); Infinity for 0.
export function psnrOf(rmse) {
  return rmse > 0 ? -20 * Math.log10(rmse) : Infinity;
}

// ---------------------------------------------------------------------------------------
// Slice messages: "VCS1", uint32 LE header length N, N bytes of JSON header, then
// width × height bytes of 8-bit grey, row 0 at the top (protocol/README.md, "Slice messages").

export const SLICE_MAGIC = "VCS1";

const bytesOf = (data) => (data instanceof ArrayBuffer ? new Uint8Array(data)
  : ArrayBuffer.isView(data) ? new Uint8Array(data.buffer, data.byteOffset, data.byteLength) : null);

export function isSliceMessage(data) {
  const b = bytesOf(data);
  return !!b && b.length >= 4 && String.fromCharCode(b[0], b[1], b[2], b[3]) === SLICE_MAGIC;
}

// Decode one slice message: {header, pixels} with pixels a Uint8Array view of width × height
// grey bytes. Throws FrameError naming the problem.
export function decodeSlice(data) {
  const bytes = bytesOf(data);
  if (!bytes) throw new FrameError("slice: not binary data");
  if (bytes.length < FRAME_PREAMBLE_BYTES) throw new FrameError("slice: shorter than the 8-byte preamble");
  if (!isSliceMessage(bytes)) throw new FrameError("slice: bad magic");
  const n = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength).getUint32(4, true);
  if (n > MAX_FRAME_HEADER_BYTES || FRAME_PREAMBLE_BYTES + n > bytes.length) throw new FrameError("slice: truncated header");
  let header;
  try {
    header = JSON.parse(utf8.decode(bytes.subarray(FRAME_PREAMBLE_BYTES, FRAME_PREAMBLE_BYTES + n)));
  } catch (e) {
    throw new FrameError(`slice header is not UTF-8 JSON (${e.message})`);
  }
  if (!isObject(header)) throw new FrameError("slice header is not a JSON object");
  for (const key of ["width", "height"]) {
    if (!Number.isInteger(header[key]) || header[key] < 1) throw new FrameError(`slice header.${key} is not a positive integer`);
  }
  if (header.format !== "gray8") throw new FrameError(`slice: unknown pixel format ${JSON.stringify(header.format)}`);
  for (const key of ["origin", "column", "row", "point"]) {
    if (!Array.isArray(header[key]) || header[key].length !== 3 || !header[key].every(Number.isFinite)) {
      throw new FrameError(`slice header.${key} is not 3 numbers`);
    }
  }
  if (!(header.pixel_spacing > 0)) throw new FrameError("slice header.pixel_spacing is not > 0");
  const pixels = bytes.subarray(FRAME_PREAMBLE_BYTES + n);
  if (pixels.length !== header.width * header.height) {
    throw new FrameError(`slice: ${pixels.length} pixel bytes for ${header.width} × ${header.height}`);
  }
  header.request = header.request ?? null;
  return { header, pixels };
}
