// Uploading a file from the user's disk to the server (`POST /api/volumes`), then opening
// the volume it answers with. XMLHttpRequest, not fetch: it reports upload progress. An
// explicit state machine, like the connection's, that refuses illegal transitions:
//
//          start()            201 {volume}          opened()
//   idle ──────────▶ uploading ───────────▶ opening ─────────▶ opened
//     │                 │  4xx/5xx, network        │ failed()
//     │ file refused    │  error, timeout          ▼
//     └────────────────▶└──────────────────────▶ failed
//                       │ cancel()
//                       └──────────────────────▶ cancelled
//
// No DOM here: the XMLHttpRequest constructor is passed in (tests pass a fake).

import { Emitter } from "./emitter.js";
import { formatBytes } from "./studies.js";

// What the server accepts (its loader parses every upload in a child process first).
export const ACCEPTED_EXTENSIONS = Object.freeze([".nrrd", ".nii", ".nii.gz", ".mha", ".zip"]);
export const ACCEPT_ATTRIBUTE = ACCEPTED_EXTENSIONS.join(",");   // <input type=file accept=…>

export const UPLOAD_STATES = Object.freeze({
  idle: "idle", uploading: "uploading", opening: "opening", opened: "opened", failed: "failed", cancelled: "cancelled",
});

const TRANSITIONS = Object.freeze({
  idle: ["uploading", "failed"],
  uploading: ["opening", "failed", "cancelled"],
  opening: ["opened", "failed"],
  opened: [],
  failed: [],
  cancelled: [],
});

export class IllegalUploadTransition extends Error {
  constructor(from, to) { super(`upload: illegal transition ${from} → ${to}`); this.name = "IllegalUploadTransition"; }
}

// The accepted extension a file name ends with (case-insensitive), or null.
export function extensionOf(name) {
  const lower = String(name ?? "").toLowerCase();
  return [...ACCEPTED_EXTENSIONS].sort((a, b) => b.length - a.length).find((e) => lower.endsWith(e) && lower.length > e.length) ?? null;
}

// Why a file cannot be uploaded ({name, size}), or null when it may be.
export function checkUploadFile(file) {
  if (!file || typeof file.name !== "string") return "no file";
  if (!extensionOf(file.name)) {
    return `${file.name}: not a file the server opens (it takes ${ACCEPTED_EXTENSIONS.join(", ")}; a DICOM series as a .zip)`;
  }
  if (!(file.size > 0)) return `${file.name} is empty`;
  return null;
}

// The server's upload address beside its WebSocket address: ws://host:port/ws →
// http://host:port/api/volumes (behind a proxy prefix too).
export function uploadUrl(wsUrl) {
  const u = new URL(wsUrl);
  u.protocol = u.protocol === "wss:" ? "https:" : "http:";
  u.pathname = u.pathname.replace(/[^/]*$/, "api/volumes");
  u.search = "";
  u.hash = "";
  return u.href;
}

// The server's one-line reason from an error body: a JSON {error} or {message}, else the
// first line of the text; at most 300 characters.
export function serverReason(body) {
  const text = String(body ?? "").trim();
  let reason = text.split("\n")[0];
  if (text.startsWith("{")) {
    try {
      const j = JSON.parse(text);
      const m = typeof j.message === "string" ? j.message : typeof j.error === "string" ? j.error : null;
      if (m) reason = m;
    } catch { /* not JSON after all: the first line */ }
  }
  return reason.length > 300 ? `${reason.slice(0, 299)}…` : reason;
}

// An HTTP refusal in words, the server's own reason after it.
export function uploadErrorText(status, body, filename) {
  const reason = serverReason(body);
  const why = {
    400: "The server refused the upload",
    401: "The server needs a token to take uploads (open the page with ?token=…)",
    403: "The server does not take uploads from this page",
    413: `${filename} is over the server's upload limit`,
    415: `The server does not open files like ${filename}`,
    422: `The server could not read ${filename}`,
    429: "Too many uploads from this address at once: wait for one to finish",
    507: "The server has no room for more uploads now: try again later",
  }[status] ?? (status >= 500 ? `The server failed to take ${filename} (HTTP ${status})` : `The upload was refused (HTTP ${status})`);
  return reason ? `${why}: ${reason}` : why;
}

// Only printable ASCII goes in a header; any other name travels as ?filename= (URL-encoded).
const headerSafe = (name) => /^[\x20-\x7e]+$/.test(name);

// Events: "state" {state, previous, message?}, "progress" {loaded, total}.
export class Upload extends Emitter {
  // file: a File (or {name, size}: tests); options: url (uploadUrl(...)), token,
  // XMLHttpRequest (constructor; default the browser's).
  constructor(file, { url, token, XMLHttpRequest: Xhr = globalThis.XMLHttpRequest } = {}) {
    super();
    this.file = file;
    this.url = url;
    this.token = token;
    this.Xhr = Xhr;
    this.state = UPLOAD_STATES.idle;
    this.loaded = 0;
    this.total = file?.size ?? 0;
    this.result = null;    // the server's 201 answer
    this.message = "";     // why it failed
    this.xhr = null;
  }

  transition(to, detail = {}) {
    const from = this.state;
    if (!TRANSITIONS[from]?.includes(to)) throw new IllegalUploadTransition(from, to);
    this.state = to;
    if (detail.message) this.message = detail.message;
    this.emit("state", { state: to, previous: from, ...detail });
  }

  get volume() { return this.result?.volume ?? null; }
  get fraction() { return this.total > 0 ? Math.min(1, this.loaded / this.total) : 0; }

  // Send the file. A file the server would refuse anyway fails at once, without a request.
  start() {
    const refused = checkUploadFile(this.file);
    if (refused) { this.transition(UPLOAD_STATES.failed, { message: refused }); return; }
    this.transition(UPLOAD_STATES.uploading);
    const xhr = new this.Xhr();
    this.xhr = xhr;
    const name = this.file.name;
    const target = headerSafe(name) ? this.url : `${this.url}${this.url.includes("?") ? "&" : "?"}filename=${encodeURIComponent(name)}`;
    xhr.open("POST", target);
    if (headerSafe(name)) xhr.setRequestHeader("X-Volcast-Filename", name);
    if (this.token) xhr.setRequestHeader("Authorization", `Bearer ${this.token}`);
    xhr.setRequestHeader("Content-Type", "application/octet-stream");
    xhr.upload.onprogress = (e) => {
      if (this.xhr !== xhr || this.state !== UPLOAD_STATES.uploading) return;
      this.loaded = e.loaded;
      if (e.lengthComputable && e.total > 0) this.total = e.total;
      this.emit("progress", { loaded: this.loaded, total: this.total });
    };
    xhr.onload = () => { if (this.xhr === xhr) this.onAnswer(xhr.status, xhr.responseText); };
    xhr.onerror = () => {
      if (this.xhr === xhr && this.state === UPLOAD_STATES.uploading) {
        this.transition(UPLOAD_STATES.failed, { message: `The upload of ${name} did not reach the server (connection lost or refused)` });
      }
    };
    xhr.onabort = () => {
      if (this.xhr === xhr && this.state === UPLOAD_STATES.uploading) this.transition(UPLOAD_STATES.cancelled, { message: `The upload of ${name} was cancelled` });
    };
    xhr.send(this.file);
  }

  onAnswer(status, body) {
    if (this.state !== UPLOAD_STATES.uploading) return;
    if (status === 201 || status === 200) {
      let answer = null;
      try { answer = JSON.parse(body); } catch { /* checked below */ }
      if (typeof answer?.volume !== "string" || !answer.volume) {
        this.transition(UPLOAD_STATES.failed, { message: `The server took ${this.file.name} but named no volume to open` });
        return;
      }
      this.result = answer;
      this.loaded = this.total;
      this.transition(UPLOAD_STATES.opening, { volume: answer.volume });
      return;
    }
    this.transition(UPLOAD_STATES.failed, { message: uploadErrorText(status, body, this.file.name), status });
  }

  cancel() { if (this.state === UPLOAD_STATES.uploading) this.xhr?.abort(); }

  // The app reports how opening the uploaded volume went.
  opened() { this.transition(UPLOAD_STATES.opened); }
  failed(message) { this.transition(UPLOAD_STATES.failed, { message }); }
}

// One line for the user: "Uploading head.nii.gz: 12 MB of 100 MB (12 %)".
export function uploadText(u) {
  const name = u.file?.name ?? "file";
  switch (u.state) {
    case UPLOAD_STATES.idle: return `Ready to upload ${name}`;
    case UPLOAD_STATES.uploading:
      return `Uploading ${name}: ${formatBytes(u.loaded)} of ${formatBytes(u.total)} (${Math.round(u.fraction * 100)} %)`;
    case UPLOAD_STATES.opening: return `Uploaded ${name}; opening it`;
    case UPLOAD_STATES.opened: return `Opened ${name}`;
    case UPLOAD_STATES.cancelled: return `The upload of ${name} was cancelled`;
    default: return u.message || `The upload of ${name} failed`;
  }
}
