// core/upload.js with a fake XMLHttpRequest: the request the server gets (method, address,
// headers, body), progress, the 201 answer's volume, the server's reasons for refusing,
// and a state machine that refuses transitions nobody designed.
import { test } from "node:test";
import assert from "node:assert/strict";

import {
  IllegalUploadTransition, UPLOAD_STATES, Upload, checkUploadFile, extensionOf, serverReason, uploadErrorText,
  uploadText, uploadUrl,
} from "../../../web/core/upload.js";

class FakeXhr {
  static last = null;
  static made = 0;
  constructor() { this.headers = {}; this.upload = {}; this.sent = undefined; this.aborted = false; FakeXhr.last = this; FakeXhr.made++; }
  open(method, url) { this.method = method; this.url = url; }
  setRequestHeader(k, v) { this.headers[k] = v; }
  send(body) { this.sent = body; }
  abort() { this.aborted = true; this.onabort?.(); }
  // the server's side
  progress(loaded, total) { this.upload.onprogress?.({ loaded, total, lengthComputable: true }); }
  answer(status, text) { this.status = status; this.responseText = text; this.onload?.(); }
}

const file = (name, size = 1000) => ({ name, size });
const URL_ = "http://127.0.0.1:8080/api/volumes";

function run(f, options = {}) {
  const u = new Upload(f, { url: URL_, XMLHttpRequest: FakeXhr, ...options });
  const states = [];
  u.on("state", (s) => states.push(s.state));
  return { u, states };
}

test("the upload address sits beside the WebSocket's, behind a proxy prefix too", () => {
  assert.equal(uploadUrl("ws://127.0.0.1:8080/ws"), "http://127.0.0.1:8080/api/volumes");
  assert.equal(uploadUrl("wss://example.org/volcast/ws?x=1"), "https://example.org/volcast/api/volumes");
});

test("the accepted files: .nrrd, .nii, .nii.gz, .mha, .zip, any case; others refused before any request", () => {
  for (const n of ["a.nrrd", "B.NII", "c.nii.gz", "d.mha", "series.ZIP"]) assert.equal(checkUploadFile(file(n)), null, n);
  assert.equal(extensionOf("head.nii.gz"), ".nii.gz");
  assert.equal(extensionOf(".nrrd"), null, "a bare extension is no name");
  assert.match(checkUploadFile(file("head.dcm")), /not a file the server opens .*\.zip/);
  assert.match(checkUploadFile(file("a.nrrd", 0)), /empty/);
  const made = FakeXhr.made;
  const { u, states } = run(file("notes.txt"));
  u.start();
  assert.deepEqual(states, ["failed"]);
  assert.equal(FakeXhr.made, made, "no request for a file the server would refuse");
  assert.match(uploadText(u), /notes\.txt: not a file/);
});

test("a file goes as POST /api/volumes with its name and the page's token, then opens the 201's volume", () => {
  const f = file("head ct.nii.gz", 4_000_000);
  const { u, states } = run(f, { token: "s3cret" });
  const progress = [];
  u.on("progress", (p) => progress.push(p.loaded));
  u.start();
  const x = FakeXhr.last;
  assert.equal(x.method, "POST");
  assert.equal(x.url, URL_);
  assert.equal(x.headers["X-Volcast-Filename"], "head ct.nii.gz");
  assert.equal(x.headers.Authorization, "Bearer s3cret");
  assert.equal(x.sent, f, "the body is the file itself");
  x.progress(1_000_000, 4_000_000);
  assert.equal(uploadText(u), "Uploading head ct.nii.gz: 1.0 MB of 4.0 MB (25 %)");
  x.progress(4_000_000, 4_000_000);
  x.answer(201, JSON.stringify({ volume: "upload:0123456789abcdef0123456789abcdef", filename: "head ct.nii.gz", bytes: 4000000, expires_in_s: 3600 }));
  assert.equal(u.state, UPLOAD_STATES.opening);
  assert.equal(u.volume, "upload:0123456789abcdef0123456789abcdef");
  u.opened();
  assert.deepEqual(states, ["uploading", "opening", "opened"]);
  assert.deepEqual(progress, [1_000_000, 4_000_000]);
});

test("without a token no Authorization header; a name that is not plain ASCII goes as ?filename=", () => {
  const { u } = run(file("Schädel.nrrd"));
  u.start();
  assert.equal(FakeXhr.last.headers.Authorization, undefined);
  assert.equal(FakeXhr.last.headers["X-Volcast-Filename"], undefined);
  assert.equal(FakeXhr.last.url, `${URL_}?filename=Sch%C3%A4del.nrrd`);
  assert.equal(u.state, "uploading");
});

test("refusals show the server's one-line reason; 413 says the file is over the upload limit", () => {
  const cases = [
    [413, "upload of 2000 MiB is over --max-upload-mib 1024\n", /big\.nrrd is over the server's upload limit: upload of 2000 MiB is over/],
    [422, '{"error": "big.nrrd: NRRD header: unknown type \\"float7\\""}', /could not read big\.nrrd: big\.nrrd: NRRD header: unknown type/],
    [401, "unauthorized\n", /needs a token/],
    [429, "2 uploads from 127.0.0.1 already\n", /Too many uploads/],
    [507, "no room\n", /no room for more uploads/],
    [500, "", /The server failed to take big\.nrrd \(HTTP 500\)$/],
  ];
  for (const [status, body, why] of cases) {
    const { u, states } = run(file("big.nrrd"));
    u.start();
    FakeXhr.last.answer(status, body);
    assert.deepEqual(states, ["uploading", "failed"], `HTTP ${status}`);
    assert.match(u.message, why, `HTTP ${status}`);
    assert.equal(uploadText(u), u.message);
  }
  assert.equal(serverReason(`first line\nsecond`), "first line");
  assert.equal(serverReason("x".repeat(400)).length, 300);
  assert.match(uploadErrorText(418, "teapot", "a.nrrd"), /refused \(HTTP 418\): teapot/);
});

test("a 201 without a volume, a lost connection and a cancel each end the upload, saying so", () => {
  let r = run(file("a.mha"));
  r.u.start();
  FakeXhr.last.answer(201, "not json");
  assert.match(r.u.message, /named no volume/);
  r = run(file("a.mha"));
  r.u.start();
  FakeXhr.last.onerror();
  assert.equal(r.u.state, "failed");
  assert.match(r.u.message, /did not reach the server/);
  r = run(file("a.mha"));
  r.u.start();
  r.u.cancel();
  assert.equal(FakeXhr.last.aborted, true);
  assert.deepEqual(r.states, ["uploading", "cancelled"]);
});

test("the state machine refuses what nobody designed: opening twice, progress or answers after the end", () => {
  const { u } = run(file("a.nrrd"));
  assert.throws(() => u.opened(), IllegalUploadTransition);
  u.start();
  assert.throws(() => u.start(), IllegalUploadTransition);
  const x = FakeXhr.last;
  x.answer(201, JSON.stringify({ volume: "upload:00" }));
  x.answer(500, "late");          // ignored: the upload is past uploading
  x.progress(1, 2);               // ignored
  assert.equal(u.state, "opening");
  u.failed("This uploaded file has expired; open it again.");
  assert.equal(u.state, "failed");
  assert.throws(() => u.opened(), IllegalUploadTransition);
});
