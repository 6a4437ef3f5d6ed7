// What the page tells the user: the connection indicator, server errors, and the message
// over the view whenever it has no current image to show (never a black canvas without
// an explanation).

import { tooLargeWords } from "../core/limits.js";

export const ERROR_SHOW_MS = 20000;   // ms an error stays up unless dismissed
export const MAX_ERRORS_SHOWN = 4;

export class ConnectionIndicator {
  constructor(root, onRetry) {
    this.box = root.getElementById("connection");
    this.text = root.getElementById("connection-text");
    this.retry = root.getElementById("retry-now");
    this.retry.addEventListener("click", onRetry);
    this.countdown = null;
  }

  // s: the connection's "state" event; connection: for retryAt and the server hello.
  show(s, connection) {
    clearInterval(this.countdown);
    this.box.dataset.state = s.state;
    this.retry.hidden = !(s.state === "waiting" || s.state === "failed");
    const hello = connection.serverHello;
    switch (s.state) {
      case "connecting": this.text.textContent = s.attempt ? `Reconnecting (attempt ${s.attempt + 1})…` : "Connecting…"; break;
      case "handshaking": this.text.textContent = "Saying hello…"; break;
      case "ready":
        this.text.textContent = `Connected · ${hello?.device?.name ?? "server"}${hello?.device?.type ? ` (${hello.device.type})` : ""}`;
        this.box.title = `${hello?.server ?? ""} at ${connection.url}`;
        break;
      case "waiting": {
        const tick = () => {
          const left = Math.max(0, (connection.retryAt ?? 0) - performance.now());
          this.text.textContent = `Disconnected · retrying in ${(left / 1000).toFixed(left < 10000 ? 1 : 0)} s`;
        };
        tick();
        this.countdown = setInterval(tick, 100);
        this.box.title = s.reason ?? "";
        break;
      }
      case "failed": this.text.textContent = `Refused: ${s.reason}`; break;
      case "closed": this.text.textContent = "Closed"; break;
      default: this.text.textContent = s.state;
    }
  }
}

// "120 axial slices, 512 × 512" for one stack a refused series offers.
export function stackLabel(s) {
  const slices = `${s.slices} ${s.orientation && s.orientation !== "unknown" ? `${s.orientation} ` : ""}slice${s.slices === 1 ? "" : "s"}`;
  return `${slices}, ${s.columns} × ${s.rows}${s.localizer ? " (localizer)" : ""}`;
}

export class ErrorList {
  // openVolume(name): what a stack's button does (a series of several stacks offers each).
  constructor(root, openVolume = () => {}) {
    this.box = root.getElementById("errors");
    this.openVolume = openVolume;
  }

  // e: {code, message, request_type?, stacks?}. Shown as the server wrote it: the code and its
  // words; a picture over the server's limits in words about the picture (the server's message,
  // which names the flag for scripts and operators, in the tooltip); the stacks of a series that
  // one volume cannot show as buttons that open each.
  show(e) {
    const item = document.createElement("div");
    item.className = "error";
    item.setAttribute("role", "alert");
    item.dataset.code = e.code ?? "";
    item.dataset.requestType = e.request_type ?? "";
    if (typeof e.id === "number") item.dataset.request = String(e.id);
    const code = document.createElement("span");
    code.className = "code";
    code.textContent = e.code ?? "error";
    const text = document.createElement("span");
    text.className = "text";
    if (e.code === "too_large") {
      const words = tooLargeWords(e);
      code.textContent = "too large";
      text.textContent = [words.title, words.detail].filter(Boolean).join(". ");
      text.title = e.message ?? "";
    } else {
      text.textContent = e.request_type ? `${e.message} (${e.request_type})` : e.message;
    }
    const close = document.createElement("button");
    close.type = "button";
    close.textContent = "✕";
    close.title = "Dismiss";
    close.addEventListener("click", () => item.remove());
    item.append(code, text, close);
    if (Array.isArray(e.stacks) && e.stacks.length > 0) {
      const stacks = document.createElement("div");
      stacks.className = "stacks";
      for (const s of e.stacks) {
        const open = document.createElement("button");
        open.type = "button";
        open.dataset.volume = s.volume;
        open.textContent = `Open ${stackLabel(s)}`;
        open.addEventListener("click", () => { item.remove(); this.openVolume(s.volume); });
        stacks.append(open);
      }
      item.append(stacks);
    }
    this.box.prepend(item);
    while (this.box.children.length > MAX_ERRORS_SHOWN) this.box.lastElementChild.remove();
    setTimeout(() => item.remove(), ERROR_SHOW_MS);
  }

  // Take down the errors that something which has since worked makes stale:
  // which({code, requestType, request}) says whether an error goes.
  clear(which = () => true) {
    for (const item of [...this.box.children]) {
      const d = item.dataset;
      if (which({ code: d.code, requestType: d.requestType, request: d.request === undefined ? null : Number(d.request) })) item.remove();
    }
  }
}

export class ViewMessage {
  constructor(root) {
    this.box = root.getElementById("view-message");
    this.title = root.getElementById("view-message-title");
    this.detail = root.getElementById("view-message-detail");
    this.progress = root.getElementById("load-progress");
    this.bar = this.progress.querySelector(".bar");
  }

  // m: null to hide, or {title, detail?, kind?, progress? (0…1, or true for indeterminate)}.
  show(m) {
    this.box.hidden = !m;
    if (!m) return;
    this.box.dataset.kind = m.kind ?? "info";
    this.title.textContent = m.title;
    this.detail.textContent = m.detail ?? "";
    this.progress.hidden = m.progress === undefined;
    this.progress.classList.toggle("indeterminate", m.progress === true);
    if (typeof m.progress === "number") this.bar.style.width = `${Math.round(m.progress * 100)}%`;
  }
}
