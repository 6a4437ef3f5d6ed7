// Stand-ins for the browser pieces core/ touches: a WebSocket whose server side the test
// plays, and timers the test advances by hand.

export class FakeWebSocket {
  static instances = [];
  static CONNECTING = 0;
  static OPEN = 1;
  static CLOSING = 2;
  static CLOSED = 3;

  constructor(url) {
    this.url = url;
    this.readyState = FakeWebSocket.CONNECTING;
    this.sent = [];            // parsed JSON of every text message the client sent
    this.binaryType = "blob";
    this.closedWith = null;    // {code, reason} when the client closed it
    FakeWebSocket.instances.push(this);
  }

  static reset() { FakeWebSocket.instances = []; }
  static get last() { return FakeWebSocket.instances[FakeWebSocket.instances.length - 1]; }

  // --- the client's side ---
  send(text) {
    if (this.readyState !== FakeWebSocket.OPEN) throw new Error("InvalidStateError: socket not open");
    if (typeof text !== "string") throw new Error("the client sends only text");
    this.sent.push(JSON.parse(text));
  }

  close(code = 1000, reason = "") {
    if (this.readyState === FakeWebSocket.CLOSED) return;
    this.closedWith = { code, reason };
    this.readyState = FakeWebSocket.CLOSED;
    // Browsers deliver close asynchronously; the connection must ignore a socket it dropped.
    queueMicrotask(() => this.onclose?.({ code, reason, wasClean: true }));
  }

  // --- the server's side (the test) ---
  serverOpen() {
    this.readyState = FakeWebSocket.OPEN;
    this.onopen?.({});
  }

  serverSend(message) {
    if (message instanceof ArrayBuffer || ArrayBuffer.isView(message)) this.onmessage?.({ data: message });
    else this.onmessage?.({ data: typeof message === "string" ? message : JSON.stringify(message) });
  }

  serverClose(code = 1006, reason = "") {
    this.readyState = FakeWebSocket.CLOSED;
    this.onerror?.({});
    this.onclose?.({ code, reason, wasClean: false });
  }

  lastSent(type) { return [...this.sent].reverse().find((m) => m.type === type); }
  types() { return this.sent.map((m) => m.type); }

  // Answer the client's hello like volcast-server.
  handshake(extra = {}) {
    this.serverOpen();
    const hello = this.lastSent("hello");
    this.serverSend({
      type: "hello", id: hello.id, protocol: 1, server: "volcast 0.1.0",
      device: { name: "fake", type: "cpu" },
      limits: { max_message_bytes: 65536, max_image_side: 16384, max_image_pixels: 67108864, max_volume_name_bytes: 1024 },
      ...extra,
    });
  }
}

// Manual timers: set/clear like setTimeout, advance(ms) runs what falls due.
export class FakeTimers {
  constructor() { this.t = 0; this.queue = []; this.nextHandle = 1; }
  now = () => this.t;
  setTimeout = (fn, ms) => { const h = this.nextHandle++; this.queue.push({ h, at: this.t + ms, fn }); return h; };
  clearTimeout = (h) => { this.queue = this.queue.filter((q) => q.h !== h); };
  get pending() { return this.queue.map((q) => q.at - this.t).sort((a, b) => a - b); }
  advance(ms) {
    const until = this.t + ms;
    for (;;) {
      this.queue.sort((a, b) => a.at - b.at);
      const next = this.queue[0];
      if (!next || next.at > until) break;
      this.queue.shift();
      this.t = next.at;
      next.fn();
    }
    this.t = until;
  }
}

// A binary frame as volcast-server writes it: "VCF1", uint32 LE header length, header, image.
export function encodeFrame(header, image = new Uint8Array([0x89, 0x50, 0x4e, 0x47])) {
  const h = new TextEncoder().encode(JSON.stringify({ ...header, image_bytes: image.length }));
  const out = new Uint8Array(8 + h.length + image.length);
  out.set([0x56, 0x43, 0x46, 0x31], 0);
  new DataView(out.buffer).setUint32(4, h.length, true);
  out.set(h, 8);
  out.set(image, 8 + h.length);
  return out.buffer;
}

export const flush = () => new Promise((resolve) => setImmediate(resolve));
