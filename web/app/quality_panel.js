// The quality panel (automatic policy with a target frame time, or docs/design.md's explicit
// switches), the render resolution, and the clip plane.

import { volumeBounds } from "../core/camera.js";
import { axisClipPlane, sliderOfPlane } from "../core/clip_plane.js";
import { correctedBounds, IDENTITY_CORRECTION } from "../core/orientation.js";

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
  // The server writes it only when on: absent from its state means off.
  adaptive_step: { id: "q-adaptive", kind: "checkbox", absentMeans: false },
};

export class QualityPanel {
  // callbacks: onPolicy(policy), onResolution(choice), onClip(planes, {interactive}).
  constructor(root, callbacks) {
    this.$ = (id) => root.getElementById(id);
    this.cb = callbacks;
    this.touched = false;        // the user changed a switch: send them with the policy
    this.seed = 0;
    this.timer = null;
    this.volumeBox = null;      // the volume's own box (camera.js's volumeBounds)
    this.correction = IDENTITY_CORRECTION;
    this.bounds = null;         // the box it is drawn in: volumeBox after the orientation correction
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

  // The policy is being sent now by the caller: a scheduled send would only repeat it (and
  // restart the server's refinement).
  cancelScheduled() { clearTimeout(this.timer); this.timer = null; }

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
        if (!(key in q) && !("absentMeans" in f)) continue;
        const value = key in q ? q[key] : f.absentMeans;
        const el = this.$(f.id);
        if (f.kind === "checkbox") el.checked = !!value; else el.value = value;
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

  // correction: the scene's quality.orientation_correction (null: none). The slider spans
  // the box the volume is drawn in, which a quarter turn of the volume changes.
  setVolume(volume, planes, correction = null) {
    this.volumeBox = volumeBounds(volume);
    this.correction = correction ?? IDENTITY_CORRECTION;
    this.bounds = correctedBounds(this.volumeBox, this.correction);
    const slider = planes?.[0] && this.bounds ? sliderOfPlane(this.bounds, planes[0]) : null;
    if (slider) {
      // Show a plane the server reports (after a reconnection) if it is axis-aligned.
      this.$("clip-enabled").checked = true;
      this.$("clip-axis").value = String(slider.axis);
      this.$("clip-flip").checked = slider.flipped;
      this.$("clip-position").value = slider.t;
    } else {
      this.$("clip-enabled").checked = false;
    }
    this.showClip();
  }

  // The volume was flipped or turned: the slider keeps its place in the new box, and an
  // enabled plane moves with it (one clip_planes request), so plane and slider agree.
  setCorrection(correction) {
    const next = correction ?? IDENTITY_CORRECTION;
    if (JSON.stringify(next) === JSON.stringify(this.correction)) return;
    this.correction = next;
    this.bounds = correctedBounds(this.volumeBox, next);
    this.showClip();
    if (this.$("clip-enabled").checked && this.bounds) this.cb.onClip(this.clipPlanes(), { interactive: false });
  }

  // One axis-aligned plane through the slider's position; keeps the half-space its normal
  // points into (the + side, or − with "Flip").
  clipPlanes() {
    if (!this.$("clip-enabled").checked || !this.bounds) return [];
    return [axisClipPlane(this.bounds, Number(this.$("clip-axis").value), Number(this.$("clip-position").value),
      this.$("clip-flip").checked)];
  }

  showClip() {
    const on = this.$("clip-enabled").checked && this.bounds;
    for (const id of ["clip-axis", "clip-flip", "clip-position"]) this.$(id).disabled = !on;
    const planes = this.clipPlanes();
    const axis = Number(this.$("clip-axis").value);
    this.$("clip-position-out").value = planes.length ? String(Number(planes[0].point[axis].toPrecision(4))) : "off";
  }
}
