// The view: shows each frame as it arrives, scaled to the canvas (whose backing store is
// the CSS size times devicePixelRatio, so frames at device resolution stay sharp), and
// turns pointer, wheel and touch input into navigation steps, at most one per animation
// frame.

export const WHEEL_IDLE_MS = 250;     // ms without wheel or key events that end their "interaction"
export const KEY_STEP_PX = 20;        // CSS px of drag one arrow key stands for
export const RESIZE_SETTLE_MS = 150;  // ms a size must hold before the server is told
const WHEEL_LINE_PX = 16;             // px per wheel "line" (deltaMode 1)

export class View {
  // callbacks: onNavigate({kind: "orbit"|"pan"|"zoom"|"window_level", dx, dy, factor}),
  // onInteraction(active: boolean), onResize({cssWidth, cssHeight, dpr}), onReset().
  constructor(container, canvas, callbacks) {
    this.container = container;
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.cb = callbacks;
    this.bitmap = null;            // the frame on screen
    this.shownSeq = 0;             // its seq: a slower decode of an older frame never replaces it
    this.pointers = new Map();     // pointerId → {x, y}
    this.mode = null;              // "orbit" | "pan" | "window_level" | "pinch"
    this.pending = { dx: 0, dy: 0, factor: 1, kind: null };
    this.rafScheduled = false;
    this.wheelTimer = null;
    this.interacting = false;
    this.size = { cssWidth: 0, cssHeight: 0, dpr: 1 };
    this.resizeTimer = null;

    new ResizeObserver(() => this.measure()).observe(container);
    this.watchDevicePixelRatio();
    this.bindPointer();
    this.measure();
  }

  // --- size and device pixel ratio -----------------------------------------------------

  measure() {
    const r = this.container.getBoundingClientRect();
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(r.width * dpr)), h = Math.max(1, Math.round(r.height * dpr));
    if (this.canvas.width !== w || this.canvas.height !== h) {
      this.canvas.width = w;
      this.canvas.height = h;
      this.draw();
    }
    this.size = { cssWidth: r.width, cssHeight: r.height, dpr };
    clearTimeout(this.resizeTimer);
    this.resizeTimer = setTimeout(() => this.cb.onResize(this.size), RESIZE_SETTLE_MS);
  }

  // devicePixelRatio changes when the window moves to another screen or the page zooms.
  watchDevicePixelRatio() {
    const mq = window.matchMedia(`(resolution: ${window.devicePixelRatio || 1}dppx)`);
    mq.addEventListener("change", () => { this.measure(); this.watchDevicePixelRatio(); }, { once: true });
  }

  // --- frames ---------------------------------------------------------------------------

  // Decode and show a frame ({header, image}); returns false if a newer one is on screen.
  async show(frame) {
    const blob = new Blob([frame.image], { type: frame.header.codec === "png" ? "image/png" : "image/jpeg" });
    // No colour-space conversion: the pixels are the renderer's values, as volcast-render writes them.
    const bitmap = await createImageBitmap(blob, { colorSpaceConversion: "none" });
    if (frame.header.seq < this.shownSeq) { bitmap.close(); return false; }
    this.bitmap?.close();
    this.bitmap = bitmap;
    // The view the image fills: a level of fewer rays comes smaller than it (older servers
    // sent every frame at the view's size and no view_width).
    this.bitmapView = [frame.header.view_width ?? bitmap.width, frame.header.view_height ?? bitmap.height];
    this.shownSeq = frame.header.seq;
    this.draw();
    return true;
  }

  clear() {
    this.bitmap?.close();
    this.bitmap = null;
    this.shownSeq = 0;
    this.draw();
  }

  // Reset the ordering after a reconnection (seq starts again at 1 on a new session).
  resetSequence() { this.shownSeq = 0; }

  get hasImage() { return this.bitmap !== null; }

  // Draw the frame over black: the view it fills fitted to the canvas (the view is the
  // canvas's size unless it was resized since), the image stretched over that view. A frame
  // of fewer rays (image_scale < 1) is smaller than the view; its grid, rounded a side at a
  // time, need not have the view's aspect, so it is stretched to the view, not fitted.
  draw() {
    const { ctx, canvas } = this;
    ctx.fillStyle = "#000";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    if (!this.bitmap) return;
    const [vw, vh] = this.bitmapView;
    const s = Math.min(canvas.width / vw, canvas.height / vh);
    const w = vw * s, h = vh * s;
    ctx.imageSmoothingEnabled = true;
    ctx.imageSmoothingQuality = "high";
    ctx.drawImage(this.bitmap, (canvas.width - w) / 2, (canvas.height - h) / 2, w, h);
  }

  // --- input ----------------------------------------------------------------------------

  bindPointer() {
    const c = this.canvas;
    c.addEventListener("contextmenu", (e) => e.preventDefault());
    c.addEventListener("pointerdown", (e) => this.onPointerDown(e));
    c.addEventListener("pointermove", (e) => this.onPointerMove(e));
    c.addEventListener("pointerup", (e) => this.onPointerUp(e));
    c.addEventListener("pointercancel", (e) => this.onPointerUp(e));
    c.addEventListener("wheel", (e) => this.onWheel(e), { passive: false });
    c.addEventListener("dblclick", () => this.cb.onReset());
    c.addEventListener("keydown", (e) => this.onKey(e));
  }

  // Keyboard (the canvas takes focus): arrows orbit, Shift+arrows pan, +/- zoom, Home resets.
  onKey(e) {
    const arrows = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, -1], ArrowDown: [0, 1] };
    if (e.key === "Home") { this.cb.onReset(); e.preventDefault(); return; }
    if (arrows[e.key]) {
      const [x, y] = arrows[e.key];
      this.queue(e.shiftKey ? "pan" : "orbit", x * KEY_STEP_PX, y * KEY_STEP_PX, 1);
    } else if (e.key === "+" || e.key === "=" || e.key === "-") {
      this.queue("zoom", 0, 0, e.key === "-" ? 1.15 : 1 / 1.15);
    } else {
      return;
    }
    e.preventDefault();
    this.setInteracting(true);
    clearTimeout(this.wheelTimer);
    this.wheelTimer = setTimeout(() => { this.flush(); if (this.pointers.size === 0) this.setInteracting(false); }, WHEEL_IDLE_MS);
  }

  onPointerDown(e) {
    // Keep receiving moves outside the canvas; synthetic events have no capturable pointer.
    try { this.canvas.setPointerCapture(e.pointerId); } catch { /* not a live pointer */ }
    this.pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
    if (this.pointers.size === 2) {
      this.mode = "pinch";
      this.pinch = this.pinchGeometry();
    } else if (this.pointers.size === 1) {
      this.mode = e.altKey ? "window_level"
        : e.button === 2 || e.button === 1 || e.shiftKey || e.ctrlKey ? "pan"
        : "orbit";
    }
    this.canvas.classList.add("dragging");
    this.setInteracting(true);
    e.preventDefault();
  }

  onPointerMove(e) {
    const p = this.pointers.get(e.pointerId);
    if (!p) return;
    const dx = e.clientX - p.x, dy = e.clientY - p.y;
    p.x = e.clientX;
    p.y = e.clientY;
    if (this.mode === "pinch") {
      const g = this.pinchGeometry();
      // Fingers apart: closer (factor < 1); the midpoint's motion pans.
      this.queue("zoom", 0, 0, this.pinch.distance / Math.max(g.distance, 1));
      this.queue("pan", g.x - this.pinch.x, g.y - this.pinch.y, 1);
      this.pinch = g;
    } else if (this.mode) {
      this.queue(this.mode, dx, dy, 1);
    }
  }

  onPointerUp(e) {
    if (!this.pointers.delete(e.pointerId)) return;
    if (this.pointers.size === 1 && this.mode === "pinch") {
      this.mode = "orbit";   // one finger left: go on turning, as touch viewers do
    } else if (this.pointers.size === 0) {
      this.mode = null;
      this.canvas.classList.remove("dragging");
      this.flush();
      this.setInteracting(false);
    }
  }

  onWheel(e) {
    e.preventDefault();
    const px = e.deltaY * (e.deltaMode === 1 ? WHEEL_LINE_PX : e.deltaMode === 2 ? this.size.cssHeight : 1);
    // Trackpad pinch arrives as ctrl+wheel with small deltas: the same zoom, finer.
    this.queue("zoom", 0, 0, Math.exp(px * (e.ctrlKey ? 0.01 : 0.0015)));
    this.setInteracting(true);
    clearTimeout(this.wheelTimer);
    this.wheelTimer = setTimeout(() => { this.flush(); if (this.pointers.size === 0) this.setInteracting(false); }, WHEEL_IDLE_MS);
  }

  pinchGeometry() {
    const [a, b] = [...this.pointers.values()];
    return { distance: Math.hypot(a.x - b.x, a.y - b.y), x: (a.x + b.x) / 2, y: (a.y + b.y) / 2 };
  }

  setInteracting(active) {
    if (active === this.interacting) return;
    this.interacting = active;
    this.cb.onInteraction(active);
  }

  // Accumulate steps of one kind; a change of kind sends what was accumulated first.
  queue(kind, dx, dy, factor) {
    if (this.pending.kind && this.pending.kind !== kind) this.flush();
    this.pending.kind = kind;
    this.pending.dx += dx;
    this.pending.dy += dy;
    this.pending.factor *= factor;
    if (!this.rafScheduled) {
      this.rafScheduled = true;
      requestAnimationFrame(() => { this.rafScheduled = false; this.flush(); });
    }
  }

  flush() {
    const p = this.pending;
    if (!p.kind) return;
    this.pending = { dx: 0, dy: 0, factor: 1, kind: null };
    if (p.dx === 0 && p.dy === 0 && p.factor === 1) return;
    this.cb.onNavigate(p);
  }
}
