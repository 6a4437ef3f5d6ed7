// core/session.js over a fake server: the first volume opens by itself, progress and
// errors reach the page, and after the server restarts the same view comes back.
import { test, beforeEach } from "node:test";
import assert from "node:assert/strict";

import { Session, chooseInitialVolume } from "../../../web/core/session.js";
import { FakeTimers, FakeWebSocket, encodeFrame, flush } from "../lib/fakes.mjs";

let timers;
beforeEach(() => { FakeWebSocket.reset(); timers = new FakeTimers(); });

const demoVolume = { name: "builtin:demo", loaded: true, dims: [64, 64, 64], spacing: [1, 1, 1], origin: [0, 0, 0], value_range: [0, 255] };
const startCamera = { eye: [200, 200, 200], target: [31.5, 31.5, 31.5], up: [0, 1, 0], projection: "perspective", fov_y_deg: 30 };

function make(options = {}) {
  const s = new Session("ws://test/ws", {
    WebSocket: FakeWebSocket, setTimeout: timers.setTimeout, clearTimeout: timers.clearTimeout,
    now: timers.now, random: () => 0.5, ...options,
  });
  const events = [];
  for (const type of ["volumes", "progress", "loading", "state", "frame", "server_error", "protocol_error"]) {
    s.on(type, (p) => events.push([type, p]));
  }
  return { s, events };
}

// Play volcast-server for one connection: hello, the volume list, and open_volume.
async function serve(ws, { volumes = [demoVolume, { name: "bonsai", loaded: false }] } = {}) {
  ws.handshake();
  await flush();
  const list = ws.lastSent("list_volumes");
  ws.serverSend({ type: "volumes", id: list.id, volumes });
  await flush();
}

function answerOpen(ws, volume = demoVolume, camera = startCamera) {
  const open = ws.lastSent("open_volume");
  ws.serverSend({ type: "progress", id: open.id, volume: open.name, stage: "loading", fraction: 0.5 });
  ws.serverSend({
    type: "state", id: open.id, volume, interacting: false,
    scene: { volume: volume.name, transfer_function: { preset: "micro_ct" }, camera, image: { width: 512, height: 512 } },
    quality_policy: { mode: "automatic", target_frame_ms: 40 },
  });
  return open;
}

test("the initial volume: the one asked for, else the server's loaded one, else none", () => {
  assert.equal(chooseInitialVolume([demoVolume], "bonsai"), "bonsai");
  assert.equal(chooseInitialVolume([{ name: "a", loaded: false }, demoVolume]), "builtin:demo");
  assert.equal(chooseInitialVolume([{ name: "a", loaded: false }]), null);
});

test("once connected it lists volumes, sends the viewport and opens the loaded volume", async () => {
  const { s, events } = make();
  s.setViewport(640.4, 479.6);     // before connecting: kept and sent once ready
  s.start();
  const ws = FakeWebSocket.last;
  await serve(ws);
  assert.deepEqual(ws.types(), ["hello", "list_volumes", "viewport", "open_volume"]);
  assert.deepEqual(ws.lastSent("viewport").image, { width: 640, height: 480 });
  assert.equal(ws.lastSent("open_volume").name, "builtin:demo");
  assert.deepEqual(s.loading, { name: "builtin:demo" });
  const open = answerOpen(ws);
  await flush();
  assert.equal(s.loading, null);
  assert.equal(s.volume.name, "builtin:demo");
  assert.deepEqual(s.scene.camera, startCamera);
  assert.deepEqual(s.scene.image, { width: 640, height: 480 }, "our viewport wins over the state's");
  const progress = events.find(([t]) => t === "progress")[1];
  assert.equal(progress.fraction, 0.5);

  // Frames carry their latency.
  timers.advance(30);
  ws.serverSend(encodeFrame({ seq: 1, request: open.id, level: 0, width: 320, height: 240, codec: "jpeg", final: false }));
  const frame = events.find(([t]) => t === "frame")[1];
  assert.equal(frame.latency, 30);
  assert.equal(s.lastFrame.header.seq, 1);
});

test("an unknown volume: the server's error reaches the page and the old volume stays", async () => {
  const { s, events } = make();
  s.start();
  const ws = FakeWebSocket.last;
  await serve(ws);
  answerOpen(ws);
  await flush();
  const result = s.openVolume("no/such/volume.nrrd");
  const open = ws.lastSent("open_volume");
  ws.serverSend({ type: "error", id: open.id, code: "not_found", message: "no volume named \"no/such/volume.nrrd\"", request_type: "open_volume" });
  assert.equal(await result, null);
  const err = events.find(([t]) => t === "server_error")[1];
  assert.equal(err.code, "not_found");
  assert.match(err.message, /no\/such\/volume\.nrrd/);
  assert.equal(s.wantedVolume, "builtin:demo");
  assert.equal(s.loading, null);
});

test("a series of several stacks: the error reaches the page with each stack's name to open", async () => {
  const { s, events } = make();
  s.start();
  const ws = FakeWebSocket.last;
  await serve(ws);
  answerOpen(ws);
  await flush();
  const result = s.openVolume("ct/series");
  const open = ws.lastSent("open_volume");
  const stacks = [
    { volume: "ct/series#stack=1", slices: 120, rows: 512, columns: 512, orientation: "axial", localizer: false },
    { volume: "ct/series#stack=2", slices: 1, rows: 256, columns: 256, orientation: "coronal", localizer: true },
  ];
  ws.serverSend({ type: "error", id: open.id, code: "load_failed", message: "ct/series: the series holds a localizer", request_type: "open_volume", stacks });
  assert.equal(await result, null);
  const err = events.find(([t]) => t === "server_error")[1];
  assert.deepEqual(err.stacks, stacks);
  assert.equal(s.wantedVolume, "builtin:demo", "nothing is opened unasked");
});

test("scene changes wait for a volume; interaction start/end are sent once each", async () => {
  const { s } = make();
  s.start();
  const ws = FakeWebSocket.last;
  await serve(ws, { volumes: [{ name: "bonsai", loaded: false }] });   // nothing loaded: nothing opens
  assert.equal(ws.lastSent("open_volume"), undefined);
  s.setCamera(startCamera);
  assert.equal(ws.lastSent("camera"), undefined, "camera before a volume would be bad_state");
  s.beginInteraction();
  s.beginInteraction();
  s.endInteraction();
  s.endInteraction();
  assert.deepEqual(ws.types().filter((t) => t.startsWith("interaction")), ["interaction_start", "interaction_end"]);
  s.setQualityPolicy({ mode: "explicit", quality: { step: 0.25 } });
  assert.deepEqual(ws.lastSent("quality_policy"), { type: "quality_policy", mode: "explicit", quality: { step: 0.25 }, id: ws.sent.length });
});

test("after the server restarts, the same volume and view come back", async () => {
  const { s } = make();
  s.setViewport(800, 600);
  s.start();
  let ws = FakeWebSocket.last;
  await serve(ws);
  answerOpen(ws);
  await flush();
  const moved = { ...startCamera, eye: [300, 100, 50] };
  const tf = { points: [[0, 0, 0, 0, 0], [255, 1, 1, 1, 0.5]] };
  const planes = [{ point: [31.5, 31.5, 31.5], normal: [0, 0, 1] }];
  s.setQualityPolicy({ mode: "automatic", target_frame_ms: 80 });
  s.setTransferFunction(tf);
  s.setClipPlanes(planes);
  s.setCamera(moved);

  ws.serverClose(1001, "server shutting down (SIGTERM)");
  assert.equal(s.connection.state, "waiting");
  timers.advance(timers.pending[0]);
  ws = FakeWebSocket.last;
  await serve(ws);
  assert.deepEqual(ws.types(), ["hello", "list_volumes", "viewport", "quality_policy", "open_volume"]);
  answerOpen(ws);     // the restarted server's starting view
  await flush();
  assert.deepEqual(ws.types().slice(5), ["transfer_function", "clip_planes", "camera"]);
  assert.deepEqual(ws.lastSent("camera").camera, moved);
  assert.deepEqual(ws.lastSent("transfer_function").transfer_function, tf);
  assert.deepEqual(ws.lastSent("clip_planes").clip_planes, planes);
  assert.equal(ws.lastSent("quality_policy").target_frame_ms, 80);
  assert.deepEqual(s.scene.camera, moved);
});

test("the saved scene is the server's, with the final frame's quality, size and camera", async () => {
  const { s } = make();
  s.start();
  const ws = FakeWebSocket.last;
  await serve(ws);
  const open = answerOpen(ws);
  await flush();
  const quality = { step: 0.5, jitter: false, preintegrated: false, interpolation: "linear", boundary_segment: true,
    early_termination: 0.99, empty_space_skipping: true, mip_level: 0, image_scale: 1, shading: false, seed: 0 };
  ws.serverSend(encodeFrame({ seq: 3, request: open.id, level: 2, quality, width: 512, height: 512, codec: "png", final: true, camera: startCamera }));
  const saving = s.sceneFile();
  const get = ws.lastSent("get_state");
  ws.serverSend({
    type: "state", id: get.id, volume: demoVolume, interacting: false, quality_policy: { mode: "automatic", target_frame_ms: 40 },
    scene: { volume: "builtin:demo", transfer_function: { preset: "micro_ct" }, camera: startCamera, image: { width: 512, height: 512 },
      quality: { ...quality, step: 0.25 }, clip_planes: [] },
  });
  const scene = await saving;
  assert.deepEqual(scene, {
    volume: "builtin:demo", transfer_function: { preset: "micro_ct" }, camera: startCamera,
    image: { width: 512, height: 512 }, quality,
  });
});

test("a frame the page cannot decode is reported, not thrown", async () => {
  const { s, events } = make();
  s.start();
  const ws = FakeWebSocket.last;
  await serve(ws);
  ws.serverSend(new Uint8Array([0x56, 0x43, 0x46, 0x31, 9, 0, 0, 0]).buffer);
  assert.match(events.find(([t]) => t === "protocol_error")[1].message, /truncated header/);
});

test("the server's DICOMweb sources come with the volume list, and a search resolves with its studies", async () => {
  const { s } = make({ autoOpen: false });
  const sources = [];
  s.on("sources", (list) => sources.push(list));
  s.start();
  const ws = FakeWebSocket.last;
  ws.handshake();
  await flush();
  ws.serverSend({ type: "volumes", id: ws.lastSent("list_volumes").id, volumes: [demoVolume],
    sources: [{ name: "orthanc", kind: "dicomweb" }, { kind: "dicomweb" }, null] });
  await flush();
  assert.deepEqual(sources, [[{ name: "orthanc", kind: "dicomweb" }]], "entries without a name are dropped");
  const query = { type: "find_studies", source: "orthanc", filters: { patient_name: "DOE*" }, limit: 100 };
  const answer = s.findStudies(query);
  const sent = ws.lastSent("find_studies");
  assert.deepEqual({ ...sent, id: undefined }, { ...query, id: undefined });
  ws.serverSend({ type: "studies", id: sent.id, source: "orthanc", studies: [{ study_uid: "1.2", series: [] }] });
  assert.deepEqual((await answer).studies, [{ study_uid: "1.2", series: [] }]);
  // A refusal rejects the search with the server's code, and is not also shown as a stray error.
  const errors = [];
  s.on("server_error", (e) => errors.push(e));
  const refused = s.findStudies({ ...query, source: "gone" });
  ws.serverSend({ type: "error", id: ws.lastSent("find_studies").id, code: "not_found", message: "no source gone", request_type: "find_studies" });
  await assert.rejects(refused, (e) => e.code === "not_found" && e.serverMessage === "no source gone");
  assert.deepEqual(errors, []);
});
