// core/connection.js: the state machine, the handshake, replies and errors, and
// reconnection with back-off, over a fake WebSocket with hand-advanced timers.
import { test, beforeEach } from "node:test";
import assert from "node:assert/strict";

import {
  BACKOFF_DEFAULTS, Connection, ConnectionLost, HANDSHAKE_TIMEOUT_MS, IllegalTransition, PROBE_INTERVAL_MS, STATES,
  backoffDelay, defaultServerUrl, healthUrl,
} from "../../../web/core/connection.js";
import { ServerError } from "../../../web/core/protocol.js";
import { FakeTimers, FakeWebSocket, encodeFrame, flush } from "../lib/fakes.mjs";

let timers;
beforeEach(() => { FakeWebSocket.reset(); timers = new FakeTimers(); });

// random() = 0.5 makes the jitter term zero: delays are exactly initial · factor^n.
function make(options = {}) {
  const c = new Connection("ws://test/ws", {
    WebSocket: FakeWebSocket, setTimeout: timers.setTimeout, clearTimeout: timers.clearTimeout,
    now: timers.now, random: () => 0.5, client: "unit", probe: null, ...options,
  });
  const states = [];
  c.on("state", (s) => states.push(s.state));
  return { c, states };
}

test("connect, hello, ready: the handshake sends protocol 1 and waits for the server's hello", () => {
  const { c, states } = make();
  c.connect();
  const ws = FakeWebSocket.last;
  assert.equal(ws.url, "ws://test/ws");
  assert.equal(ws.binaryType, "arraybuffer");
  assert.equal(c.state, STATES.connecting);
  ws.serverOpen();
  assert.equal(c.state, STATES.handshaking);
  assert.deepEqual(ws.sent, [{ type: "hello", protocol: 1, client: "unit", id: 1 }]);
  assert.throws(() => c.send({ type: "list_volumes" }), ConnectionLost, "nothing but hello before the answer");
  ws.serverSend({ type: "hello", id: 1, protocol: 1, server: "volcast 0.1.0", device: { name: "d", type: "gpu" }, limits: {} });
  assert.equal(c.state, STATES.ready);
  assert.equal(c.serverHello.server, "volcast 0.1.0");
  assert.deepEqual(states, ["connecting", "handshaking", "ready"]);
  assert.equal(timers.queue.length, 0, "the handshake timeout is cleared");
});

test("illegal transitions are refused", () => {
  const { c } = make();
  assert.throws(() => c.transition(STATES.ready), IllegalTransition);
  assert.throws(() => c.transition(STATES.handshaking), /idle → handshaking/);
  c.connect();
  assert.throws(() => c.connect(), /connecting → connecting/, "a second connect while connecting");
  assert.equal(c.state, STATES.connecting, "a refused transition changes nothing");
});

test("requests resolve with their reply, or reject with the server's error", async () => {
  const { c } = make();
  c.connect();
  const ws = FakeWebSocket.last;
  ws.handshake();
  const list = c.request({ type: "list_volumes" });
  const open = c.request({ type: "open_volume", name: "nope" });
  const [l, o] = ws.sent.slice(-2);
  assert.deepEqual(l, { type: "list_volumes", id: 2 });
  assert.deepEqual(o, { type: "open_volume", name: "nope", id: 3 });
  ws.serverSend({ type: "error", id: 3, code: "not_found", message: "no volume \"nope\"", request_type: "open_volume" });
  ws.serverSend({ type: "volumes", id: 2, volumes: [{ name: "bonsai", loaded: true }] });
  assert.equal((await list).volumes[0].name, "bonsai");
  await assert.rejects(open, (e) => e instanceof ServerError && e.code === "not_found" && e.requestType === "open_volume");
  assert.throws(() => c.request({ type: "camera", camera: {} }), /has no reply/);
});

test("errors that answer no awaited request are events; progress and state are messages", () => {
  const { c } = make();
  const errors = [], messages = [];
  c.on("error", (e) => errors.push(e));
  c.on("message", (m) => messages.push(m.type));
  c.connect();
  const ws = FakeWebSocket.last;
  ws.handshake();
  const id = c.send({ type: "camera", camera: "front" });
  ws.serverSend({ type: "error", id, code: "bad_field", message: "camera: must be a JSON object, got a string", request_type: "camera" });
  ws.serverSend({ type: "progress", id: null, volume: "v", stage: "preprocessing", fraction: 0.5 });
  ws.serverSend("this is not JSON");
  assert.equal(errors.length, 1);
  assert.equal(errors[0].code, "bad_field");
  assert.deepEqual(messages, ["hello", "progress"]);
  assert.equal(c.state, STATES.ready, "a bad message from the server does not drop the connection");
});

test("frames are decoded and timestamped; undecodable ones are protocol errors", () => {
  const { c } = make();
  const frames = [], problems = [];
  c.on("frame", (f) => frames.push(f));
  c.on("protocol_error", (e) => problems.push(e.message));
  c.connect();
  const ws = FakeWebSocket.last;
  ws.handshake();
  timers.advance(5);
  ws.serverSend(encodeFrame({ seq: 1, request: null, level: 0, width: 2, height: 2, codec: "jpeg", final: false }));
  ws.serverSend(new Uint8Array([1, 2, 3]).buffer);
  assert.equal(frames.length, 1);
  assert.equal(frames[0].header.seq, 1);
  assert.equal(frames[0].receivedAt, 5);
  assert.match(problems[0], /shorter than the 8-byte preamble/);
});

test("a lost connection rejects what was pending and reconnects with growing back-off", async () => {
  const { c, states } = make();
  c.connect();
  let ws = FakeWebSocket.last;
  ws.handshake();
  const pending = c.request({ type: "get_state" });
  ws.serverClose(1006);
  await assert.rejects(pending, ConnectionLost);
  assert.equal(c.state, STATES.waiting);

  // The server stays away: each attempt waits twice as long, up to the ceiling.
  const delays = [];
  for (let attempt = 0; attempt < 8; attempt++) {
    const [delay] = timers.pending;
    delays.push(delay);
    timers.advance(delay);
    assert.equal(c.state, STATES.connecting);
    FakeWebSocket.last.serverClose(1006);   // refused again
  }
  assert.deepEqual(delays, [250, 500, 1000, 2000, 4000, 8000, 8000, 8000]);

  // It comes back: the next attempt succeeds and the back-off starts over.
  timers.advance(timers.pending[0]);
  ws = FakeWebSocket.last;
  ws.handshake();
  assert.equal(c.state, STATES.ready);
  ws.serverClose(1001, "server shutting down (SIGTERM)");
  assert.equal(timers.pending[0], BACKOFF_DEFAULTS.initialMs);
  assert.equal(c.lastCloseReason, "server shutting down (SIGTERM)");
  assert.ok(states.filter((s) => s === "ready").length === 2);
});

test("back-off jitter stays within ±20 % and never exceeds the ceiling by more", () => {
  for (let attempt = 0; attempt < 12; attempt++) {
    const base = Math.min(BACKOFF_DEFAULTS.maxMs, BACKOFF_DEFAULTS.initialMs * 2 ** attempt);
    assert.equal(backoffDelay(attempt, {}, () => 0), Math.round(base * 0.8));
    assert.equal(backoffDelay(attempt, {}, () => 1), Math.round(base * 1.2));
  }
});

test("unauthorized fails for good: no retry until connect() is called again", async () => {
  const { c, states } = make({ token: "wrong" });
  c.connect();
  const ws = FakeWebSocket.last;
  ws.serverOpen();
  assert.equal(ws.sent[0].token, "wrong");
  ws.serverSend({ type: "error", id: ws.sent[0].id, code: "unauthorized", message: "wrong token", request_type: "hello" });
  ws.serverClose(1008, "unauthorized");
  await flush();
  assert.equal(c.state, STATES.failed);
  assert.deepEqual(timers.pending, [], "nothing scheduled");
  assert.deepEqual(states, ["connecting", "handshaking", "failed"]);
  c.connect();
  assert.equal(c.state, STATES.connecting);
});

test("busy during the handshake is retried, not fatal", () => {
  const { c } = make();
  c.connect();
  const ws = FakeWebSocket.last;
  ws.serverOpen();
  ws.serverSend({ type: "error", id: 1, code: "busy", message: "16 sessions already", request_type: "hello" });
  assert.equal(c.state, STATES.waiting);
  assert.equal(ws.closedWith.code, 4000);
  assert.equal(timers.pending.length, 1);
});

test("a server that opens the socket but never says hello is dropped and retried", () => {
  const { c } = make();
  c.connect();
  FakeWebSocket.last.serverOpen();
  timers.advance(HANDSHAKE_TIMEOUT_MS - 1);
  assert.equal(c.state, STATES.handshaking);
  timers.advance(1);
  assert.equal(c.state, STATES.waiting);
  assert.equal(FakeWebSocket.instances.length, 1);
  timers.advance(timers.pending[0]);
  assert.equal(FakeWebSocket.instances.length, 2);
});

test("close() says close, stops reconnecting and ignores the old socket's late events", async () => {
  const { c, states } = make();
  c.connect();
  const ws = FakeWebSocket.last;
  ws.handshake();
  c.close();
  assert.equal(ws.lastSent("close").type, "close");
  assert.equal(ws.closedWith.code, 1000);
  await flush();                              // the fake delivers onclose late, as browsers do
  assert.equal(c.state, STATES.closed);
  assert.deepEqual(timers.pending, []);
  assert.deepEqual(states.slice(-1), ["closed"]);
  // close() while waiting cancels the retry.
  c.connect();
  FakeWebSocket.last.serverClose();
  assert.equal(c.state, STATES.waiting);
  c.close();
  assert.deepEqual(timers.pending, []);
});

test("retryNow skips the wait", () => {
  const { c } = make();
  c.connect();
  FakeWebSocket.last.serverClose();
  assert.equal(c.state, STATES.waiting);
  c.retryNow();
  assert.equal(c.state, STATES.connecting);
  assert.deepEqual(timers.pending, [], "the scheduled retry is cancelled");
});

test("the default address is the page's own host at /ws", () => {
  assert.equal(defaultServerUrl({ protocol: "http:", host: "127.0.0.1:8080" }), "ws://127.0.0.1:8080/ws");
  assert.equal(defaultServerUrl({ protocol: "https:", host: "viewer.example" }), "wss://viewer.example/ws");
});

// A server that the test switches on and off, seen through the probe (its /healthz): a
// connection attempt while it is off fails before the socket opens, as a refused TCP
// connection does.
function probedServer() {
  const server = { up: false, probes: [], inFlight: 0, maxInFlight: 0 };
  server.probe = () => {
    server.probes.push(timers.now());
    server.inFlight += 1;
    server.maxInFlight = Math.max(server.maxInFlight, server.inFlight);
    const answer = server.up;
    return new Promise((resolve) => timers.setTimeout(() => { server.inFlight -= 1; resolve(answer); }, 5));
  };
  return server;
}

// Advance the fake clock in small steps, letting promise callbacks run between them.
async function advanceAsync(ms, step = 5) {
  for (let t = 0; t < ms; t += step) { timers.advance(step); await flush(); }
}

test("a restarted server is found within 1 s of answering again, however long it was away", async () => {
  for (const downMs of [3000, 20000, 120000]) {
    FakeWebSocket.reset();
    timers = new FakeTimers();
    const server = probedServer();
    const { c } = make({ probe: server.probe });
    c.connect();
    FakeWebSocket.last.handshake();
    FakeWebSocket.last.serverClose(1001, "server shutting down");
    // Every attempt while it is down fails before its socket opens.
    const refuse = () => { const ws = FakeWebSocket.last; if (ws.readyState === FakeWebSocket.CONNECTING && !ws.closedWith) ws.serverClose(1006); };
    for (let t = 0; t < downMs; t += 50) { await advanceAsync(50); refuse(); }
    assert.equal(c.state, STATES.waiting, `down ${downMs} ms: still waiting`);
    // Bounded: no more than one probe per interval, never two at once.
    assert.ok(server.probes.length <= downMs / PROBE_INTERVAL_MS + 1, `down ${downMs} ms: ${server.probes.length} probes`);
    assert.equal(server.maxInFlight, 1);
    const attemptsWhileDown = FakeWebSocket.instances.length;
    server.up = true;
    const upAt = timers.now();
    let readyAt = null;
    c.on("state", (s) => { if (s.state === STATES.connecting && readyAt === null) readyAt = timers.now(); });
    for (let t = 0; t < 2000 && readyAt === null; t += 5) await advanceAsync(5);
    assert.ok(readyAt !== null, `down ${downMs} ms: no attempt within 2 s of the server answering`);
    // Within the probe interval plus the probe's own 5 ms round trip (the fake's).
    assert.ok(readyAt - upAt <= PROBE_INTERVAL_MS + 10, `down ${downMs} ms: reconnected ${readyAt - upAt} ms after the server answered`);
    FakeWebSocket.last.handshake();
    assert.equal(c.state, STATES.ready);
    // The WebSocket attempts themselves kept their exponential back-off (8 s ceiling).
    assert.ok(attemptsWhileDown <= 7 + downMs / BACKOFF_DEFAULTS.maxMs / 0.8 + 1, `${attemptsWhileDown} WebSocket attempts in ${downMs} ms`);
    c.close();
  }
});

test("a server that answers but refuses (busy) is left to the back-off: the probe is no news", async () => {
  const server = probedServer();
  server.up = true;
  const { c } = make({ probe: server.probe });
  c.connect();
  // Each attempt opens and is told busy: the server is up all along.
  const busy = () => {
    const ws = FakeWebSocket.last;
    if (ws.readyState !== FakeWebSocket.CONNECTING || ws.closedWith) return;
    ws.serverOpen();
    ws.serverSend({ type: "error", id: ws.lastSent("hello").id, code: "busy", message: "16 sessions already", request_type: "hello" });
  };
  busy();
  for (let t = 0; t < 20000; t += 50) { await advanceAsync(50); busy(); }
  // 250 + 500 + 1000 + 2000 + 4000 + 8000 = 15750 ms: 7 attempts in 20 s, not one per probe.
  assert.equal(FakeWebSocket.instances.length, 7);
  assert.ok(server.probes.length > 10, "it did probe");
  c.close();
});

test("the probe asks /healthz beside the WebSocket address", () => {
  assert.equal(healthUrl("ws://127.0.0.1:8080/ws"), "http://127.0.0.1:8080/healthz");
  assert.equal(healthUrl("wss://example.org/volcast/ws?x=1"), "https://example.org/volcast/healthz");
});
