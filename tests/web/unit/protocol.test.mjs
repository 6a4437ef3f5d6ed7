// core/protocol.js against protocol/README.md: its example frame byte for byte, every
// server line of its example session, and the client lines it shows.
import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { fileURLToPath } from "node:url";
import path from "node:path";

import {
  FrameError, MessageError, PROTOCOL_VERSION, REPLY_TYPE, SCENE_CHANGING, TF_PRESETS, decodeFrame,
  parseServerMessage, psnrOf, requests,
} from "../../../web/core/protocol.js";
import { encodeFrame } from "../lib/fakes.mjs";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../../..");
const readme = readFileSync(path.join(root, "protocol/README.md"), "utf8");

function exampleHexFrame() {
  const text = readFileSync(path.join(root, "tests/protocol/data/frame_example.hex"), "utf8");
  const hex = text.split("\n").map((l) => l.replace(/#.*/, "")).join("").replace(/\s+/g, "");
  return new Uint8Array(hex.match(/../g).map((h) => parseInt(h, 16))).buffer;
}

function exampleSession() {
  const begin = readme.indexOf("<!-- example-session:begin -->");
  const end = readme.indexOf("<!-- example-session:end -->");
  assert.ok(begin >= 0 && end > begin, "protocol/README.md has its example session markers");
  return readme.slice(begin, end).split("\n");
}

test("decodes the README's example frame byte for byte", () => {
  const { header, image } = decodeFrame(exampleHexFrame());
  assert.equal(header.seq, 42);
  assert.equal(header.request, 17);
  assert.equal(header.level, 2);
  assert.equal(header.codec, "png");
  assert.equal(header.final, true);
  assert.deepEqual([header.width, header.height], [4, 2]);
  assert.deepEqual(header.error, { method: "rmse_vs_next_level", value: 0.0042 });
  assert.deepEqual(header.camera.eye, [0, 0, 5]);
  assert.deepEqual([...image], [0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a]);
});

test("decodes a frame given as a typed-array view with an offset", () => {
  const buf = exampleHexFrame();
  const padded = new Uint8Array(buf.byteLength + 3);
  padded.set(new Uint8Array(buf), 3);
  assert.equal(decodeFrame(padded.subarray(3)).header.seq, 42);
});

test("every malformed frame is refused with a FrameError naming the problem", () => {
  const good = new Uint8Array(exampleHexFrame());
  const cases = [
    [good.slice(0, 5), /shorter than the 8-byte preamble/],
    [Uint8Array.from([0x56, 0x43, 0x46, 0x32, ...good.slice(4)]), /bad magic "VCF2"/],
    [good.slice(0, 100), /truncated header/],
    [good.slice(0, good.length - 1), /image is 7 bytes, header says 8/],
    [Uint8Array.from([...good, 0]), /image is 9 bytes, header says 8/],
    [new Uint8Array(encodeFrame({ seq: 1, width: 1, height: 1, codec: "webp" })), /unknown codec "webp"/],
    [new Uint8Array(encodeFrame({ seq: -1, width: 1, height: 1, codec: "png" })), /header.seq/],
    ["not binary", /not binary data/],
  ];
  for (const [bytes, pattern] of cases) {
    assert.throws(() => decodeFrame(bytes), (e) => e instanceof FrameError && pattern.test(e.message), String(pattern));
  }
  // A header that is not JSON, and one absurdly long.
  const bad = new Uint8Array(8 + 3);
  bad.set([0x56, 0x43, 0x46, 0x31, 3, 0, 0, 0, 0x7b, 0x7b, 0x7b]);
  assert.throws(() => decodeFrame(bad), /header is not UTF-8 JSON/);
  const huge = new Uint8Array(8);
  huge.set([0x56, 0x43, 0x46, 0x31, 0, 0, 0, 1]);
  assert.throws(() => decodeFrame(huge), /header of 16777216 bytes is over/);
});

test("a frame header's error estimate is kept only when it has a finite value", () => {
  const f = (error) => decodeFrame(encodeFrame({ seq: 1, width: 1, height: 1, codec: "jpeg", error })).header.error;
  assert.equal(f(null), null);
  assert.equal(f({ method: "x" }), null);
  assert.deepEqual(f({ value: 0.01, method: "calibrated_vs_reference" }), { value: 0.01, method: "calibrated_vs_reference" });
});

test("every server line of the README's example session parses", () => {
  let count = 0;
  for (const line of exampleSession()) {
    if (!line.startsWith("S: {")) continue;
    const msg = parseServerMessage(line.slice(3));
    assert.equal(typeof msg.type, "string");
    assert.ok("id" in msg);
    count++;
  }
  assert.ok(count >= 8, `found ${count} server messages`);
});

test("the README's client lines are what the request builders write", () => {
  const lines = exampleSession().filter((l) => l.startsWith("C: {")).map((l) => JSON.parse(l.slice(3)));
  const built = {
    list_volumes: () => requests.listVolumes(),
    open_volume: (m) => requests.openVolume(m.name),
    camera: (m) => requests.camera(m.camera),
    interaction_start: () => requests.interactionStart(),
    interaction_end: () => requests.interactionEnd(),
    viewport: (m) => requests.viewport(m.image.width, m.image.height),
    transfer_function: (m) => requests.transferFunction(m.transfer_function),
    clip_planes: (m) => requests.clipPlanes(m.clip_planes),
    get_state: () => requests.getState(),
    still: (m) => requests.still(m.image),
    close: () => requests.close(),
    hello: (m) => requests.hello({ client: m.client }),
    quality_policy: (m) => (m.mode === "explicit" ? requests.qualityExplicit(m.quality)
      : requests.qualityAutomatic(m.target_frame_ms, m.quality)),
  };
  let checked = 0;
  for (const line of lines) {
    const make = built[line.type];
    if (!make || typeof line.camera === "string") continue;   // "rotate" and the refused string camera
    const { id, ...fields } = line;
    assert.deepEqual(make(fields), fields, line.type);
    checked++;
  }
  assert.ok(checked >= 12, `checked ${checked} client lines`);
});

test("hello speaks version 1 and sends a token only when there is one", () => {
  assert.equal(PROTOCOL_VERSION, 1);
  assert.deepEqual(requests.hello({ client: "t" }), { type: "hello", protocol: 1, client: "t" });
  assert.equal(requests.hello({ client: "t", token: "s3cret" }).token, "s3cret");
});

test("server messages: lenient in, refusing only non-messages", () => {
  const m = parseServerMessage('{"type":"volumes","volumes":[],"future_field":1}');
  assert.equal(m.id, null);
  assert.equal(m.future_field, 1);
  assert.equal(parseServerMessage('{"type":"brand_new","id":3}').type, "brand_new");
  const e = parseServerMessage('{"type":"error","id":2}');
  assert.equal(e.code, "internal");
  assert.match(e.message, /no message/);
  assert.equal(parseServerMessage('{"type":"progress","fraction":7}').fraction, 1);
  for (const bad of ["nope", "[1]", '"x"', '{"type":3}', "{}"]) {
    assert.throws(() => parseServerMessage(bad), MessageError, bad);
  }
});

test("scene-changing requests and replies are the README's lists", () => {
  assert.deepEqual([...SCENE_CHANGING].sort(),
    ["camera", "clip_planes", "open_volume", "quality_policy", "still", "transfer_function", "viewport"]);
  assert.deepEqual(REPLY_TYPE, { hello: "hello", list_volumes: "volumes", open_volume: "state", get_state: "state", find_studies: "studies",
    probe: "probe", roi_stats: "roi_stats", pick: "pick" });
  // The README's transfer_function row lists the presets the server knows.
  for (const { name } of TF_PRESETS) assert.ok(readme.includes(`\`${name}\``), name);
});

test("PSNR is 20·log10(1/RMSE)", () => {
  assert.equal(psnrOf(0.1), 20);
  assert.equal(psnrOf(0.001), 60);
  assert.equal(psnrOf(0), Infinity);
});
