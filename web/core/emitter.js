// A minimal event emitter: on/off/emit. (EventTarget would do in browsers, but Node 18's
// lacks CustomEvent, and listeners here want plain payloads.)
export class Emitter {
  constructor() { this.listeners = new Map(); }

  on(type, fn) {
    if (!this.listeners.has(type)) this.listeners.set(type, new Set());
    this.listeners.get(type).add(fn);
    return () => this.off(type, fn);
  }

  off(type, fn) { this.listeners.get(type)?.delete(fn); }

  emit(type, payload) {
    for (const fn of [...(this.listeners.get(type) ?? [])]) fn(payload);
  }
}
