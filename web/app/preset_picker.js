// The transfer-function preset picker fed by the server: a modality picker (the server's
// choice first, every modality it has presets for) and the presets of the modality shown,
// in the volume's own data units (volume object `modality`, renderer/model/presets.cpp); the line
// under them says which modality and preset are shown and why, and follows the user's
// choice. Volumes the server sends no presets for (built-in phantoms, older servers) keep
// the page's named presets (core/protocol.js TF_PRESETS) and no modality picker.

import { TF_PRESETS } from "../core/protocol.js";
import { modalitiesOf, presetNote, presetsOfModality } from "../core/presets.js";

// Points match a preset's when every number agrees to this relative tolerance: the server
// sends the same doubles, JSON round trips keep them; the margin only absorbs tidying.
const MATCH_TOLERANCE = 1e-9;

function samePoints(a, b) {
  if (!Array.isArray(a) || !Array.isArray(b) || a.length !== b.length) return false;
  return a.every((p, i) => p.length === b[i].length &&
    p.every((x, k) => Math.abs(x - b[i][k]) <= MATCH_TOLERANCE * Math.max(1, Math.abs(x))));
}

export class PresetPicker {
  // apply(preset): the page shows and sends preset.points and sets shading to preset.shading.
  constructor(doc, { apply }) {
    this.doc = doc;
    this.select = doc.getElementById("tf-preset");
    this.apply = apply;
    this.info = null;        // the volume's `modality` object, or null
    this.modality = null;    // the modality whose presets are offered
    this.current = null;     // the preset whose points the view has, or null (the user's own curve)
    const row = this.select.closest(".row");
    this.modalityRow = Object.assign(doc.createElement("div"), { className: "row", hidden: true });
    this.modalitySelect = Object.assign(doc.createElement("select"), { id: "tf-modality" });
    this.modalitySelect.setAttribute("aria-label", "Modality the presets are for");
    this.modalityRow.append(Object.assign(doc.createElement("label"), { htmlFor: "tf-modality", textContent: "Modality" }),
      this.modalitySelect);
    row.before(this.modalityRow);
    this.modalitySelect.addEventListener("change", () => this.chooseModality(this.modalitySelect.value));
    this.reason = Object.assign(doc.createElement("div"), { id: "preset-reason", className: "muted small" });
    row.after(this.reason);
    this.fill();
  }

  get presets() { return this.info?.presets ?? []; }

  // The volume just opened (or null) and the transfer function its scene starts with.
  setVolume(volume, tf, { restored = false } = {}) {
    this.info = Array.isArray(volume?.modality?.presets) ? volume.modality : null;
    this.modality = this.info?.name ?? null;
    this.current = null;
    this.fillModalities();
    this.fill();
    this.showMatching(tf?.points);
    const chosen = this.presets.find((p) => p.name === this.info?.default_preset);
    // A fresh open starts on the default preset: its shading comes with it.
    if (!restored && chosen && samePoints(tf?.points, chosen.points)) this.apply(chosen, { send: false });
  }

  fillModalities() {
    const names = modalitiesOf(this.info);
    this.modalitySelect.replaceChildren(...names.map((m) => new Option(m, m)));
    this.modalityRow.hidden = names.length === 0;
    if (this.modality) this.modalitySelect.value = this.modality;
  }

  fill() {
    const keep = this.select.value;
    const options = [new Option("(custom)", "")];
    if (this.info) {
      for (const p of presetsOfModality(this.info, this.modality)) options.push(new Option(p.label, p.name));
    } else {
      for (const p of TF_PRESETS) options.push(new Option(p.label, p.name));
    }
    this.select.replaceChildren(...options);
    if ([...this.select.options].some((o) => o.value === keep)) this.select.value = keep;
  }

  // Shows the preset whose points these are (switching to its modality), or (custom).
  showMatching(points) {
    const p = this.presets.find((q) => samePoints(points, q.points)) ?? null;
    this.current = p;
    if (p) this.show(p);
    else if (this.info) this.select.value = "";
    this.updateNote();
  }

  // The user picked `name`: true when it is one of the server's presets (applied here).
  choose(name) {
    const p = this.presets.find((q) => q.name === name);
    if (!p) return false;
    this.current = p;
    this.show(p);
    this.apply(p, { send: true });
    this.updateNote();
    return true;
  }

  // The user picked another modality: its presets are offered and its first (that
  // modality's default) applied.
  chooseModality(modality) {
    if (!this.info || !modalitiesOf(this.info).includes(modality)) return;
    this.modality = modality;
    this.fill();
    const first = presetsOfModality(this.info, modality)[0];
    if (first) this.choose(first.name);
    else this.updateNote();
  }

  show(p) {
    const modality = p.modality || this.info?.name;
    if (modality && modality !== this.modality) {
      this.modality = modality;
      this.fill();
    }
    this.modalitySelect.value = this.modality ?? "";
    this.select.value = p.name;
  }

  updateNote() {
    this.reason.textContent = this.info ? presetNote(this.info, { modality: this.modality, preset: this.current }) : "";
  }
}
