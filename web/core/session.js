// A viewing session on top of a Connection: the volume list, the open volume, the scene
// as this client wants it (camera, transfer function, clip planes, viewport, quality
// policy), loading progress, frames and their statistics. After a reconnection it puts
// the same view back: viewport and policy, the same volume, then camera, transfer function
// and clip planes — the server restarted with none of them.
//
// No DOM here: the app listens to the events and draws; tests drive it with a fake socket.
//
// Events: "connection" (Connection "state" payload), "hello", "volumes" (array), "sources"
// (the server's DICOMweb sources, [{name, kind}], with every volume list), "progress"
// (progress message), "loading" ({name} | null), "state" (a server `state`), "opened"
// ({state, restored}: a volume is open and, after a reconnection, the view put back), "frame" ({header, image, latency}), "server_error" (error message),
// "protocol_error" (Error), "scene" (a local scene change was sent).

import { Connection, STATES } from "./connection.js";
import { Emitter } from "./emitter.js";
import { SCENE_CHANGING, ServerError, requests } from "./protocol.js";
import { FrameStats } from "./stats.js";

// The volume to open first: the one asked for (URL), else the first the server has
// loaded already (its default volume), else none (the picker asks the user).
export function chooseInitialVolume(volumes, preferred) {
  if (preferred) return preferred;
  return volumes.find((v) => v.loaded)?.name ?? null;
}

export class Session extends Emitter {
  // options: Connection options plus `preferredVolume` (name to open first) and
  // `autoOpen` (default true: open chooseInitialVolume's pick once connected).
  constructor(url, options = {}) {
    super();
    this.connection = options.connection ?? new Connection(url, options);
    this.stats = new FrameStats();
    this.preferredVolume = options.preferredVolume ?? null;
    this.autoOpen = options.autoOpen ?? true;
    this.volumes = [];
    this.sources = [];           // the server's image archives: [{name, kind: "dicomweb"}]
    this.volume = null;          // the open volume's object (protocol `volumes` form)
    this.wantedVolume = null;    // the name this client means to have open
    this.loading = null;         // {name} while an open_volume is in flight
    this.scene = {};             // last scene the server reported, updated by what we sent
    this.policy = null;          // the quality policy we sent (null: the server's default)
    this.viewport = null;        // {width, height} wanted
    this.interacting = false;
    this.hasView = false;        // camera/TF/clips of `volume` were set by this client
    this.lastFrame = null;       // latest {header, image}
    this.lastFinal = null;       // latest final frame
    this.serverState = null;     // latest `state` message

    const c = this.connection;
    c.on("state", (s) => this.onConnectionState(s));
    c.on("hello", (h) => this.emit("hello", h));
    c.on("sent", ({ message, at }) => {
      if (SCENE_CHANGING.has(message.type) || message.type === "interaction_end") this.stats.noteSent(message, at);
    });
    c.on("message", (m) => this.onMessage(m));
    c.on("frame", (f) => this.onFrame(f));
    c.on("error", (e) => this.emit("server_error", e));
    c.on("protocol_error", (e) => this.emit("protocol_error", e));
  }

  start() { this.connection.connect(); }
  stop() { this.connection.close(); }
  get ready() { return this.connection.state === STATES.ready; }
  get hello() { return this.connection.serverHello; }

  // --- connection lifecycle -------------------------------------------------------------

  onConnectionState(s) {
    if (s.state !== STATES.ready) {
      if (this.loading) { this.loading = null; this.emit("loading", null); }
      this.interacting = false;
    }
    this.emit("connection", s);
    if (s.state === STATES.ready) this.onReady().catch((e) => this.reportFailure(e));
  }

  // Once connected: list volumes, send viewport and policy, reopen our volume and put the
  // view back as it was.
  async onReady() {
    this.stats.reset();
    await this.refreshVolumes();
    if (this.viewport) this.sendIfReady(requests.viewport(this.viewport.width, this.viewport.height));
    if (this.policy) this.sendIfReady(this.policyRequest(this.policy));
    const name = this.wantedVolume ?? (this.autoOpen ? chooseInitialVolume(this.volumes, this.preferredVolume) : null);
    if (!name) return;
    const restore = this.hasView && this.wantedVolume === name
      ? { camera: this.scene.camera, transfer_function: this.scene.transfer_function, clip_planes: this.scene.clip_planes }
      : null;
    await this.openVolume(name, restore);
  }

  async refreshVolumes() {
    const reply = await this.connection.request(requests.listVolumes());
    this.volumes = Array.isArray(reply.volumes) ? reply.volumes : [];
    this.sources = Array.isArray(reply.sources)
      ? reply.sources.filter((s) => s && typeof s.name === "string" && s.name).map((s) => ({ name: s.name, kind: String(s.kind ?? "") }))
      : [];
    this.emit("volumes", this.volumes);
    this.emit("sources", this.sources);
    return this.volumes;
  }

  // Search a source: query is a `find_studies` request (core/studies.js's buildStudyQuery).
  // Resolves with the server's `studies` answer; rejects with ServerError (source_failed,
  // not_found, bad_field) or ConnectionLost.
  findStudies(query) {
    if (!this.ready) return Promise.reject(new Error("not connected to the server"));
    return this.connection.request(query);
  }

  // --- requests -------------------------------------------------------------------------

  // Open a volume; restore (optional) is a view to put back once it is open. Resolves with
  // the server's `state`, or null when the server refused (the error is emitted).
  async openVolume(name, restore = null) {
    if (!this.ready) throw new Error("not connected");
    const previous = this.wantedVolume;
    this.loading = { name };
    this.emit("loading", this.loading);
    let state;
    try {
      state = await this.connection.request(requests.openVolume(name));
    } catch (e) {
      this.loading = null;
      this.emit("loading", null);
      if (e instanceof ServerError) {
        // The server keeps the previous volume open (a refused request changes nothing).
        this.wantedVolume = previous;
        this.emit("server_error", { code: e.code, message: e.serverMessage, id: e.id, request_type: e.requestType, stacks: e.stacks });
        return null;
      }
      throw e;
    }
    this.loading = null;
    this.emit("loading", null);
    this.wantedVolume = name;
    this.hasView = false;
    if (restore) {
      if (restore.transfer_function) this.setTransferFunction(restore.transfer_function);
      if (restore.clip_planes?.length) this.setClipPlanes(restore.clip_planes);
      if (restore.camera) this.setCamera(restore.camera);
    }
    this.emit("opened", { state, restored: !!restore });
    return state;
  }

  setCamera(camera) { this.changeScene("camera", camera, requests.camera(camera)); }
  setTransferFunction(tf) { this.changeScene("transfer_function", tf, requests.transferFunction(tf)); }
  setClipPlanes(planes) { this.changeScene("clip_planes", planes, requests.clipPlanes(planes)); }

  changeScene(key, value, message) {
    this.scene = { ...this.scene, [key]: value };
    this.hasView = true;
    if (this.volume && this.sendIfReady(message) !== null) this.emit("scene", { key, value });
  }

  setViewport(width, height) {
    const w = Math.max(1, Math.round(width)), h = Math.max(1, Math.round(height));
    if (this.viewport && this.viewport.width === w && this.viewport.height === h) return false;
    this.viewport = { width: w, height: h };
    this.scene = { ...this.scene, image: { ...this.viewport } };
    this.sendIfReady(requests.viewport(w, h));
    return true;
  }

  // policy: {mode: "automatic", target_frame_ms, quality?} or {mode: "explicit", quality}.
  setQualityPolicy(policy) {
    this.policy = policy;
    if (this.sendIfReady(this.policyRequest(policy)) !== null) this.emit("policy", policy);
  }

  policyRequest(p) {
    return p.mode === "explicit" ? requests.qualityExplicit(p.quality) : requests.qualityAutomatic(p.target_frame_ms, p.quality);
  }

  beginInteraction() {
    if (this.interacting) return;
    this.interacting = true;
    this.sendIfReady(requests.interactionStart());
  }

  endInteraction() {
    if (!this.interacting) return;
    this.interacting = false;
    this.sendIfReady(requests.interactionEnd());
  }

  getState() { return this.connection.request(requests.getState()); }

  // Measurements (protocol/README.md's probe, roi_stats, pick): each resolves with the
  // server's answer, rejects with ServerError (bad_state, bad_field) or when not connected.
  // They never change the scene.
  probe(point) { return this.measureRequest(requests.probe(point)); }
  roiStats(axis, center, radii, shape) { return this.measureRequest(requests.roiStats(axis, center, radii, shape)); }
  pick(x, y, width, height) { return this.measureRequest(requests.pick(x, y, width, height)); }
  measureRequest(message) {
    if (!this.ready) return Promise.reject(new Error("not connected to the server"));
    return this.connection.request(message);
  }

  // Send when connected; returns the id, or null when not connected (the wanted state is
  // kept and sent again after reconnecting).
  sendIfReady(message) {
    if (!this.ready) return null;
    return this.connection.send(message);
  }

  // --- incoming -------------------------------------------------------------------------

  onMessage(m) {
    if (m.type === "progress") this.emit("progress", m);
    else if (m.type === "volumes") { this.volumes = m.volumes ?? []; }
    else if (m.type === "state") this.onState(m);
  }

  onState(m) {
    this.serverState = m;
    if (m.volume) {
      this.volume = m.volume;
      const i = this.volumes.findIndex((v) => v.name === m.volume.name);
      if (i >= 0) this.volumes[i] = m.volume; else this.volumes.push(m.volume);
    }
    // Keys the client set since stay as the client set them (they are in flight).
    this.scene = { ...(m.scene ?? {}) };
    if (this.viewport) this.scene.image = { ...this.viewport };
    if (m.quality_policy && !this.policy) this.serverPolicy = m.quality_policy;
    this.emit("state", m);
  }

  onFrame(frame) {
    const latency = this.stats.noteFrame(frame.header, frame.receivedAt);
    this.lastFrame = frame;
    if (frame.header.final) this.lastFinal = frame;
    this.emit("frame", { ...frame, latency });
  }

  reportFailure(e) {
    // A lost connection during onReady is normal (the server went away again).
    if (e?.name === "ConnectionLost") return;
    this.emit("protocol_error", e);
  }

  // --- saving ---------------------------------------------------------------------------

  // The scene as a file volcast-render accepts (docs/design.md's scene file), from the server's
  // own view of the session (get_state). When a final frame of the current view is on
  // screen, its quality switches and size are used, so that the file reproduces exactly
  // that frame. The volume is the server's name for it (see web/README.md).
  async sceneFile() {
    const state = await this.getState();
    const scene = structuredClone(state.scene ?? {});
    const final = this.lastFrame?.header.final ? this.lastFrame.header : null;
    if (final) {
      if (final.quality) scene.quality = structuredClone(final.quality);
      scene.image = { width: final.width, height: final.height };
      if (final.camera) scene.camera = structuredClone(final.camera);
    }
    if (Array.isArray(scene.clip_planes) && scene.clip_planes.length === 0) delete scene.clip_planes;
    return scene;
  }
}
