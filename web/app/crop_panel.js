// The compositing mode (emission–absorption, maximum or minimum intensity projection), the
// projections' window/level, and the crop box: six sliders, one per face, in the volume's
// own axes. All travel in the quality object of the protocol's quality_policy
// (docs/design.md's scene file: quality.compositing, quality.projection_window {window,
// level} in data units, quality.crop in normalised box coordinates, 0 and 1 the outer faces
// of the outermost voxels), so every level the server renders keeps them.
//
// A MIP or MinIP is a greyscale picture windowed like a radiograph: level − window/2 black,
// level + window/2 white (the transfer function plays no part). Its fields start at the
// volume's value range, which is what the server uses while none is sent.

export const COMPOSITING_MODES = [
  { value: "emission_absorption", label: "Emission–absorption" },
  { value: "mip", label: "Maximum intensity (MIP)" },
  { value: "minip", label: "Minimum intensity (MinIP)" },
];

const AXES = ["x", "y", "z"];
const MIN_GAP = 0.01;   // the smallest box the sliders allow, of the volume's extent per axis

// The crop and compositing keys added to a quality object; the defaults are left out, as the
// server writes them.
// projectionWindow ({window, level} or null) goes with a projection only.
export function withCompositingAndCrop(quality, compositing, crop, projectionWindow = null) {
  const q = { ...quality };
  const projecting = compositing && compositing !== "emission_absorption";
  if (projecting) q.compositing = compositing;
  else delete q.compositing;
  if (projecting && projectionWindow) q.projection_window = { window: projectionWindow.window, level: projectionWindow.level };
  else delete q.projection_window;
  const full = crop.min.every((v) => v === 0) && crop.max.every((v) => v === 1);
  if (full) delete q.crop; else q.crop = { min: [...crop.min], max: [...crop.max] };
  return q;
}

export class CropPanel {
  // card: an empty <details> to fill; onChange({ interactive }) after every edit:
  // interactive while a slider is dragged, not for its release or any other edit.
  constructor(card, onChange) {
    this.card = card;
    this.onChange = onChange;
    this.dragging = false;
    this.projectionWindow = null;   // {window, level} the user set; null: the volume's range
    this.range = [0, 1];            // the open volume's value range
    this.shownListeners = [];       // onShown(fn): the crop handles redraw with the sliders
    this.build();
    this.showWindow();
  }

  build() {
    const card = this.card;
    card.classList.add("card");
    card.innerHTML = "";
    const summary = document.createElement("summary");
    summary.textContent = "Compositing and crop box";
    card.append(summary);

    const modeRow = document.createElement("div");
    modeRow.className = "row";
    const modeLabel = document.createElement("label");
    modeLabel.htmlFor = "compositing";
    modeLabel.textContent = "Compositing";
    this.mode = document.createElement("select");
    this.mode.id = "compositing";
    for (const m of COMPOSITING_MODES) this.mode.append(new Option(m.label, m.value));
    this.mode.addEventListener("change", () => this.onChange({ interactive: false }));
    modeRow.append(modeLabel, this.mode);
    card.append(modeRow);

    // The projection's window/level: shown while a projection is chosen.
    this.windowRow = document.createElement("div");
    this.windowRow.className = "row";
    this.windowRow.innerHTML = `<label for="projection-window">Window</label>
      <input id="projection-window" type="number" step="any" min="0" title="Projection window (data units): the span from black to white">
      <label for="projection-level" class="inline">Level</label>
      <input id="projection-level" type="number" step="any" title="Projection level (data units): the value shown mid-grey">`;
    card.append(this.windowRow);
    this.windowInputs = { window: this.windowRow.querySelector("#projection-window"), level: this.windowRow.querySelector("#projection-level") };
    for (const key of ["window", "level"]) {
      this.windowInputs[key].addEventListener("change", () => {
        const v = Number(this.windowInputs[key].value);
        const current = this.effectiveWindow();
        if (this.windowInputs[key].value.trim() === "" || !Number.isFinite(v) || (key === "window" && !(v > 0))) { this.showWindow(); return; }
        this.setProjectionWindow({ ...current, [key]: v });
        this.onChange({ interactive: false });
      });
    }
    this.mode.addEventListener("change", () => this.showWindow());

    this.sliders = { min: [], max: [] };
    this.outputs = { min: [], max: [] };
    for (let a = 0; a < 3; ++a) {
      for (const side of ["min", "max"]) {
        const row = document.createElement("div");
        row.className = "row";
        const id = `crop-${side}-${AXES[a]}`;
        const label = document.createElement("label");
        label.htmlFor = id;
        label.textContent = `${AXES[a]} ${side === "min" ? "from" : "to"}`;
        const input = document.createElement("input");
        Object.assign(input, { id, type: "range", min: "0", max: "1", step: "0.005", value: side === "min" ? "0" : "1" });
        const out = document.createElement("output");
        out.htmlFor = id;
        // A drag is an interaction (input, input, …), its release (change) the end of it.
        input.addEventListener("input", () => { this.dragging = true; this.keepOrder(a, side); this.show(); this.onChange({ interactive: true }); });
        input.addEventListener("change", () => { this.dragging = false; this.keepOrder(a, side); this.show(); this.onChange({ interactive: false }); });
        row.append(label, input, out);
        card.append(row);
        this.sliders[side][a] = input;
        this.outputs[side][a] = out;
      }
    }
    // A drag back to where it started fires no change: the release still ends the
    // interaction (after the change event, where there is one).
    document.addEventListener("pointerup", () => setTimeout(() => {
      if (!this.dragging) return;
      this.dragging = false;
      this.onChange({ interactive: false });
    }, 0));
    const reset = document.createElement("button");
    reset.type = "button";
    reset.id = "crop-reset";
    reset.textContent = "Whole volume";
    reset.addEventListener("click", () => { this.set({ min: [0, 0, 0], max: [1, 1, 1] }); this.onChange({ interactive: false }); });
    card.append(reset);
    this.show();
  }

  // A face dragged past its opposite pushes nothing: it stops MIN_GAP short of it.
  keepOrder(a, side) {
    const lo = this.sliders.min[a], hi = this.sliders.max[a];
    if (Number(hi.value) - Number(lo.value) >= MIN_GAP) return;
    if (side === "min") lo.value = String(Math.max(0, Number(hi.value) - MIN_GAP));
    else hi.value = String(Math.min(1, Number(lo.value) + MIN_GAP));
  }

  get compositing() { return this.mode.value; }
  get projecting() { return this.mode.value !== "emission_absorption"; }

  // The open volume: its range is the projection window while the user sets none.
  setVolume(volume) {
    const r = volume?.value_range;
    this.range = Array.isArray(r) && r[1] > r[0] ? [r[0], r[1]] : [0, 1];
    this.projectionWindow = null;
    this.showWindow();
  }

  effectiveWindow() {
    return this.projectionWindow ?? { window: this.range[1] - this.range[0], level: (this.range[0] + this.range[1]) / 2 };
  }

  setProjectionWindow(wl) {
    this.projectionWindow = wl ? { window: wl.window, level: wl.level } : null;
    this.showWindow();
  }

  // An Alt-drag in the 3D view while projecting windows the projection (as it windows the
  // transfer function otherwise); next: core/window_level.js's step.
  dragWindow(next, interactive) {
    this.setProjectionWindow(next);
    this.onChange({ interactive });
  }

  showWindow() {
    this.windowRow.hidden = !this.projecting;
    const wl = this.effectiveWindow();
    // 4 significant digits: HU come out whole, grey values readable, never cut in the field.
    this.windowInputs.window.value = String(Number(wl.window.toPrecision(4)));
    this.windowInputs.level.value = String(Number(wl.level.toPrecision(4)));
  }

  onShown(fn) { this.shownListeners.push(fn); }

  get crop() {
    return {
      min: this.sliders.min.map((s) => Number(s.value)),
      max: this.sliders.max.map((s) => Number(s.value)),
    };
  }

  set(crop) {
    for (let a = 0; a < 3; ++a) {
      this.sliders.min[a].value = String(crop.min[a]);
      this.sliders.max[a].value = String(crop.max[a]);
    }
    this.show();
  }

  // What the server reports (a state's scene.quality).
  showState(quality) {
    if (!quality) return;
    this.mode.value = quality.compositing ?? "emission_absorption";
    const pw = quality.projection_window;
    if (pw && pw.window > 0 && Number.isFinite(pw.level)) this.projectionWindow = { window: pw.window, level: pw.level };
    this.showWindow();
    this.set(quality.crop ?? { min: [0, 0, 0], max: [1, 1, 1] });
  }

  show() {
    for (const side of ["min", "max"])
      for (let a = 0; a < 3; ++a) this.outputs[side][a].value = Number(this.sliders[side][a].value).toFixed(3);
    for (const fn of this.shownListeners) fn(this.crop);
  }

  // A crop from a handle dragged in the 3D view or a slice: the sliders follow, and it goes
  // as a slider's edit does (interactive while the handle moves, final on release).
  setFromHandle(crop, interactive) {
    this.set(crop);
    this.onChange({ interactive });
  }

  decorate(quality) { return withCompositingAndCrop(quality, this.compositing, this.crop, this.projectionWindow); }
}
