// Opening a file from the user's disk: "Open file…" (an <input type=file>) or a file dropped
// anywhere on the page is uploaded (core/upload.js: POST /api/volumes, with progress), then
// opened by the name the server answers with. One upload at a time; while it runs the
// button cancels it.

import { ACCEPTED_EXTENSIONS, ACCEPT_ATTRIBUTE, UPLOAD_STATES, Upload, uploadText, uploadUrl } from "../core/upload.js";
import { formatBytes } from "../core/studies.js";

export class FileOpener {
  // options: serverUrl (the WebSocket's), token, open(volume, label), changed() (redraw the
  // message over the view), error(text) (a banner).
  constructor(root, session, { serverUrl, token, open, changed, error }) {
    this.session = session;
    this.url = uploadUrl(serverUrl);
    this.token = token;
    this.open = open;
    this.changed = changed;
    this.error = error;
    this.upload = null;
    this.button = root.getElementById("open-file");
    this.input = root.getElementById("file-input");
    this.overlay = root.getElementById("drop-overlay");
    this.input.accept = ACCEPT_ATTRIBUTE;
    this.button.addEventListener("click", () => (this.busy ? this.upload.cancel() : this.input.click()));
    this.input.addEventListener("change", () => {
      const files = [...this.input.files];
      this.input.value = "";   // the same file chosen again is a new upload
      this.take(files);
    });
    // Drag and drop anywhere on the page; the overlay says what a drop does.
    let depth = 0;
    const hasFiles = (e) => [...(e.dataTransfer?.types ?? [])].includes("Files");
    root.addEventListener("dragenter", (e) => { if (!hasFiles(e)) return; e.preventDefault(); depth++; this.overlay.hidden = false; });
    root.addEventListener("dragover", (e) => { if (!hasFiles(e)) return; e.preventDefault(); e.dataTransfer.dropEffect = "copy"; });
    root.addEventListener("dragleave", (e) => { if (!hasFiles(e)) return; depth = Math.max(0, depth - 1); if (!depth) this.overlay.hidden = true; });
    root.addEventListener("drop", (e) => {
      if (!hasFiles(e) && !e.dataTransfer?.files?.length) return;
      e.preventDefault();
      depth = 0;
      this.overlay.hidden = true;
      this.take([...e.dataTransfer.files]);
    });
    session.on("opened", ({ state }) => {
      if (this.upload?.state === UPLOAD_STATES.opening && state.volume?.name === this.upload.volume) { this.upload.opened(); this.show(); }
    });
    this.overlay.querySelector(".accepted").textContent = ACCEPTED_EXTENSIONS.filter((e) => e !== ".zip").join(", ");
  }

  get busy() { return this.upload?.state === UPLOAD_STATES.uploading; }

  take(files) {
    if (!files.length) return;
    if (files.length > 1) return this.error(`drop one file at a time (a DICOM series as one .zip); got ${files.length}`);
    if (this.busy) return this.error(`an upload is still running (${this.upload.file.name}): cancel it first`);
    if (!this.session.ready) return this.error("not connected to the server yet");
    const upload = new Upload(files[0], { url: this.url, token: this.token });
    this.upload = upload;
    upload.on("progress", () => this.show());
    upload.on("state", (s) => {
      if (upload !== this.upload) return;
      if (s.state === UPLOAD_STATES.opening) this.open(upload.volume, `${upload.file.name} (uploaded)`);
      // A failed open after the upload has its banner already (main.js words the server's error).
      if ((s.state === UPLOAD_STATES.failed && s.previous !== UPLOAD_STATES.opening) || s.state === UPLOAD_STATES.cancelled) this.error(uploadText(upload));
      this.show();
    });
    upload.start();
  }

  // Opening the uploaded volume failed (the server said why; main.js words it).
  openFailed(text) {
    if (this.upload?.state === UPLOAD_STATES.opening) { this.upload.failed(text); this.show(); }
  }

  show() {
    this.button.textContent = this.busy ? "Cancel upload" : "Open file…";
    this.button.setAttribute("aria-pressed", String(this.busy));
    this.changed();
  }

  // What the message over the view says while a file goes up: {title, detail, progress}, or null.
  uploadMessage() {
    const u = this.upload;
    if (!u || u.state !== UPLOAD_STATES.uploading) return null;
    return {
      title: `Uploading ${u.file.name}`,
      detail: `${formatBytes(u.loaded)} of ${formatBytes(u.total)} · ${Math.round(u.fraction * 100)} %`,
      progress: u.fraction,
    };
  }
}
