// The connection to a volcast server: one WebSocket, the hello handshake, request ids and
// replies, and reconnection with back-off. An explicit state machine that refuses illegal
// transitions (noVNC's RFB does the same), so that a stray socket event cannot put the
// page into a state nobody designed.
//
//            connect()                open              server hello
//   idle ─────────────▶ connecting ─────────▶ handshaking ─────────▶ ready
//                          ▲   │ close/error        │ close              │ socket closed
//                  timer   │   ▼                    ▼                    ▼
//                        waiting ◀────────────────────────────────────────
//   While waiting out a back-off longer than PROBE_INTERVAL_MS, a cheap GET of /healthz
//   every PROBE_INTERVAL_MS notices a server that answers again and connects at once.
//   failed: the server refused us for good (unauthorized, unsupported_version); no retry.
//   closed: close() was called; nothing reconnects.

import {
  FATAL_ERROR_CODES, MessageError, REPLY_TYPE, ServerError, decodeFrame, decodeSlice, isSliceMessage,
  parseServerMessage, requests,
} from "./protocol.js";
import { Emitter } from "./emitter.js";

export const STATES = Object.freeze({
  idle: "idle",
  connecting: "connecting",
  handshaking: "handshaking",
  ready: "ready",
  waiting: "waiting",
  failed: "failed",
  closed: "closed",
});

const TRANSITIONS = Object.freeze({
  idle: ["connecting", "closed"],
  connecting: ["handshaking", "waiting", "failed", "closed"],
  handshaking: ["ready", "waiting", "failed", "closed"],
  ready: ["waiting", "failed", "closed"],
  waiting: ["connecting", "closed"],
  failed: ["connecting", "closed"],
  closed: ["connecting"],
});

export class IllegalTransition extends Error {
  constructor(from, to) { super(`connection: illegal transition ${from} → ${to}`); this.name = "IllegalTransition"; }
}

export class ConnectionLost extends Error {
  constructor(reason) { super(`connection lost: ${reason}`); this.name = "ConnectionLost"; }
}

// Exponential back-off with jitter: attempt n (0-based) waits
// min(max, initial · factor^n) · (1 ± jitter).
export const BACKOFF_DEFAULTS = Object.freeze({
  initialMs: 250,        // ms, first retry
  factor: 2,
  maxMs: 8000,           // ms, ceiling between WebSocket attempts (the probe below finds a restarted server sooner)
  jitter: 0.2,           // ±20 %, so that many tabs do not retry in step
});

// The probe: one small HTTP request at a time, at most one per PROBE_INTERVAL_MS (a dead
// server costs a refused TCP connection twice a second per tab), so that a restarted server
// is found within PROBE_INTERVAL_MS + one round trip of answering again, well inside 1 s.
export const PROBE_INTERVAL_MS = 500;

// The server's /healthz beside its WebSocket address. `no-cors`: a page served by another
// origin cannot read the answer, but any answer at all means the server is back.
export function healthUrl(wsUrl) {
  const u = new URL(wsUrl);
  u.protocol = u.protocol === "wss:" ? "https:" : "http:";
  u.pathname = u.pathname.replace(/[^/]*$/, "healthz");   // behind a proxy prefix too
  u.search = "";
  u.hash = "";
  return u.href;
}

export function fetchProbe(wsUrl, fetchFn = globalThis.fetch) {
  const url = healthUrl(wsUrl);
  return () => fetchFn(url, { mode: "no-cors", cache: "no-store", signal: AbortSignal.timeout(PROBE_INTERVAL_MS) })
    .then(() => true, () => false);
}

export function backoffDelay(attempt, options = BACKOFF_DEFAULTS, random = Math.random) {
  const { initialMs, factor, maxMs, jitter } = { ...BACKOFF_DEFAULTS, ...options };
  const base = Math.min(maxMs, initialMs * Math.pow(factor, Math.max(0, attempt)));
  return Math.max(0, Math.round(base * (1 + jitter * (2 * random() - 1))));
}

export const HANDSHAKE_TIMEOUT_MS = 10000;   // ms from socket open to the server's hello

// Events: "state" {state, previous, detail}, "hello" (server hello), "message" (any text
// message not consumed as a reply), "frame" {header, image}, "error" (a server error that
// answers no awaited request), "protocol_error" (undecodable input), "sent" {id, message, at}.
export class Connection extends Emitter {
  // url: ws:// or wss:// address. options: WebSocket (constructor), client (name for hello),
  // token, backoff (BACKOFF_DEFAULTS overrides), setTimeout/clearTimeout/now/random (tests),
  // probe (() => Promise<boolean>: does the server answer at all; null: no probing; default
  // fetchProbe(url) where fetch exists), probeIntervalMs.
  constructor(url, options = {}) {
    super();
    this.url = url;
    this.WebSocket = options.WebSocket ?? globalThis.WebSocket;
    this.clientName = options.client ?? "volcast-web";
    this.token = options.token;
    this.backoff = { ...BACKOFF_DEFAULTS, ...(options.backoff ?? {}) };
    this.timers = {
      set: options.setTimeout ?? ((fn, ms) => setTimeout(fn, ms)),
      clear: options.clearTimeout ?? ((h) => clearTimeout(h)),
    };
    this.now = options.now ?? (() => (globalThis.performance ?? Date).now());
    this.random = options.random ?? Math.random;
    this.probe = options.probe !== undefined ? options.probe : globalThis.fetch ? fetchProbe(url) : null;
    this.probeIntervalMs = options.probeIntervalMs ?? PROBE_INTERVAL_MS;
    this.probeTimer = null;
    this.probeInFlight = false;
    this.probeGeneration = 0;
    // Seen down: an attempt failed before its socket opened, or a probe got no answer. Only a
    // probe answered after that is news; a server that answers but refuses (busy) is left
    // to the back-off.
    this.serverSeenDown = false;
    this.state = STATES.idle;
    this.socket = null;
    this.serverHello = null;
    this.attempt = 0;          // failed attempts since the last successful hello
    this.retryAt = null;       // now() when the next attempt starts, while waiting
    this.nextId = 1;
    this.pending = new Map();  // id → {resolve, reject, type}
    this.retryTimer = null;
    this.handshakeTimer = null;
    this.lastCloseReason = "";
  }

  // --- state machine --------------------------------------------------------------------

  transition(to, detail = {}) {
    const from = this.state;
    if (!TRANSITIONS[from]?.includes(to)) throw new IllegalTransition(from, to);
    this.state = to;
    this.emit("state", { state: to, previous: from, ...detail });
  }

  get isReady() { return this.state === STATES.ready; }

  connect() {
    this.cancelRetry();
    this.transition(STATES.connecting, { attempt: this.attempt });
    let socket;
    try {
      socket = new this.WebSocket(this.url);
    } catch (e) {
      // A malformed URL throws synchronously: no server will ever answer it.
      this.transition(STATES.failed, { reason: `cannot open ${this.url}: ${e.message}` });
      return;
    }
    socket.binaryType = "arraybuffer";
    this.socket = socket;
    // Each handler ignores a socket that is no longer ours (an old one closing late).
    socket.onopen = () => { if (this.socket === socket) this.onOpen(); };
    socket.onmessage = (ev) => { if (this.socket === socket) this.onMessage(ev.data); };
    socket.onerror = () => { /* always followed by close, which carries the reason */ };
    socket.onclose = (ev) => { if (this.socket === socket) this.onClose(ev); };
  }

  // Close for good: no reconnection until connect() is called again.
  close() {
    this.cancelRetry();
    this.clearHandshakeTimer();
    const socket = this.socket;
    this.socket = null;
    if (socket) {
      if (this.state === STATES.ready) { try { this.rawSend(socket, { ...requests.close(), id: this.nextId++ }); } catch { /* closing anyway */ } }
      try { socket.close(1000, "client closed"); } catch { /* already closed */ }
    }
    this.rejectPending(new ConnectionLost("closed by the client"));
    if (this.state !== STATES.closed) this.transition(STATES.closed, { reason: "closed by the client" });
  }

  // Give up waiting and try now (the "retry now" button).
  retryNow() {
    if (this.state === STATES.waiting || this.state === STATES.failed) this.connect();
  }

  // --- sending --------------------------------------------------------------------------

  // Send a request; returns its id. Throws if not ready (hello is sent by the handshake).
  send(message) {
    if (this.state !== STATES.ready) throw new ConnectionLost(`not connected (${this.state})`);
    const id = this.nextId++;
    this.rawSend(this.socket, { ...message, id });
    return id;
  }

  // Send a request that has a reply (REPLY_TYPE) and resolve with it; rejects with
  // ServerError when the server answers with an error, ConnectionLost when the socket goes.
  request(message) {
    if (!REPLY_TYPE[message.type]) throw new Error(`${message.type} has no reply; use send()`);
    const id = this.send(message);
    return new Promise((resolve, reject) => this.pending.set(id, { resolve, reject, type: message.type }));
  }

  rawSend(socket, message) {
    socket.send(JSON.stringify(message));
    this.emit("sent", { id: message.id, message, at: this.now() });
  }

  // --- socket events --------------------------------------------------------------------

  onOpen() {
    this.transition(STATES.handshaking);
    const id = this.nextId++;
    this.pending.set(id, {
      type: "hello",
      resolve: (hello) => this.onHello(hello),
      // A refusal for good fails; `busy` and the like are retried. A lost socket is
      // handled by onClose, which also rejects this waiter.
      reject: (err) => {
        if (!(err instanceof ServerError)) return;
        if (FATAL_ERROR_CODES.includes(err.code)) this.fail(err);
        else this.dropSocket(err.message);
      },
    });
    this.rawSend(this.socket, { ...requests.hello({ client: this.clientName, token: this.token }), id });
    this.handshakeTimer = this.timers.set(() => {
      this.handshakeTimer = null;
      this.dropSocket(`no hello from the server within ${HANDSHAKE_TIMEOUT_MS} ms`);
    }, HANDSHAKE_TIMEOUT_MS);
  }

  onHello(hello) {
    this.clearHandshakeTimer();
    this.serverHello = hello;
    this.attempt = 0;
    this.serverSeenDown = false;
    this.transition(STATES.ready, { hello });
    this.emit("hello", hello);
  }

  onMessage(data) {
    if (typeof data !== "string" && isSliceMessage(data)) {
      // The answer to a `slice` request (app/slice_views.js); never a 3D frame.
      try { this.emit("slice", decodeSlice(data)); } catch (e) { this.emit("protocol_error", e); }
      return;
    }
    if (typeof data !== "string") {
      let frame;
      try {
        frame = decodeFrame(data);
      } catch (e) {
        this.emit("protocol_error", e);
        return;
      }
      frame.receivedAt = this.now();
      this.emit("frame", frame);
      return;
    }
    let msg;
    try {
      msg = parseServerMessage(data);
    } catch (e) {
      this.emit("protocol_error", e instanceof MessageError ? e : new MessageError(String(e)));
      return;
    }
    const waiter = msg.id !== null ? this.pending.get(msg.id) : undefined;
    if (msg.type === "error") {
      if (waiter) {
        this.pending.delete(msg.id);
        waiter.reject(new ServerError(msg));
      } else {
        this.emit("error", msg);
      }
      if (FATAL_ERROR_CODES.includes(msg.code) && !waiter) this.fail(new ServerError(msg));
      return;
    }
    if (waiter && REPLY_TYPE[waiter.type] === msg.type) {
      this.pending.delete(msg.id);
      waiter.resolve(msg);
      // The reply is also a message (a `state` updates whoever shows the scene).
    }
    this.emit("message", msg);
  }

  onClose(ev) {
    if (this.state === STATES.connecting) this.serverSeenDown = true;
    this.socket = null;
    this.clearHandshakeTimer();
    const reason = ev?.reason || (ev?.code ? `WebSocket closed (code ${ev.code})` : "WebSocket closed");
    this.lastCloseReason = reason;
    this.rejectPending(new ConnectionLost(reason));
    if (this.state === STATES.failed || this.state === STATES.closed) return;
    this.scheduleRetry(reason);
  }

  // --- helpers --------------------------------------------------------------------------

  // The server refused us for good: stop and say why.
  fail(err) {
    this.clearHandshakeTimer();
    const socket = this.socket;
    this.socket = null;
    if (socket) { try { socket.close(1000, "refused"); } catch { /* already closed */ } }
    this.rejectPending(new ConnectionLost(err.message));
    if (this.state !== STATES.failed && this.state !== STATES.closed) {
      this.transition(STATES.failed, { reason: err.message, code: err.code });
    }
  }

  // Give up on the current socket and schedule a retry.
  dropSocket(reason) {
    this.clearHandshakeTimer();
    const socket = this.socket;
    this.socket = null;
    if (socket) { try { socket.close(4000, reason.slice(0, 100)); } catch { /* already closed */ } }
    this.rejectPending(new ConnectionLost(reason));
    this.scheduleRetry(reason);
  }

  scheduleRetry(reason) {
    const delay = backoffDelay(this.attempt, this.backoff, this.random);
    this.attempt += 1;
    this.retryAt = this.now() + delay;
    this.transition(STATES.waiting, { reason, delayMs: delay, attempt: this.attempt });
    this.retryTimer = this.timers.set(() => {
      this.retryTimer = null;
      this.retryAt = null;
      if (this.state === STATES.waiting) this.connect();
    }, delay);
    if (this.probe && delay > this.probeIntervalMs) this.scheduleProbe();
  }

  // A chain of probes for one waiting period; cancelRetry() ends it (its generation).
  scheduleProbe() {
    const generation = this.probeGeneration;
    this.probeTimer = this.timers.set(() => {
      this.probeTimer = null;
      if (this.state !== STATES.waiting || generation !== this.probeGeneration) return;
      if (this.probeInFlight) { this.scheduleProbe(); return; }   // one at a time: an older one still out
      this.probeInFlight = true;
      Promise.resolve().then(() => this.probe()).catch(() => false).then((answered) => {
        this.probeInFlight = false;
        if (this.state !== STATES.waiting || generation !== this.probeGeneration) return;
        if (!answered) this.serverSeenDown = true;
        else if (this.serverSeenDown) { this.serverSeenDown = false; this.connect(); return; }
        this.scheduleProbe();
      });
    }, this.probeIntervalMs);
  }

  cancelRetry() {
    if (this.retryTimer !== null) this.timers.clear(this.retryTimer);
    this.retryTimer = null;
    this.retryAt = null;
    if (this.probeTimer !== null) this.timers.clear(this.probeTimer);
    this.probeTimer = null;
    this.probeGeneration += 1;
  }

  clearHandshakeTimer() {
    if (this.handshakeTimer !== null) this.timers.clear(this.handshakeTimer);
    this.handshakeTimer = null;
  }

  rejectPending(err) {
    const waiters = [...this.pending.values()];
    this.pending.clear();
    for (const w of waiters) w.reject(err);
  }
}

// The WebSocket address of the server that served this page: same host and port, /ws.
export function defaultServerUrl(location) {
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  return `${scheme}//${location.host}/ws`;
}
