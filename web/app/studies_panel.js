// The studies panel: search a DICOMweb source of the server (protocol/README.md's
// `find_studies`), list its studies, expand one to its series, click a series to open it.
// Shown only when the server's volume list names sources. Patient names are shown, never
// logged: nothing here writes to the console.

import {
  COMMON_MODALITIES, QueryError, buildStudyQuery, describeError, formatPatientName, formatStudyDate, normaliseStudies,
  overallProgress, progressText, sourceOf,
} from "../core/studies.js";

const el = (tag, props = {}, ...children) => {
  const e = Object.assign(document.createElement(tag), props);
  e.append(...children.filter((c) => c !== null && c !== undefined));
  return e;
};

export class StudiesPanel {
  // card: the <details> to fill; session: core/session.js; onOpen(volume, label): open a series.
  constructor(card, session, { onOpen }) {
    this.card = card;
    this.session = session;
    this.onOpen = onOpen;
    this.searchSeq = 0;       // answers to an older search are dropped
    this.studies = [];
    this.opening = null;      // the volume name of the series being opened from here
    this.clicked = null;      // the series last clicked here, until its open ends
    this.build();
    session.on("sources", (sources) => this.setSources(sources));
    session.on("progress", (p) => this.onProgress(p));
    session.on("loading", (l) => this.onLoading(l));
    session.on("opened", ({ state }) => this.onOpened(state.volume?.name));
  }

  build() {
    const field = (id, label, input) => [el("label", { htmlFor: id, textContent: label }), Object.assign(input, { id })];
    this.source = el("select", { title: "The image archive (PACS) to search" });
    this.name = el("input", { placeholder: "DOE^J* (* any, ? one)", spellcheck: false, autocomplete: "off",
      title: "Patient name, family^given or family, given. Without * or ? it finds names that start with it" });
    this.patientId = el("input", { spellcheck: false, autocomplete: "off", title: "Patient ID, exactly" });
    this.date = el("input", { placeholder: "YYYY-MM-DD, or from – to", autocomplete: "off",
      title: "A study date, or a range from – to (either end may be left out)" });
    this.modality = el("select", { title: "Modality of any series in the study" },
      new Option("any", ""), ...COMMON_MODALITIES.map((m) => new Option(m, m)));
    this.searchButton = el("button", { type: "submit", textContent: "Search", id: "study-search-button" });
    this.form = el("form", { id: "study-search", className: "study-search", autocomplete: "off" },
      el("div", { className: "grid-fields" },
        ...field("study-source", "Source", this.source),
        ...field("study-patient-name", "Patient name", this.name),
        ...field("study-patient-id", "Patient ID", this.patientId),
        ...field("study-date", "Study date", this.date),
        ...field("study-modality", "Modality", this.modality)),
      el("div", { className: "row end" }, this.searchButton));
    this.status = el("div", { id: "study-status", className: "study-status muted small", role: "status" });
    this.list = el("ul", { id: "study-list", className: "study-list" });
    this.list.setAttribute("aria-label", "Studies found");
    this.openStatus = el("div", { id: "study-open-status", className: "study-open-status small", hidden: true },
      el("div", { className: "text" }), el("div", { className: "progress" }, el("div", { className: "bar" })));
    this.card.replaceChildren(el("summary", { textContent: "Studies" }), this.form, this.status, this.openStatus, this.list);
    this.form.addEventListener("submit", (e) => { e.preventDefault(); this.search(); });
    this.form.addEventListener("input", (e) => e.target.removeAttribute("aria-invalid"));
  }

  setSources(sources) {
    const names = sources.map((s) => s.name);
    this.card.hidden = names.length === 0;
    const keep = this.source.value;
    this.source.replaceChildren(...sources.map((s) => new Option(s.kind ? `${s.name} (${s.kind})` : s.name, s.name)));
    if (names.includes(keep)) this.source.value = keep;
  }

  showStatus(text, kind = "info") {
    this.status.dataset.kind = kind;
    this.status.setAttribute("role", kind === "error" ? "alert" : "status");
    this.status.replaceChildren(...(Array.isArray(text) ? text : [text]).map((t, i) => (i ? el("div", { className: "detail", textContent: t }) : el("div", { textContent: t }))));
  }

  async search() {
    let query;
    try {
      query = buildStudyQuery({
        source: this.source.value, patientName: this.name.value, patientId: this.patientId.value,
        studyDate: this.date.value, modality: this.modality.value,
      });
    } catch (e) {
      if (!(e instanceof QueryError)) throw e;
      const input = { patient_name: this.name, patient_id: this.patientId, study_date: this.date, modality: this.modality, source: this.source }[e.field];
      input?.setAttribute("aria-invalid", "true");
      this.showStatus(e.message, "error");
      return;
    }
    const seq = ++this.searchSeq;
    this.searchButton.disabled = true;
    this.showStatus(`Searching ${query.source}…`);
    try {
      const reply = await this.session.findStudies(query);
      if (seq !== this.searchSeq) return;
      this.showStudies(normaliseStudies(reply), query);
    } catch (e) {
      if (seq !== this.searchSeq) return;
      const said = e.code ? describeError({ code: e.code, message: e.serverMessage, request_type: "find_studies" }, { source: query.source })
        : { title: "The search did not reach the server.", detail: e.message };
      this.list.replaceChildren();
      this.showStatus([said.title, said.detail].filter(Boolean), "error");
      this.status.dataset.code = e.code ?? "client";
    } finally {
      if (seq === this.searchSeq) this.searchButton.disabled = false;
    }
  }

  showStudies(studies, query) {
    this.studies = studies;
    delete this.status.dataset.code;
    const more = studies.length >= query.limit ? ` (the first ${query.limit}: narrow the search to see others)` : "";
    this.showStatus(studies.length ? `${studies.length} ${studies.length === 1 ? "study" : "studies"}${more}` : "No studies match.");
    this.list.replaceChildren(...studies.map((s) => this.studyItem(s)));
  }

  studyItem(study) {
    const series = el("ul", { className: "series-list", hidden: true },
      ...(study.series.length ? study.series.map((s) => this.seriesItem(study, s))
        : [el("li", { className: "muted small", textContent: "No series the server can open." })]));
    const who = formatPatientName(study.patient_name) || "(no name)";
    const head = el("button", { type: "button", className: "study-head" },
      el("span", { className: "line1" },
        el("span", { className: "patient", textContent: who }),
        el("span", { className: "date", textContent: formatStudyDate(study.study_date) })),
      el("span", { className: "line2 muted" },
        el("span", { className: "pid", textContent: study.patient_id ? `ID ${study.patient_id}` : "" }),
        el("span", { className: "desc", textContent: study.description }),
        el("span", { className: "mods", textContent: study.modalities.join(" ") })));
    head.setAttribute("aria-expanded", "false");
    head.addEventListener("click", () => {
      const open = series.hidden;
      series.hidden = !open;
      head.setAttribute("aria-expanded", String(open));
    });
    return el("li", { className: "study" }, head, series);
  }

  seriesItem(study, s) {
    const images = s.instances === null ? "" : `${s.instances} ${s.instances === 1 ? "image" : "images"}`;
    const button = el("button", { type: "button", className: "series", title: `Open this series (${s.volume})` },
      el("span", { className: "mod", textContent: s.modality || "?" }),
      el("span", { className: "desc", textContent: s.description || "(no description)" }),
      el("span", { className: "count muted", textContent: images }));
    button.dataset.volume = s.volume;
    const label = [formatPatientName(study.patient_name), s.modality, s.description].filter(Boolean).join(" · ");
    button.addEventListener("click", () => { this.clicked = s.volume; this.onOpen(s.volume, label); });
    return el("li", {}, button);
  }

  // --- opening a series ------------------------------------------------------------------

  mark(volume, cls, on) {
    for (const b of this.list.querySelectorAll("button.series")) if (b.dataset.volume === volume) b.classList.toggle(cls, on);
  }

  onLoading(l) {
    if (l && sourceOf(l.name)) {
      this.opening = l.name;
      this.mark(l.name, "opening", true);
      this.showOpen(progressText(null), true);
    } else if (!l && this.opening) {
      this.mark(this.opening, "opening", false);
    }
  }

  onProgress(p) {
    if (!this.opening || this.session.loading?.name !== this.opening) return;
    this.showOpen(progressText(p), overallProgress(this.opening, p));   // the same bar as over the view
  }

  onOpened(name) {
    for (const b of this.list.querySelectorAll("button.series")) b.classList.toggle("current", b.dataset.volume === name);
    if (this.opening && name === this.opening) { this.opening = null; this.openStatus.hidden = true; this.openStatus.title = ""; }
    if (this.clicked === name) this.clicked = null;
  }

  // A refused open of a series: said in the panel, in words. True when it was a series
  // clicked here (the panel is where the user looks; no banner needed over the view).
  showOpenError(e, volume) {
    if (!sourceOf(volume)) return false;
    this.mark(volume, "opening", false);
    this.opening = null;
    const said = describeError(e, { volume });
    this.showOpen([said.title, said.detail].filter(Boolean), null, "error");
    this.openStatus.dataset.code = e.code ?? "";
    this.openStatus.title = said.detail;   // the whole reason; the panel shows its first lines
    const fromHere = this.clicked === volume && !this.card.hidden;
    this.clicked = null;
    return fromHere;
  }

  showOpen(text, fraction, kind = "info") {
    this.openStatus.hidden = false;
    this.openStatus.dataset.kind = kind;
    const lines = Array.isArray(text) ? text : [text];
    this.openStatus.querySelector(".text").replaceChildren(...lines.map((t) => el("div", { textContent: t })));
    const bar = this.openStatus.querySelector(".progress");
    bar.hidden = fraction === null;
    bar.classList.toggle("indeterminate", fraction === true);
    if (typeof fraction === "number") bar.firstChild.style.width = `${Math.round(Math.min(1, Math.max(0, fraction)) * 100)}%`;
  }
}
