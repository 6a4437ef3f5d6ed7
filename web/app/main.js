// The page: wires the session (core/) to the view, the panels and the overlays.
//
// URL parameters: ?volume=NAME opens that volume first; ?server=ws://host:port/ws talks to
// another server than the one that served the page; ?token=T for a server started with
// --token. A view link's fragment (#volume=…&eye=…, core/view_link.js) opens its volume
// with its whole view: camera, transfer function, orientation, crop box, clip planes,
// compositing and projection window, and the slice panes' window/level, crosshair and slab.

import { orbit, pan, volumeBounds, zoom } from "../core/camera.js";
import { defaultServerUrl } from "../core/connection.js";
import { Session } from "../core/session.js";
import { presetPoints, problems, resolvePoints, tidyPoints } from "../core/transfer_function.js";
import { windowLevelStep } from "../core/window_level.js";
import { imageEdgeLabels, isAnatomical, mmPerPixelAtTarget, scaleBarLength } from "../core/orientation.js";
import { OrientationControls } from "./orientation_marker.js";
import { PresetPicker } from "./preset_picker.js";
import { tooLargeWords } from "../core/limits.js";
import { CropPanel } from "./crop_panel.js";
import { CropHandles } from "./crop_handles.js";
import { MeasureTools } from "./measure_tools.js";
import { QualityPanel, renderScaleFor } from "./quality_panel.js";
import { SliceViews } from "./slice_views.js";
import { StatsOverlay } from "./stats_overlay.js";
import { ConnectionIndicator, ErrorList, ViewMessage } from "./status.js";
import { TransferFunctionEditor } from "./tf_editor.js";
import { View } from "./view.js";
import { formatViewLink, parseViewLink } from "../core/view_link.js";
import { describeError, overallProgress, progressText } from "../core/studies.js";
import { StudiesPanel } from "./studies_panel.js";
import { FileOpener } from "./file_opener.js";

const CLIENT_NAME = "volcast-web 0.1.0";
const MAX_FRAMES_KEPT = 400;           // frame headers kept in window.volcast.frames (tests, console)

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const serverUrl = params.get("server") || defaultServerUrl(location);
const viewLink = parseViewLink(location.hash);   // {view, error}: refused whole when wrong

const session = new Session(serverUrl, {
  client: CLIENT_NAME,
  token: params.get("token") || undefined,
  preferredVolume: viewLink.view?.volume ?? (params.get("volume") || null),
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
  pendingLink: viewLink.view,   // the view link's camera and transfer function, until its volume opens
  lastOpening: null,        // the name of the latest open_volume: what an open error is about
  labels: new Map(),        // volume name → what the picker shows (an upload's file name, a series' description)
};

// Names of volumes a user brought (an upload's id is its only key; a PACS series names a
// study): kept out of the address's query string, which reaches server logs; the fragment does not.
const isPrivateName = (name) => /^(upload|dicomweb):/.test(name ?? "");

// --- widgets --------------------------------------------------------------------------

const errors = new ErrorList(document, (name) => openNamed(name));
const message = new ViewMessage(document);
const indicator = new ConnectionIndicator(document, () => session.connection.retryNow());
const stats = new StatsOverlay(document, session.stats);
if (viewLink.error) errors.show({ code: "view_link", message: viewLink.error });

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

// The crop panel adds quality.compositing and quality.crop to the switches, the
// orientation controls quality.orientation_correction.
const completePolicy = (policy) => (policy.quality
  ? { ...policy, quality: orientation.decorate(crop.decorate(policy.quality)) } : policy);
const sendPolicy = perAnimationFrame((policy) => session.setQualityPolicy(policy));

const quality = new QualityPanel(document, {
  onPolicy: (policy) => session.setQualityPolicy(completePolicy(policy)),
  onResolution: (choice) => { app.resolution = choice; updateViewport(); },
  onClip: (planes, { interactive }) => {
    if (!session.volume) return;
    if (interactive) { session.beginInteraction(); sendClip(planes); }
    else { sendClip.now(planes); session.endInteraction(); }
  },
});

const presetPicker = new PresetPicker(document, {
  apply(preset, { send }) {
    app.tf = { points: preset.points.map((p) => [...p]) };
    app.tfOpacityUnit = undefined;
    tfEditor.setPoints(app.tf.points);
    $("tf-preset").value = preset.name;
    const shading = $("q-shading");
    if (shading.checked !== preset.shading) {
      shading.checked = preset.shading;
      shading.dispatchEvent(new Event("change"));   // the quality panel sends it with its policy
    }
    if (send && session.volume) session.setTransferFunction(app.tf);
  },
});

const orientation = new OrientationControls(document, session, {
  setCamera(camera) { app.camera = camera; session.setCamera(camera); },
  getCamera: () => app.camera,
  getTarget: () => app.startCamera?.target ?? null,
  // A flip or turn of the volume travels with the quality switches, as the crop box does.
  onCorrection: () => { quality.touched = true; quality.schedule(); },
  // The clip slider spans the volume as drawn: a quarter turn swaps its extents.
  onCorrectionShown: (matrix) => quality.setCorrection(matrix),
});

// Compositing and crop box travel with the quality switches. A crop slider's drag is an
// interaction, as a camera drag is: between interaction_start and interaction_end the policy
// goes at most once per animation frame (the server answers with cheap frames), and the
// release sends it at once, for the refinement up to the final frame.
const crop = new CropPanel($("crop-card"), ({ interactive }) => {
  quality.touched = true;
  if (!session.volume) return quality.schedule();
  quality.cancelScheduled();
  if (interactive) { session.beginInteraction(); sendPolicy(completePolicy(quality.policy())); return; }
  sendPolicy.now(completePolicy(quality.policy()));
  if (!view.interacting) session.endInteraction();
});

// --- transfer function ----------------------------------------------------------------

function onTfEdited(points, interactive) {
  const bad = problems(points);
  if (bad.length) { errors.show({ code: "transfer_function", message: bad.join("; ") }); return; }
  errors.clear((e) => e.code === "transfer_function");
  app.tf = { points: tidyPoints(points) };
  if (app.tfOpacityUnit !== undefined) app.tf.opacity_unit = app.tfOpacityUnit;
  $("tf-preset").value = "";
  presetPicker.showMatching(app.tf.points);   // the note under the picker follows the curve shown
  if (!session.volume) return;
  if (interactive) { session.beginInteraction(); sendTf(app.tf); }
  else { sendTf.now(app.tf); if (!view.interacting) session.endInteraction(); }
}

$("tf-preset").addEventListener("change", () => {
  const name = $("tf-preset").value;
  if (!name || !session.volume) return;
  if (presetPicker.choose(name)) return;
  app.tf = { preset: name };
  tfEditor.setPoints(presetPoints(name, session.volume.value_range ?? [0, 1]));
  session.setTransferFunction(app.tf);
});

function windowLevelDrag(step) {
  // A projection (MIP, MinIP) is windowed by its own W/L, not the transfer function.
  if (crop.projecting) return crop.dragWindow(windowLevelStep(crop.effectiveWindow(), step.dx, step.dy, session.volume?.value_range ?? [0, 1]), true);
  const wl = tfEditor.windowLevel;
  if (!wl) return;
  const next = windowLevelStep(wl, step.dx, step.dy, session.volume?.value_range ?? [0, 1]);
  tfEditor.applyWindowLevel(next.window, next.level, true);
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
  // The indicator's new text can re-wrap the top bar and so resize the view: measure it now,
  // not at the last resize the observer reported, so the first frames have the view's size.
  if (s.state === "ready") { view.resetSequence(); view.measure(); updateViewport(); }
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

// The picker: the server's scans first, the synthetic builtin: phantoms in a group apart.
session.on("volumes", (volumes) => {
  const select = $("volume-select");
  const option = (v) => {
    const facts = [v.dims?.join("×"), v.loaded ? "loaded" : null].filter(Boolean).join(" · ");
    return new Option(facts ? `${v.name} (${facts})` : v.name, v.name);
  };
  const group = (label, list) => {
    const g = document.createElement("optgroup");
    g.label = label;
    g.append(...list.map(option));
    return g;
  };
  const scans = volumes.filter((v) => !v.name.startsWith("builtin:")).sort((a, b) => a.name.localeCompare(b.name));
  const phantoms = volumes.filter((v) => v.name.startsWith("builtin:"));
  const placeholder = new Option(scans.length ? "choose a volume…" : "no scans on the server: choose a phantom…", "");
  placeholder.disabled = true;
  select.replaceChildren(placeholder, group(`Scans (${scans.length})`, scans), group("Synthetic phantoms", phantoms));
  showOpenVolume();
});

function showOpenVolume() {
  const select = $("volume-select"), name = session.volume?.name ?? "";
  if (name && ![...select.options].some((o) => o.value === name)) select.append(new Option(app.labels.get(name) ?? name, name));
  select.value = name;
}

session.on("loading", (l) => {
  if (l) { app.progress = null; app.openError = null; app.lastOpening = l.name; }
  $("open-volume").disabled = $("volume-select").disabled = !!l;
  updateMessage();
});

session.on("progress", (p) => {
  // Preparation for an open volume (B-spline coefficients, a kernel variant): shown until it is done,
  // while the stand-in frames keep coming.
  if (p.stage === "preprocessing" && session.volume && !session.loading) app.sceneProgress = p.fraction < 1 ? p : null;
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
  // A volume that opened makes the errors of opening and of the scene before it stale (not
  // a refused view link's: the user has yet to read why the link's view is not there).
  if (!restored) errors.clear((e) => e.requestType === "open_volume" || SCENE_REQUESTS.includes(e.requestType) || ["volume", "client", "transfer_function"].includes(e.code));
  tfEditor.setVolume(volume);
  applyPendingLink(volume);
  showTransferFunction(session.scene.transfer_function ?? state.scene?.transfer_function);
  quality.showState(state);
  if (!restored) crop.setVolume(volume);
  crop.showState(state.scene?.quality);
  quality.setVolume(volume, session.scene.clip_planes, state.scene?.quality?.orientation_correction);
  showOpenVolume();
  // After the quality panel shows the state: a preset's shading then overrides it.
  presetPicker.setVolume(volume, app.tf, { restored });
  orientation.setVolume(volume, { keepHand: restored });
  orientation.showState(state.scene?.quality);
  orientation.showCamera(app.camera);
  $("volume-name").value = "";
  $("volume-info").textContent = $("volume-info").title = describeVolume(volume);
  document.title = volume?.name ? `${volume.name} — volcast` : "volcast";
  const url = new URL(location.href);
  // A view link names the view it opened; another volume makes it wrong.
  if (url.hash && parseViewLink(url.hash).view?.volume !== volume?.name && !app.pendingLink) url.hash = "";
  if (isPrivateName(volume?.name)) {
    url.searchParams.delete("volume");
    if (!url.hash) url.hash = formatViewLink({ volume: volume.name });   // a reload reopens it while it lives
  } else {
    url.searchParams.set("volume", volume?.name ?? "");
  }
  history.replaceState(null, "", url);
  updateMessage();
});

session.on("server_error", (e) => {
  // A volume the user brought (an upload, a PACS series): said in words, the server's reason after.
  // A series clicked in the studies panel is answered there, not over the view too.
  let saidInPanel = false;
  if (e.request_type === "open_volume" && isPrivateName(app.lastOpening)) {
    const said = describeError(e, { volume: app.lastOpening });
    saidInPanel = studies.showOpenError(e, app.lastOpening);
    e = { ...e, message: [said.title, said.detail].filter(Boolean).join(" ") };
    opener.openFailed(said.title);
  }
  // A series of several stacks offers each over the view, wherever it was opened from.
  if (!saidInPanel || e.stacks?.length) errors.show(e);
  // A refused quality policy leaves the server's: show that, not the refused values.
  if (e.request_type === "quality_policy") {
    session.getState().then((s) => { quality.showState(s); orientation.showState(s.scene?.quality); }, () => {});
  }
  if (e.request_type === "open_volume" && !session.volume) app.openError = e;
  if ((e.code === "render_failed" || e.code === "internal" || e.code === "too_large") && !app.frameSinceOpen) app.renderError = e;
  updateMessage();
});

session.on("protocol_error", (e) => errors.show({ code: "client", message: e.message ?? String(e) }));

const frames = [];
session.on("frame", async (f) => {
  frames.push(f.header);
  if (frames.length > MAX_FRAMES_KEPT) frames.shift();
  if (f.header.final) app.sceneProgress = null;
  try {
    if (await view.show(f)) {
      app.frameSinceOpen = true;
      app.renderError = null;
      // A frame answering a later request shows the scene works again: earlier scene errors go.
      const answered = f.header.request;
      if (typeof answered === "number") errors.clear((e) => SCENE_REQUESTS.includes(e.requestType) && e.request !== null && e.request < answered);
      errors.clear((e) => e.code === "decode");
      window.volcast.shown = f.header;
      stats.refresh();
      updateMessage();
    }
  } catch (e) {
    errors.show({ code: "decode", message: `cannot decode frame ${f.header.seq} (${f.header.codec}): ${e.message}` });
  }
});

const SCENE_REQUESTS = ["camera", "viewport", "transfer_function", "quality_policy", "clip_planes", "still"];

function describeVolume(v) {
  if (!v) return "";
  const parts = [app.labels.get(v.name) ?? v.name];
  if (v.dims) parts.push(v.dims.join("×"));
  if (v.voxel_type) parts.push(v.voxel_type);
  if (v.spacing) parts.push(`spacing ${v.spacing.map((s) => Number(s.toPrecision(3))).join("×")}`);
  if (v.value_range) parts.push(`range ${v.value_range.map((x) => Number(x.toPrecision(4))).join(" … ")}`);
  return parts.join(" · ");
}

// The message over the view: whatever explains a missing or stale image.
function updateMessage() {
  const state = session.connection.state;
  const upload = opener.uploadMessage();
  if (upload && state === "ready") return message.show(upload);
  $("view").classList.toggle("stale", state !== "ready" && view.hasImage);
  if (state !== "ready") {
    const why = session.connection.lastCloseReason;
    if (state === "failed") return message.show({ kind: "error", title: "The server refused this page", detail: why || "" });
    if (view.hasImage) return message.show({ title: "Connection lost — reconnecting", detail: "The image is the last frame received." });
    return message.show({ title: "Connecting to the server…", detail: serverUrl, progress: true });
  }
  if (session.loading) {
    const p = app.progress, name = session.loading.name;
    return message.show({ title: `Opening ${app.labels.get(name) ?? name}`, detail: progressText(p), progress: overallProgress(name, p) });
  }
  if (!session.volume) {
    if (app.openError) {
      if (isPrivateName(app.lastOpening)) return message.show({ kind: "error", title: describeError(app.openError, { volume: app.lastOpening }).title, detail: `${app.openError.code}: ${app.openError.message}` });
      return message.show({ kind: "error", title: "Could not open the volume", detail: `${app.openError.code}: ${app.openError.message}` });
    }
    return message.show({ title: "No volume open", detail: "Choose a volume above." });
  }
  if (app.sceneProgress) {
    const p = app.sceneProgress;
    return message.show({ title: `Preparing ${(p.task ?? p.stage).replace(/_/g, " ")}`, detail: `${Math.round(p.fraction * 100)} %`, progress: p.fraction });
  }
  if (!app.frameSinceOpen) {
    if (app.renderError?.code === "too_large") return message.show({ kind: "error", ...tooLargeWords(app.renderError) });
    if (app.renderError) return message.show({ kind: "error", title: "The server could not render this view", detail: `${app.renderError.code}: ${app.renderError.message}` });
    return message.show({ title: `Rendering ${session.volume.name}…`, progress: true });
  }
  message.show(null);
}

// --- volume picker and saving -----------------------------------------------------------

function openNamed(name) {
  if (!name) return errors.show({ code: "volume", message: "choose a volume (or type a name) first" });
  if (!session.ready) return errors.show({ code: "volume", message: "not connected to the server yet" });
  errors.clear((e) => e.code === "volume");
  session.openVolume(name).catch((err) => errors.show({ code: "client", message: err.message }));
}

// The typed name when there is one, else the list's choice; choosing in the list opens at once.
$("volume-form").addEventListener("submit", (e) => {
  e.preventDefault();
  openNamed($("volume-name").value.trim() || $("volume-select").value);
});
$("volume-select").addEventListener("change", () => {
  $("volume-name").value = "";
  openNamed($("volume-select").value);
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

// The image on screen, opaque over black as the view shows it: the final frame's own PNG
// when it is the one shown (lossless, at the rendered size), else the canvas. With "Letters
// and scale" it also carries the orientation letters at the edges (the file's axes where
// the patient axes are unknown, as on the page) and a scale bar at the volume's centre.
async function savePng() {
  const f = session.lastFrame;
  const final = f?.header.final && f.header.seq === window.volcast.shown?.seq;
  const source = final ? await createImageBitmap(new Blob([f.image], { type: "image/png" })) : $("view-canvas");
  const out = document.createElement("canvas");
  out.width = source.width;
  out.height = source.height;
  const g = out.getContext("2d");
  g.fillStyle = "#000";
  g.fillRect(0, 0, out.width, out.height);
  g.drawImage(source, 0, 0);
  const camera = (final ? f.header.camera : window.volcast.shown?.camera) ?? app.camera;
  window.volcast.lastSaved = $("save-annotate").checked && camera ? annotateImage(g, out.width, out.height, camera) : null;
  const name = final ? `${fileStem()}-${f.header.seq}.png` : `${fileStem()}-view.png`;
  out.toBlob((blob) => download(blob, name), "image/png");
}

// Orientation letters at the middle of each edge, a note on where they come from, and a
// scale bar; returns what was drawn (for the tests and the console).
function annotateImage(g, width, height, camera) {
  const source = orientation.source;
  const labels = imageEdgeLabels(camera, isAnatomical(source));
  const note = source === "axes" ? "orientation unknown: the file's axes" : source === "hand" ? "patient axes set by hand" : "";
  const px = Math.max(12, Math.round(Math.min(width, height) / 36));
  const pad = Math.round(px * 0.6);
  g.font = `bold ${px}px system-ui, sans-serif`;
  g.lineJoin = "round";
  const text = (s, x, y, align, baseline) => {
    g.textAlign = align;
    g.textBaseline = baseline;
    g.lineWidth = Math.max(2, px / 5);
    g.strokeStyle = "rgba(0, 0, 0, 0.85)";
    g.strokeText(s, x, y);
    g.fillStyle = "#fff";
    g.fillText(s, x, y);
  };
  text(labels.left, pad, height / 2, "left", "middle");
  text(labels.right, width - pad, height / 2, "right", "middle");
  text(labels.top, width / 2, pad, "center", "top");
  text(labels.bottom, width / 2, height - pad, "center", "bottom");
  g.font = `${Math.round(px * 0.7)}px system-ui, sans-serif`;
  if (note) text(note, pad, height - pad, "left", "bottom");
  // The bar is exact at the depth of the camera's target (the volume's centre) only, unless
  // the projection is orthographic: said beside it.
  const perPx = mmPerPixelAtTarget(camera, height);
  const bar = scaleBarLength(perPx, width * 0.25);
  let scale = null;
  if (bar) {
    const x1 = width - pad, x0 = x1 - bar.pixels, y = height - pad - Math.round(px * 1.2);
    g.fillStyle = "#fff";
    g.strokeStyle = "rgba(0, 0, 0, 0.85)";
    g.lineWidth = 1;
    g.fillRect(x0, y, bar.pixels, Math.max(2, px / 6));
    g.strokeRect(x0, y, bar.pixels, Math.max(2, px / 6));
    const words = `${bar.mm} mm${camera.projection === "orthographic" ? "" : " at the centre"}`;
    text(words, x1, height - pad, "right", "bottom");
    scale = { mm: bar.mm, pixels: bar.pixels, mmPerPixel: perPx, words };
  }
  return { labels, note, scale, width, height };
}

async function saveScene() {
  try {
    const scene = await session.sceneFile();
    // What the picture does not hold but the viewer showed (volcast-render ignores it): the
    // same fields a view link carries beyond the scene.
    const { orientation: orient, slice_window, crosshair, slab } = currentView();
    scene.viewer = JSON.parse(JSON.stringify({ orientation: orient, slice_window, crosshair, slab }));
    download(new Blob([`${JSON.stringify(scene, null, 2)}\n`], { type: "application/json" }), `${fileStem()}-scene.json`);
  } catch (e) {
    errors.show({ code: e.code ?? "client", message: `cannot save the scene: ${e.serverMessage ?? e.message}` });
  }
}

// --- view link, stats, full screen, phone layout ------------------------------------------

// The view link's camera and transfer function, once its volume (or, naming none, the first
// volume) has opened; the link's own problems were shown at start. The rest of the link
// waits until the panels and the slice panes have taken the new volume
// (applyRestOfLink, after every "opened" listener that puts a panel at its defaults).
function applyPendingLink(volume) {
  const link = app.pendingLink;
  if (!link || (link.volume && link.volume !== volume?.name)) return;
  app.pendingLink = null;
  app.pendingRest = link;
  if (link.transfer_function) session.setTransferFunction(link.transfer_function);
  if (link.camera) { app.camera = link.camera; session.setCamera(app.camera); }
}

function applyRestOfLink() {
  const link = app.pendingRest;
  app.pendingRest = null;
  if (!link || !session.volume) return;
  // Orientation first: the clip slider spans the box as drawn after it.
  if (link.orientation) orientation.applyOrientationView(link.orientation);
  if (link.clip_planes) {
    quality.setVolume(session.volume, link.clip_planes, orientation.correction);
    session.setClipPlanes(link.clip_planes);   // the link's planes as they are, not the slider's rounding
  }
  if (link.orientation || link.crop || link.compositing || link.projection_window) {
    crop.showState({
      compositing: link.compositing ?? "emission_absorption",
      crop: link.crop ?? { min: [0, 0, 0], max: [1, 1, 1] },
      ...(link.projection_window ? { projection_window: link.projection_window } : {}),
    });
    // One policy with all of it (the orientation's own scheduled send would only repeat it).
    quality.touched = true;
    quality.cancelScheduled();
    session.setQualityPolicy(completePolicy(quality.policy()));
  }
  if (link.slab) slices.setSlab({ thickness: link.slab.thickness, mode: link.slab.mode });
  if (link.slice_window) {
    slices.wl = { window: link.slice_window.window, level: link.slice_window.level };
    slices.showWindowLevel();
  }
  if (link.crosshair) slices.setPoint([...link.crosshair]);
  slices.requestAll();
}

// The whole view as core/view_link.js carries it: what this page sent, the server's
// defaults left out.
function currentView() {
  const q = completePolicy({ quality: quality.quality() }).quality;
  const planes = session.scene.clip_planes;
  return {
    volume: session.volume.name,
    camera: app.camera,
    transfer_function: app.tf,
    orientation: orientation.orientationView(),
    crop: q.crop,
    clip_planes: planes?.length ? planes : undefined,
    compositing: q.compositing,
    projection_window: q.projection_window,
    slice_window: slices.wl ? { ...slices.wl } : undefined,
    crosshair: slices.point ? [...slices.point] : undefined,
    slab: slices.slab && slices.slab.thickness > 0 ? { ...slices.slab } : undefined,
  };
}

function copyViewLink() {
  if (!session.volume) return errors.show({ code: "view_link", message: "open a volume first" });
  const url = new URL(location.href);
  url.hash = formatViewLink(currentView());
  history.replaceState(null, "", url);
  const button = $("copy-link");
  const said = (text) => { button.textContent = text; setTimeout(() => { button.textContent = "Link"; }, 1500); };
  // The address bar holds the link either way; the clipboard needs a secure context.
  (navigator.clipboard?.writeText(url.href) ?? Promise.reject(new Error("no clipboard"))).then(() => said("Copied"), () => said("In the address"));
}

const STATS_HIDDEN_KEY = "volcast.statsHidden";
function showStats(visible) {
  $("stats").hidden = !visible;
  $("toggle-stats").setAttribute("aria-pressed", String(visible));
  try { localStorage.setItem(STATS_HIDDEN_KEY, visible ? "" : "1"); } catch { /* storage off */ }
}
showStats((() => { try { return !localStorage.getItem(STATS_HIDDEN_KEY); } catch { return true; } })());

function toggleFullscreen() {
  if (document.fullscreenElement) return document.exitFullscreen();
  $("view").requestFullscreen().catch((e) => errors.show({ code: "client", message: `full screen refused: ${e.message}` }));
}
document.addEventListener("fullscreenchange", () => {
  $("fullscreen").setAttribute("aria-pressed", String(document.fullscreenElement === $("view")));
});

// Keys anywhere but in a field: S hides or shows the stats, F full screen.
document.addEventListener("keydown", (e) => {
  if (e.ctrlKey || e.metaKey || e.altKey || e.target.closest?.("input, select, textarea")) return;
  if (e.key === "s" || e.key === "S") showStats($("stats").hidden);
  else if (e.key === "f" || e.key === "F") toggleFullscreen();
});

// On a phone the stats leave the view for the top of the panel below it: nothing covers the image.
const PHONE = matchMedia("(max-width: 600px)");
function placeStats() {
  const box = $("stats");
  if (PHONE.matches) $("panel").prepend(box); else $("view").insertBefore(box, $("errors"));
  box.classList.toggle("docked", PHONE.matches);
}
PHONE.addEventListener("change", placeStats);
placeStats();

// A number field shows what is applied: a value the field's own limits refuse (or no
// number at all) is not sent; the applied one comes back, marked invalid until retyped.
const panel = $("panel");
panel.addEventListener("focusin", (e) => { if (e.target.type === "number") e.target.dataset.applied = e.target.value; });
panel.addEventListener("change", (e) => {
  const el = e.target;
  if (el.type !== "number") return;
  const v = el.validity;
  if (!(v.badInput || v.rangeOverflow || v.rangeUnderflow || el.value.trim() === "")) { el.dataset.applied = el.value; return; }
  e.stopImmediatePropagation();
  const refused = el.value;
  el.value = el.dataset.applied ?? "";
  el.setAttribute("aria-invalid", "true");
  el.title = `${refused === "" ? "no number" : `"${refused}"`} refused: ${el.min !== "" ? `at least ${el.min}` : ""}${el.min !== "" && el.max !== "" ? ", " : ""}${el.max !== "" ? `at most ${el.max}` : ""}; showing the value in use`;
  el.addEventListener("input", () => { el.removeAttribute("aria-invalid"); el.title = ""; }, { once: true });
}, true);

$("copy-link").addEventListener("click", copyViewLink);
$("toggle-stats").addEventListener("click", () => showStats($("stats").hidden));
$("fullscreen").addEventListener("click", toggleFullscreen);
$("save-png").addEventListener("click", savePng);
$("save-scene").addEventListener("click", saveScene);
$("reset-view").addEventListener("click", resetView);

// For the console and the browser tests: the session and the frame headers seen.
const slices = new SliceViews(document, session, $("slices"), $("view"));
// Crop handles first: a press on a handle is theirs before a measurement's.
const cropHandles = new CropHandles(document, session, crop, slices, $("view"));
const measure = new MeasureTools(document, session, slices, $("view"));
// After the panes' own "opened" (which puts the crosshair and window at the new volume's defaults).
session.on("opened", () => applyRestOfLink());

// A volume the user brings: a series from a PACS (the studies panel), a file from their disk.
function openBrought(name, label) {
  if (label) app.labels.set(name, label);
  openNamed(name);
}
const studies = new StudiesPanel($("studies-card"), session, { onOpen: openBrought });
const opener = new FileOpener(document, session, {
  serverUrl, token: params.get("token") || undefined,
  open: (name, label) => openBrought(name, label),
  changed: () => updateMessage(),
  error: (text) => errors.show({ code: "upload", message: text }),
});
window.volcast = { session, view, tfEditor, frames, shown: null, savePng, saveScene, orientation, slices, studies, opener, crop, cropHandles, measure };

// Closing the tab says goodbye, so the server frees the session at once.
window.addEventListener("pagehide", () => session.stop());
window.addEventListener("pageshow", (e) => { if (e.persisted) session.start(); });   // back from the page cache

updateViewport();
updateMessage();
session.start();
