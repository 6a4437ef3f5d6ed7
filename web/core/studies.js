// Searching a DICOMweb source (protocol/README.md's `find_studies`) and telling the user
// what the server is doing with a series: the search fields checked and turned into a
// request, dates and patient names as people read them, retrieval progress in words, and
// errors a user understands. No DOM here: it runs under Node's test runner.
//
// Patient names and IDs are shown, never logged: nothing here writes to the console.

export const DEFAULT_STUDY_LIMIT = 100;   // the server's default `limit`
export const MAX_STUDY_LIMIT = 1000;      // the server's largest `limit`
const MAX_PN_CHARS = 64;                  // DICOM PN: 64 characters per component group
const MAX_LO_CHARS = 64;                  // DICOM LO (patient ID)
const MAX_SH_CHARS = 16;                  // DICOM SH (accession number), CS (modality)

// Modalities offered in the picker (DICOM PS3.3 C.7.3.1.1.1); any other CS value may be typed.
export const COMMON_MODALITIES = Object.freeze(["CT", "MR", "PT", "NM", "US", "XA", "CR", "DX", "MG", "OT"]);

export class QueryError extends Error {
  constructor(field, message) { super(message); this.name = "QueryError"; this.field = field; }
}

// eslint-disable-next-line no-control-regex
const CONTROL = /[\u0000-\u001f\u007f]/;

function realDate(compact) {
  const y = Number(compact.slice(0, 4)), m = Number(compact.slice(4, 6)), d = Number(compact.slice(6, 8));
  const t = new Date(Date.UTC(y, m - 1, d));
  return y >= 1800 && t.getUTCFullYear() === y && t.getUTCMonth() === m - 1 && t.getUTCDate() === d;
}

const DATE = "(\\d{4}-\\d{2}-\\d{2}|\\d{8})";
const ONE_DATE = new RegExp(`^${DATE}$`);
// "from–to" with an en or em dash, a hyphen, "..", or "to"; either end may be empty.
const DATE_RANGE = new RegExp(`^${DATE}?\\s*(?:[-–—]|\\.\\.|to)\\s*${DATE}?$`, "i");

// A study date as typed ("2024-01-31", "20240131", "2024-01-01 – 2024-01-31", "2024-01-01–",
// "–20240131") into the protocol's form ("YYYYMMDD" or "YYYYMMDD-YYYYMMDD", either end
// empty); "" for no date. Throws QueryError naming what is wrong.
export function parseStudyDate(text) {
  const s = String(text ?? "").trim();
  if (!s) return "";
  const compact = (d) => {
    const c = d.replace(/-/g, "");
    if (!realDate(c)) throw new QueryError("study_date", `study date: ${d} is not a date`);
    return c;
  };
  let m = ONE_DATE.exec(s);
  if (m) return compact(m[1]);
  m = DATE_RANGE.exec(s);
  if (!m || (!m[1] && !m[2])) {
    throw new QueryError("study_date", "study date: give a date (2024-01-31) or a range (2024-01-01 – 2024-01-31; either end may be left out)");
  }
  const from = m[1] ? compact(m[1]) : "", to = m[2] ? compact(m[2]) : "";
  if (from && to && from > to) throw new QueryError("study_date", "study date: the range ends before it starts");
  return `${from}-${to}`;
}

// A patient name as typed into a DICOM PN match: "Doe, John" → "Doe^John" (DICOM's
// family^given); without a wildcard it matches names that start with it ("doe" finds
// "DOE^JOHN"), as PACS search boxes do; * and ? are DICOM's wildcards.
export function patientNameQuery(text) {
  let s = String(text ?? "").trim();
  if (!s) return "";
  if (CONTROL.test(s) || s.includes("\\")) throw new QueryError("patient_name", "patient name: no control characters or backslashes");
  s = s.replace(/\s*,\s*/g, "^");
  if (!/[*?]/.test(s)) s += "*";
  if (s.length > MAX_PN_CHARS) throw new QueryError("patient_name", `patient name: at most ${MAX_PN_CHARS - 1} characters`);
  return s;
}

function plainField(field, label, text, max) {
  const s = String(text ?? "").trim();
  if (CONTROL.test(s) || s.includes("\\")) throw new QueryError(field, `${label}: no control characters or backslashes`);
  if (s.length > max) throw new QueryError(field, `${label}: at most ${max} characters`);
  return s;
}

// The search form's fields ({source, patientName, patientId, studyDate, modality,
// accessionNumber, limit}) as a `find_studies` request without an id; empty fields are
// left out (no filter at all lists the source's studies up to the limit). Throws QueryError.
export function buildStudyQuery({ source, patientName, patientId, studyDate, modality, accessionNumber, limit } = {}) {
  if (typeof source !== "string" || !/^[A-Za-z0-9_-]{1,64}$/.test(source)) throw new QueryError("source", "choose a source to search");
  const filters = {};
  const name = patientNameQuery(patientName);
  if (name) filters.patient_name = name;
  const id = plainField("patient_id", "patient ID", patientId, MAX_LO_CHARS);
  if (id) filters.patient_id = id;
  const date = parseStudyDate(studyDate);
  if (date) filters.study_date = date;
  const mod = plainField("modality", "modality", modality, MAX_SH_CHARS).toUpperCase();
  if (mod && !/^[A-Z0-9_ ]+$/.test(mod)) throw new QueryError("modality", "modality: letters and digits, like CT or MR");
  if (mod) filters.modality = mod;
  const acc = plainField("accession_number", "accession number", accessionNumber, MAX_SH_CHARS);
  if (acc) filters.accession_number = acc;
  const n = limit === undefined || limit === null || limit === "" ? DEFAULT_STUDY_LIMIT : Number(limit);
  if (!Number.isInteger(n) || n < 1 || n > MAX_STUDY_LIMIT) throw new QueryError("limit", `limit: a whole number from 1 to ${MAX_STUDY_LIMIT}`);
  return { type: "find_studies", source, filters, limit: n };
}

// --- showing what came back ------------------------------------------------------------

// "20240131" → "2024-01-31"; anything else as it came.
export function formatStudyDate(da) {
  const s = String(da ?? "");
  return /^\d{8}$/.test(s) ? `${s.slice(0, 4)}-${s.slice(4, 6)}-${s.slice(6)}` : s;
}

// DICOM PN "DOE^JOHN^Q^DR^JR" → "DOE, JOHN Q"; the first component group only (the
// ideographic and phonetic ones after "=" are left out); "" for none.
export function formatPatientName(pn) {
  const alphabetic = String(pn ?? "").split("=")[0];
  const [family = "", given = "", middle = ""] = alphabetic.split("^").map((c) => c.trim());
  const rest = [given, middle].filter(Boolean).join(" ");
  return family && rest ? `${family}, ${rest}` : family || rest;
}

// The server's `studies` answer, kept lenient: every study has a string uid and a series
// array, newest first (by date, then as sent).
export function normaliseStudies(reply) {
  const list = Array.isArray(reply?.studies) ? reply.studies : [];
  const str = (x) => (typeof x === "string" ? x : x === undefined || x === null ? "" : String(x));
  const studies = list.filter((s) => s && typeof s === "object").map((s, order) => ({
    study_uid: str(s.study_uid),
    patient_name: str(s.patient_name),
    patient_id: str(s.patient_id),
    study_date: str(s.study_date),
    description: str(s.description),
    accession_number: str(s.accession_number),
    modalities: Array.isArray(s.modalities) ? s.modalities.map(str).filter(Boolean) : [],
    series: (Array.isArray(s.series) ? s.series : []).filter((x) => x && typeof x.volume === "string").map((x) => ({
      series_uid: str(x.series_uid), modality: str(x.modality), description: str(x.description),
      instances: Number.isFinite(x.instances) ? x.instances : null, volume: x.volume,
    })),
    order,
  }));
  studies.sort((a, b) => (b.study_date.localeCompare(a.study_date)) || a.order - b.order);
  return studies.map(({ order, ...s }) => s);
}

// --- progress and errors in words ------------------------------------------------------

// Bytes in SI units as people read them: "850 kB", "6.2 MB", "62 MB", "1.4 GB".
export function formatBytes(n) {
  if (!(n >= 0)) return "";
  const units = [["GB", 1e9], ["MB", 1e6], ["kB", 1e3]];
  for (const [unit, size] of units) {
    if (n >= size) { const v = n / size; return `${v < 10 ? v.toFixed(1) : Math.round(v)} ${unit}`; }
  }
  return `${n} B`;
}

const isPair = (x) => Array.isArray(x) && x.length === 2 && x.every((v) => Number.isInteger(v) && v >= 0);

// One line for a `progress` message: "Retrieving 120 of 300 images, 62 MB" while a series
// comes from a PACS; "loading · reading voxels · 35 %" for the other stages.
export function progressText(p) {
  if (!p) return "asking the server…";
  if (p.stage === "retrieving") {
    const parts = [];
    if (isPair(p.instances)) parts.push(`Retrieving ${p.instances[0]} of ${p.instances[1]} images`);
    else parts.push("Retrieving images");
    if (Number.isFinite(p.bytes) && p.bytes >= 0) parts.push(formatBytes(p.bytes));
    return parts.join(", ");
  }
  const task = p.task ? ` · ${String(p.task).replace(/_/g, " ")}` : "";
  return `${p.stage ?? "working"}${task} · ${Math.round((p.fraction ?? 0) * 100)} %`;
}

// The share of the progress bar each stage takes: a series from a PACS spends most of its
// time coming over the network; a file on the server, reading it.
const SHARES = {
  file: { loading: [0, 0.6], preprocessing: [0.6, 0.9], uploading: [0.9, 1] },
  retrieved: { retrieving: [0, 0.7], loading: [0.7, 0.88], preprocessing: [0.88, 0.97], uploading: [0.97, 1] },
};

// How far the whole open is, 0…1, from the latest progress of volume `name`; true (an
// indeterminate bar) before any.
export function overallProgress(name, p) {
  if (!p) return true;
  const shares = String(name ?? "").startsWith("dicomweb:") ? SHARES.retrieved : SHARES.file;
  const [from, to] = shares[p.stage] ?? [0, 1];
  let f = Number.isFinite(p.fraction) ? p.fraction : 0;
  if (p.stage === "retrieving" && isPair(p.instances) && p.instances[1] > 0 && !(p.fraction > 0)) f = p.instances[0] / p.instances[1];
  return from + Math.min(1, Math.max(0, f)) * (to - from);
}

// The source of a dicomweb:SOURCE/STUDY/SERIES name, or null.
export function sourceOf(volumeName) {
  const m = /^dicomweb:([A-Za-z0-9_-]{1,64})\//.exec(String(volumeName ?? ""));
  return m ? m[1] : null;
}

// A server error about a search or an open, in words a user understands; the server's own
// message follows, since it names what was wrong. {title, detail}.
export function describeError(error, { volume = null, source = null } = {}) {
  const code = error?.code ?? "error";
  const name = String(volume ?? "");
  let said = error?.message ?? error?.serverMessage ?? "";
  // The user knows which series they clicked: the server's reason without its leading name.
  if (name && said.startsWith(`${name}: `)) said = said.slice(name.length + 2);
  const where = source ?? sourceOf(volume);
  if (name.startsWith("upload:") && code === "not_found") {
    return { title: "This uploaded file has expired; open it again.", detail: said };
  }
  switch (code) {
    case "source_failed":
      return { title: `The image archive${where ? ` "${where}"` : ""} did not answer as expected.`, detail: said };
    case "not_found":
      if (error?.request_type === "find_studies" || (!volume && where)) return { title: `This server has no image archive called "${where ?? "?"}".`, detail: said };
      if (where) return { title: `The archive "${where}" no longer has this series.`, detail: said };
      return { title: "There is no such volume on the server.", detail: said };
    case "bad_field": return { title: "The search was refused.", detail: said };
    case "busy": return { title: "The server is busy; try again in a moment.", detail: said };
    case "load_failed":
      // For a PACS series the server's reason says which: the archive unreachable, or the images unreadable.
      if (where) return { title: `The series from "${where}" could not be opened.`, detail: said };
      return { title: "The images could not be read as a volume.", detail: said };
    case "too_large": return { title: "This series is too large for the server.", detail: said };
    default: return { title: `${code}`, detail: said };
  }
}
