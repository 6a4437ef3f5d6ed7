// The transfer-function preset picker fed by the server: the presets of the volume's
// modality in its own data units (volume object `modality`, renderer/presets.cpp), the line
// saying which modality and preset were chosen and why, and each preset's shading. Volumes
// the server sends no presets for (built-in phantoms, older servers) keep the page's named
// presets (core/protocol.js TF_PRESETS).

import { TF_PRESETS } from "../core/protocol.js";

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
    this.presets = [];
    this.reason = Object.assign(doc.createElement("div"), { id: "preset-reason", className: "muted small" });
    this.select.closest(".row").after(this.reason);
    this.fill();
  }

  // The volume just opened (or null) and the transfer function its scene starts with.
  setVolume(volume, tf, { restored = false } = {}) {
    const m = volume?.modality;
    this.presets = Array.isArray(m?.presets) ? m.presets : [];
    this.fill();
    if (!m) { this.reason.textContent = ""; return; }
    const chosen = this.presets.find((p) => p.name === m.default_preset);
    this.reason.textContent = `${m.name} (${m.source === "file" ? "from the file" : "inferred"}): ${m.reason}` +
      (chosen ? ` → ${chosen.label}, W ${round(chosen.window)} / L ${round(chosen.level)}${chosen.shading ? ", shaded" : ""}` : "");
    this.showMatching(tf?.points);
    // A fresh open starts on the default preset: its shading comes with it.
    if (!restored && chosen && samePoints(tf?.points, chosen.points)) this.apply(chosen, { send: false });
  }

  fill() {
    const keep = this.select.value;
    const options = [new Option("(custom)", "")];
    if (this.presets.length) {
      for (const p of this.presets) options.push(new Option(p.label, p.name));
    } else {
      for (const p of TF_PRESETS) options.push(new Option(p.label, p.name));
    }
    this.select.replaceChildren(...options);
    if ([...this.select.options].some((o) => o.value === keep)) this.select.value = keep;
  }

  // Selects the preset whose points these are, or (custom).
  showMatching(points) {
    const p = this.presets.find((q) => samePoints(points, q.points));
    if (p) this.select.value = p.name;
  }

  // The user picked `name`: true when it is one of the server's presets (applied here).
  choose(name) {
    const p = this.presets.find((q) => q.name === name);
    if (!p) return false;
    this.apply(p, { send: true });
    return true;
  }
}

const round = (x) => Number(Number(x).toPrecision(4));
