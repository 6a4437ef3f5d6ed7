// The page: wires the session (core/) to the view, the panels and the overlays.
//
// URL parameters: ?volume=NAME opens that volume first; ?server=ws://host:port/ws talks to
// another server than the one that served the page; ?token=T for a server started with
// --token.

import { orbit, pan, volumeBounds, zoom } from "../core/camera.js";
import { defaultServerUrl } from "../core/connection.js";
import { TF_PRESETS } from "../core/protocol.js";
import { Session } from "../core/session.js";
import { presetPoints, problems, resolvePoints, tidyPoints } from "../core/transfer_function.js";
import { CropPanel } from "./crop_panel.js";
import { QualityPanel, renderScaleFor } from "./quality_panel.js";
import { StatsOverlay } from "./stats_overlay.js";
import { ConnectionIndicator, ErrorList, ViewMessage } from "./status.js";
import { TransferFunctionEditor } from "./tf_editor.js";
import { View } from "./view.js";

const CLIENT_NAME = "volcast-web 0.1.0";
const MAX_FRAMES_KEPT = 400;           // frame headers kept in window.volcast.frames (tests, console)
const WL_WINDOW_PER_PX = 0.005;        // Alt-drag: log-scale window change per px (horizontal)
const WL_LEVEL_SPAN_PER_PX = 1 / 400;  // Alt-drag: fraction of the value range per px (vertical)
const STAGE_SHARE = { loading: [0, 0.6], preprocessing: [0.6, 0.9], uploading: [0.9, 1] };   // of the bar

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const serverUrl = params.get("server") || defaultServerUrl(location);

const session = new Session(serverUrl, {
  client: CLIENT_NAME,
  token: params.get("token") || undefined,
  preferredVolume: params.get("volume") || null,
});

// What the page holds beyond the session: the camera being navigated, the view to reset
// to, the transfer function being edited, and what the message over the view should say.
const app = {
  camera: null,
  startCamera: null,
  tf: null,                 // scene-file transfer function: {points, opacity_unit?} or {preset}
  progress: null,           // latest progress message while loading
  sceneProgress: null,      // preprocessing a scene change needs (id null), until the next frame
  openError: null,          // why the last open failed, while no volume is open
  renderError: null,        // why the server could not render, while no frame is on screen
  frameSinceOpen: false,
  resolution: "auto",
};

// --- widgets --------------------------------------------------------------------------

const errors = new ErrorList(document);
const message = new ViewMessage(document);
const indicator = new ConnectionIndicator(document, () => session.connection.retryNow());
const stats = new StatsOverlay(document, session.stats);

// One send per animation frame for continuous edits (TF drags, clip slider); the latest
// value wins, as on the server.
function perAnimationFrame(send) {
  let latest, scheduled = false;
  const fn = (value) => {
    latest = value;
    if (scheduled) return;
    scheduled = true;
    requestAnimationFrame(() => { scheduled = false; if (latest !== undefined) { send(latest); latest = undefined; } });
  };
  fn.now = (value) => { latest = undefined; send(value); };
  return fn;
}

const sendTf = perAnimationFrame((tf) => session.setTransferFunction(tf));
const sendClip = perAnimationFrame((planes) => session.setClipPlanes(planes));

const view = new View($("view"), $("view-canvas"), {
  onNavigate(step) {
    if (!app.camera || !session.volume) return;
    const radius = volumeBounds(session.volume)?.radius ?? 0;
    const heightPx = view.size.cssHeight || 1;
    if (step.kind === "orbit") app.camera = orbit(app.camera, step.dx, step.dy);
    else if (step.kind === "pan") app.camera = pan(app.camera, step.dx, step.dy, heightPx);
    else if (step.kind === "zoom") app.camera = zoom(app.camera, step.factor, radius);
    else if (step.kind === "window_level") return windowLevelDrag(step);
    session.setCamera(app.camera);
  },
  onInteraction(active) {
    if (!session.volume) return;
    if (active) session.beginInteraction();
    else session.endInteraction();
  },
  onResize: () => updateViewport(),
  onReset: () => resetView(),
});

const tfEditor = new TransferFunctionEditor({
  canvas: $("tf-editor"), value: $("tf-point-value"), alpha: $("tf-point-alpha"), color: $("tf-point-color"),
  remove: $("tf-point-remove"), window: $("tf-window"), level: $("tf-level"),
}, (points, { interactive }) => onTfEdited(points, interactive));

const quality = new QualityPanel(document, {
  // The crop panel adds quality.compositing and quality.crop to the switches.
  onPolicy: (policy) => session.setQualityPolicy(policy.quality ? { ...policy, quality: crop.decorate(policy.quality) } : policy),
  onResolution: (choice) => { app.resolution = choice; updateViewport(); },
  onClip: (planes, { interactive }) => {
    if (!session.volume) return;
    if (interactive) { session.beginInteraction(); sendClip(planes); }
    else { sendClip.now(planes); session.endInteraction(); }
  },
});

// Compositing and crop box travel with the quality switches: an edit sends the policy with them.
const crop = new CropPanel($("crop-card"), () => { quality.touched = true; quality.schedule(); });

for (const p of TF_PRESETS) $("tf-preset").append(new Option(p.label, p.name));

// --- transfer function ----------------------------------------------------------------

function onTfEdited(points, interactive) {
  const bad = problems(points);
  if (bad.length) { errors.show({ code: "transfer_function", message: bad.join("; ") }); return; }
  app.tf = { points: tidyPoints(points) };
  if (app.tfOpacityUnit !== undefined) app.tf.opacity_unit = app.tfOpacityUnit;
  $("tf-preset").value = "";
  if (!session.volume) return;
  if (interactive) { session.beginInteraction(); sendTf(app.tf); }
  else { sendTf.now(app.tf); if (!view.interacting) session.endInteraction(); }
}

$("tf-preset").addEventListener("change", () => {
  const name = $("tf-preset").value;
  if (!name || !session.volume) return;
  app.tf = { preset: name };
  tfEditor.setPoints(presetPoints(name, session.volume.value_range ?? [0, 1]));
  session.setTransferFunction(app.tf);
});

function windowLevelDrag(step) {
  const wl = tfEditor.windowLevel;
  const range = session.volume?.value_range ?? [0, 1];
  if (!wl) return;
  const w = wl.window * Math.exp(step.dx * WL_WINDOW_PER_PX);
  const l = wl.level + step.dy * (range[1] - range[0]) * WL_LEVEL_SPAN_PER_PX;
  tfEditor.applyWindowLevel(w, l, true);
}

function showTransferFunction(tf) {
  app.tf = tf;
  app.tfOpacityUnit = tf?.opacity_unit;
  $("tf-preset").value = tf?.preset ?? "";
  try {
    tfEditor.setPoints(tf ? resolvePoints(tf, session.volume?.value_range ?? [0, 1]) : []);
  } catch (e) {
    // A preset this page does not know (a newer server): shown by name, not editable here.
    tfEditor.setPoints([]);
    errors.show({ code: "transfer_function", message: e.message });
  }
}

// --- viewport and camera --------------------------------------------------------------

function updateViewport() {
  const { cssWidth, cssHeight, dpr } = view.size;
  if (!(cssWidth > 0 && cssHeight > 0)) return;
  const scale = renderScaleFor(app.resolution, dpr, session.hello?.device?.type);
  let w = Math.max(1, Math.round(cssWidth * scale)), h = Math.max(1, Math.round(cssHeight * scale));
  // Stay within the server's limits, keeping the aspect ratio.
  const limits = session.hello?.limits ?? {};
  const side = limits.max_image_side ?? Infinity, pixels = limits.max_image_pixels ?? Infinity;
  const shrink = Math.min(1, side / w, side / h, Math.sqrt(pixels / (w * h)));
  if (shrink < 1) { w = Math.max(1, Math.floor(w * shrink)); h = Math.max(1, Math.floor(h * shrink)); }
  session.setViewport(w, h);
  quality.showResolution(`${w}×${h} px`);
}

function resetView() {
  if (!app.startCamera || !session.volume) return;
  app.camera = app.startCamera;
  session.setCamera(app.camera);
}

// --- session events -------------------------------------------------------------------

session.on("connection", (s) => {
  indicator.show(s, session.connection);
  if (s.state === "ready") { view.resetSequence(); updateViewport(); }
  updateMessage();
});

session.on("hello", (hello) => {
  const info = $("server-info");
  info.replaceChildren();
  const rows = [["server", hello.server], ["device", `${hello.device?.name ?? "?"} (${hello.device?.type ?? "?"})`],
    ["address", serverUrl], ["max image", `${hello.limits?.max_image_side ?? "?"} px a side`]];
  for (const [k, v] of rows) info.append(Object.assign(document.createElement("dt"), { textContent: k }),
    Object.assign(document.createElement("dd"), { textContent: v ?? "?" }));
});

session.on("volumes", (volumes) => {
  const list = $("volume-list");
  list.replaceChildren(...volumes.map((v) => {
    const o = new Option(v.dims ? `${v.dims.join("×")}${v.loaded ? " · loaded" : ""}` : v.loaded ? "loaded" : "", v.name);
    return o;
  }));
});

session.on("loading", (l) => {
  if (l) { app.progress = null; app.openError = null; }
  $("open-volume").disabled = !!l;
  updateMessage();
});

session.on("progress", (p) => {
  if (p.id === null && session.volume && !session.loading) app.sceneProgress = p;
  else app.progress = p;
  updateMessage();
});

session.on("opened", ({ state, restored }) => {
  const volume = state.volume;
  app.startCamera = state.scene?.camera ?? null;
  app.camera = session.scene.camera ?? app.startCamera;
  // After a reconnection the same view comes back: keep its last image until the new one.
  app.renderError = null;
  if (!restored) {
    app.frameSinceOpen = false;
    view.clear();
    window.volcast.shown = null;
  }
  tfEditor.setVolume(volume);
  showTransferFunction(session.scene.transfer_function ?? state.scene?.transfer_function);
  quality.showState(state);
  crop.showState(state.scene?.quality);
  quality.setVolume(volume, session.scene.clip_planes);
  $("volume-name").value = volume?.name ?? "";
  $("volume-info").textContent = $("volume-info").title = describeVolume(volume);
  document.title = volume?.name ? `${volume.name} — volcast` : "volcast";
  const url = new URL(location.href);
  url.searchParams.set("volume", volume?.name ?? "");
  history.replaceState(null, "", url);
  updateMessage();
});

session.on("server_error", (e) => {
  errors.show(e);
  if (e.request_type === "open_volume" && !session.volume) app.openError = e;
  if ((e.code === "render_failed" || e.code === "internal") && !app.frameSinceOpen) app.renderError = e;
  updateMessage();
});

session.on("protocol_error", (e) => errors.show({ code: "client", message: e.message ?? String(e) }));

const frames = [];
session.on("frame", async (f) => {
  frames.push(f.header);
  if (frames.length > MAX_FRAMES_KEPT) frames.shift();
  app.sceneProgress = null;
  try {
    if (await view.show(f)) {
      app.frameSinceOpen = true;
      app.renderError = null;
      window.volcast.shown = f.header;
      stats.refresh();
      updateMessage();
    }
  } catch (e) {
    errors.show({ code: "client", message: `cannot decode frame ${f.header.seq} (${f.header.codec}): ${e.message}` });
  }
});

function describeVolume(v) {
  if (!v) return "";
  const parts = [v.name];
  if (v.dims) parts.push(v.dims.join("×"));
  if (v.voxel_type) parts.push(v.voxel_type);
  if (v.spacing) parts.push(`spacing ${v.spacing.map((s) => Number(s.toPrecision(3))).join("×")}`);
  if (v.value_range) parts.push(`range ${v.value_range.map((x) => Number(x.toPrecision(4))).join(" … ")}`);
  return parts.join(" · ");
}

// The message over the view: whatever explains a missing or stale image.
function updateMessage() {
  const state = session.connection.state;
  $("view").classList.toggle("stale", state !== "ready" && view.hasImage);
  if (state !== "ready") {
    const why = session.connection.lastCloseReason;
    if (state === "failed") return message.show({ kind: "error", title: "The server refused this page", detail: why || "" });
    if (view.hasImage) return message.show({ title: "Connection lost — reconnecting", detail: "The image is the last frame received." });
    return message.show({ title: "Connecting to the server…", detail: serverUrl, progress: true });
  }
  if (session.loading) {
    const p = app.progress;
    const share = STAGE_SHARE[p?.stage] ?? [0, 1];
    const overall = p ? share[0] + p.fraction * (share[1] - share[0]) : true;
    const detail = p ? `${p.stage}${p.task ? ` · ${p.task.replace(/_/g, " ")}` : ""} · ${Math.round(p.fraction * 100)} %` : "asking the server…";
    return message.show({ title: `Opening ${session.loading.name}`, detail, progress: overall });
  }
  if (!session.volume) {
    if (app.openError) return message.show({ kind: "error", title: "Could not open the volume", detail: `${app.openError.code}: ${app.openError.message}` });
    return message.show({ title: "No volume open", detail: "Choose a volume above." });
  }
  if (app.sceneProgress) {
    const p = app.sceneProgress;
    return message.show({ title: `Preparing ${(p.task ?? p.stage).replace(/_/g, " ")}`, detail: `${Math.round(p.fraction * 100)} %`, progress: p.fraction });
  }
  if (!app.frameSinceOpen) {
    if (app.renderError) return message.show({ kind: "error", title: "The server could not render this view", detail: `${app.renderError.code}: ${app.renderError.message}` });
    return message.show({ title: `Rendering ${session.volume.name}…`, progress: true });
  }
  message.show(null);
}

// --- volume picker and saving -----------------------------------------------------------

$("volume-form").addEventListener("submit", (e) => {
  e.preventDefault();
  const name = $("volume-name").value.trim();
  if (!name) return errors.show({ code: "volume", message: "type or choose a volume name first" });
  if (!session.ready) return errors.show({ code: "volume", message: "not connected to the server yet" });
  session.openVolume(name).catch((err) => errors.show({ code: "client", message: err.message }));
});

function download(blob, filename) {
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob);
  a.download = filename;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10000);
}

const fileStem = () => (session.volume?.name ?? "view").replace(/[^A-Za-z0-9._-]+/g, "_");

// The image on screen: the final frame's own PNG when it is the one shown (lossless, at the
// rendered size, premultiplied RGBA stored as straight RGBA), else the canvas.
function savePng() {
  const f = session.lastFrame;
  if (f?.header.final && f.header.seq === window.volcast.shown?.seq) {
    download(new Blob([f.image], { type: "image/png" }), `${fileStem()}-${f.header.seq}.png`);
  } else {
    $("view-canvas").toBlob((blob) => download(blob, `${fileStem()}-view.png`), "image/png");
  }
}

async function saveScene() {
  try {
    const scene = await session.sceneFile();
    download(new Blob([`${JSON.stringify(scene, null, 2)}\n`], { type: "application/json" }), `${fileStem()}-scene.json`);
  } catch (e) {
    errors.show({ code: e.code ?? "client", message: `cannot save the scene: ${e.serverMessage ?? e.message}` });
  }
}

$("save-png").addEventListener("click", savePng);
$("save-scene").addEventListener("click", saveScene);
$("reset-view").addEventListener("click", resetView);

// For the console and the browser tests: the session and the frame headers seen.
window.volcast = { session, view, frames, shown: null, savePng, saveScene };

// Closing the tab says goodbye, so the server frees the session at once.
window.addEventListener("pagehide", () => session.stop());
window.addEventListener("pageshow", (e) => { if (e.persisted) session.start(); });   // back from the page cache

updateViewport();
updateMessage();
session.start();
