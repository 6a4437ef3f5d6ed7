// What the stats overlay shows, computed from frame headers and send times: frames per
// second, latency (request sent → first frame showing it), the current frame's level,
// timings and error estimate, and the error-against-time series of the current view.

export const FPS_WINDOW_MS = 1000;      // ms of frame arrivals averaged for frames per second
export const MAX_TRACKED_REQUESTS = 256; // send times kept for latency; older ones are dropped
export const MAX_SERIES_POINTS = 64;     // points kept in one view's error series

export class FrameStats {
  constructor() {
    this.sentAt = new Map();    // request id → ms it was sent
    this.arrivals = [];         // ms of recent frame arrivals
    this.latencyMs = null;      // of the latest request that got a frame
    this.last = null;           // latest frame header
    this.refineFrom = -Infinity; // ms the latest interaction_end was sent
    this.series = { request: undefined, startMs: 0, points: [] };
    this.frames = 0;
  }

  // A request went out (connection "sent" event).
  noteSent(message, at) {
    if (message.type === "interaction_end") this.refineFrom = at;
    if (message.id === undefined || message.id === null) return;
    this.sentAt.set(message.id, at);
    if (this.sentAt.size > MAX_TRACKED_REQUESTS) this.sentAt.delete(this.sentAt.keys().next().value);
  }

  // A frame arrived at time `at` (ms). Returns the latency it measured, or null when it is
  // not the first frame answering its request.
  noteFrame(header, at) {
    this.frames += 1;
    this.last = header;
    this.arrivals.push(at);
    while (this.arrivals.length && this.arrivals[0] < at - FPS_WINDOW_MS) this.arrivals.shift();

    let latency = null;
    const sent = this.sentAt.get(header.request);
    if (sent !== undefined) {
      latency = at - sent;
      this.latencyMs = latency;
      this.sentAt.delete(header.request);   // only the first frame measures latency
    }

    // A new series starts with each new view: another request, or refinement after a drag.
    const viewStart = Math.max(sent ?? -Infinity, this.refineFrom);
    const isNewView = header.request !== this.series.request
      || (Number.isFinite(viewStart) && viewStart > this.series.startMs);
    if (isNewView) {
      const start = Number.isFinite(viewStart) ? viewStart : at;
      this.series = { request: header.request, startMs: start, points: [] };
    }
    if (header.error) {
      // Passes at rest continue the view's series past its final frame (shown as final ones).
      const final = header.final || header.rest_pass > 0;
      this.series.points.push({ tMs: at - this.series.startMs, value: header.error.value, level: header.level, final });
      if (this.series.points.length > MAX_SERIES_POINTS) this.series.points.shift();
    }
    return latency;
  }

  // Frames per second: frames that arrived in the last FPS_WINDOW_MS before `now`.
  fps(now) {
    return (this.arrivals.filter((t) => t > now - FPS_WINDOW_MS && t <= now).length * 1000) / FPS_WINDOW_MS;
  }

  reset() {
    this.sentAt.clear();
    this.arrivals = [];
    this.latencyMs = null;
    this.last = null;
    this.series = { request: undefined, startMs: 0, points: [] };
  }
}
