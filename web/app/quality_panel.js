// The quality panel (automatic policy with a target frame time, or docs/design.md's explicit
// switches), the render resolution, and the clip plane.

import { volumeBounds } from "../core/camera.js";

export const POLICY_SETTLE_MS = 250;   // ms after the last edit before the policy is sent

// Render resolution: device pixels per CSS pixel of the view.
export function renderScaleFor(choice, dpr, deviceType) {
  switch (choice) {
    case "device": return dpr;
    case "css": return 1;
    case "half": return 0.5;
    // A GPU renders device pixels at interactive rates; a CPU device gets CSS pixels.
    default: return deviceType === "gpu" ? dpr : 1;
  }
}

const QUALITY_FIELDS = {
  step: { id: "q-step", kind: "number" },
  interpolation: { id: "q-interpolation", kind: "select" },
  early_termination: { id: "q-early", kind: "number" },
  mip_level: { id: "q-mip", kind: "integer" },
  image_scale: { id: "q-scale", kind: "number" },
  preintegrated: { id: "q-preintegrated", kind: "checkbox" },
  jitter: { id: "q-jitter", kind: "checkbox" },
  boundary_segment: { id: "q-boundary", kind: "checkbox" },
  empty_space_skipping: { id: "q-skipping", kind: "checkbox" },
  shading: { id: "q-shading", kind: "checkbox" },
};

export class QualityPanel {
  // callbacks: onPolicy(policy), onResolution(choice), onClip(planes, {interactive}).
  constructor(root, callbacks) {
    this.$ = (id) => root.getElementById(id);
    this.cb = callbacks;
    this.touched = false;        // the user changed a switch: send them with the policy
    this.seed = 0;
    this.timer = null;
    this.bounds = null;
    this.bind();
  }

  bind() {
    const $ = this.$;
    const changed = () => { this.touched = true; this.schedule(); };
    for (const f of Object.values(QUALITY_FIELDS)) $(f.id).addEventListener("change", changed);
    for (const r of document.querySelectorAll('input[name="quality-mode"]')) {
      r.addEventListener("change", () => { this.updateMode(); this.schedule(); });
    }
    $("target-ms").addEventListener("input", () => { this.showTarget(); this.schedule(); });
    $("resolution").addEventListener("change", () => this.cb.onResolution($("resolution").value));

    // Clip plane: dragging the slider is an interaction (cheap frames), releasing refines.
    const clip = (interactive) => this.cb.onClip(this.clipPlanes(), { interactive });
    $("clip-position").addEventListener("input", () => { this.showClip(); clip(true); });
    $("clip-position").addEventListener("change", () => clip(false));
    for (const id of ["clip-enabled", "clip-axis", "clip-flip"]) $(id).addEventListener("change", () => { this.showClip(); clip(false); });
    this.updateMode();
    this.showTarget();
  }

  get mode() { return document.querySelector('input[name="quality-mode"]:checked').value; }

  updateMode() {
    const explicit = this.mode === "explicit";
    this.$("target-row").classList.toggle("disabled", explicit);
    this.$("quality-note").textContent = explicit
      ? "Every frame uses exactly these settings: interaction frames come as JPEG, then one final PNG."
      : "While you interact the server picks the level that meets the target frame time, then refines to the settings below.";
  }

  showTarget() { this.$("target-ms-out").value = `${this.$("target-ms").value} ms`; }

  schedule() {
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.cb.onPolicy(this.policy()), POLICY_SETTLE_MS);
  }

  quality() {
    const q = { seed: this.seed };
    for (const [key, f] of Object.entries(QUALITY_FIELDS)) {
      const el = this.$(f.id);
      q[key] = f.kind === "checkbox" ? el.checked
        : f.kind === "select" ? el.value
        : f.kind === "integer" ? Math.round(Number(el.value))
        : Number(el.value);
    }
    return q;
  }

  // The policy as the protocol's quality_policy request takes it. Automatic sends the
  // switches only once the user has changed one (else the server's own final level).
  policy() {
    if (this.mode === "explicit") return { mode: "explicit", quality: this.quality() };
    const p = { mode: "automatic", target_frame_ms: Number(this.$("target-ms").value) };
    if (this.touched) p.quality = this.quality();
    return p;
  }

  // Show what the server reports (a `state`): its policy and the scene's quality.
  showState(state) {
    const q = state.scene?.quality;
    if (q) {
      this.seed = q.seed ?? 0;
      for (const [key, f] of Object.entries(QUALITY_FIELDS)) {
        if (!(key in q)) continue;
        const el = this.$(f.id);
        if (f.kind === "checkbox") el.checked = !!q[key]; else el.value = q[key];
      }
    }
    const p = state.quality_policy;
    if (p?.mode) {
      for (const r of document.querySelectorAll('input[name="quality-mode"]')) r.checked = r.value === p.mode;
      if (p.target_frame_ms) this.$("target-ms").value = p.target_frame_ms;
      this.updateMode();
      this.showTarget();
    }
  }

  showResolution(text) { this.$("resolution-out").textContent = text; }

  // --- clip plane -------------------------------------------------------------------------

  setVolume(volume, planes) {
    this.bounds = volumeBounds(volume);
    const plane = planes?.[0];
    if (plane && this.bounds) {
      // Show a plane the server reports (after a reconnection) if it is axis-aligned.
      const axis = plane.normal.findIndex((n) => Math.abs(n) > 0.999);
      if (axis >= 0) {
        this.$("clip-enabled").checked = true;
        this.$("clip-axis").value = String(axis);
        this.$("clip-flip").checked = plane.normal[axis] < 0;
        const { lo, hi } = this.bounds;
        this.$("clip-position").value = (plane.point[axis] - lo[axis]) / (hi[axis] - lo[axis]);
      }
    } else {
      this.$("clip-enabled").checked = false;
    }
    this.showClip();
  }

  // One axis-aligned plane through the slider's position; keeps the half-space its normal
  // points into (the + side, or − with "Flip").
  clipPlanes() {
    if (!this.$("clip-enabled").checked || !this.bounds) return [];
    const axis = Number(this.$("clip-axis").value);
    const t = Number(this.$("clip-position").value);
    const { lo, hi, center } = this.bounds;
    const point = [...center];
    point[axis] = lo[axis] + t * (hi[axis] - lo[axis]);
    const normal = [0, 0, 0];
    normal[axis] = this.$("clip-flip").checked ? -1 : 1;
    return [{ point: point.map((x) => Number(x.toPrecision(8))), normal }];
  }

  showClip() {
    const on = this.$("clip-enabled").checked && this.bounds;
    for (const id of ["clip-axis", "clip-flip", "clip-position"]) this.$(id).disabled = !on;
    const planes = this.clipPlanes();
    const axis = Number(this.$("clip-axis").value);
    this.$("clip-position-out").value = planes.length ? String(Number(planes[0].point[axis].toPrecision(4))) : "off";
  }
}
