// What the browser suites check of a volume whose file names no patient axes: no label on
// the page names a patient direction (flip.test.mjs on builtin:demo, orient.test.mjs on a
// scan file).
import assert from "node:assert/strict";

export const ANATOMICAL_LETTERS = new Set(["R", "L", "A", "P", "S", "I"]);
export const ANATOMICAL_WORDS = /\b(anterior|posterior|superior|inferior|left|right)\b/i;
const SIDES = /\b(anterior|posterior|superior|inferior)\b/i;

// Every label on the page that could name a direction: the orientation card's and the
// marker's text and tooltips, the slice panes' edge letters, the note over the view, and
// the page's visible text as a whole (split into words: a lone R, L, A, P, S or I). The
// tooltips of "Treat as LPS" and "Treat as RAS" are left out: they say what each choice
// would mean, which is what the user is asked to decide.
export const directionLabels = (page) => page.evaluate(() => {
  const card = document.getElementById("orientation-card");
  const marker = document.getElementById("orientation-marker");
  const texts = [...card.querySelectorAll("button, summary, div")]
    .flatMap((el) => [el.textContent, el.closest("#orientation-treat") ? "" : el.title ?? ""]);
  return {
    card: texts,
    marker: [marker.dataset.right, marker.dataset.up, marker.dataset.toward, marker.getAttribute("aria-label") ?? ""],
    edges: [...document.querySelectorAll(".slice-pane .edge")].map((e) => e.textContent.trim()),
    note: document.getElementById("orientation-note").textContent,
    // The slice panes' bar labels its window and level fields "W" and "L", and a preset's
    // note says "W 2000 / L 400": a window and level, not a side.
    page: document.body.innerText.replace(document.querySelector(".slices-bar")?.innerText ?? "", "")
      .replace(/\bW -?[\d.,]+ \/ L -?[\d.,]+/g, ""),
  };
});

export function assertNoAnatomy(labels, what) {
  const words = (t) => t.split(/[^A-Za-z]+/).filter(Boolean);
  for (const t of [...labels.card, ...labels.marker, labels.note]) {
    // The marker's spoken label may say "to the right" of the screen; nothing may say anterior.
    const words_ = labels.marker.includes(t) ? SIDES : ANATOMICAL_WORDS;
    assert.ok(!words_.test(t), `${what}: "${t}" names a patient direction`);
    for (const w of words(t)) assert.ok(!ANATOMICAL_LETTERS.has(w), `${what}: "${t}" has the letter ${w}`);
  }
  for (const e of labels.edges) assert.match(e, /^[+−][xyz]$/, `${what}: pane edge "${e}"`);
  for (const w of words(labels.page)) assert.ok(!ANATOMICAL_LETTERS.has(w), `${what}: the page shows a lone "${w}"`);
  assert.ok(!/\b(anterior|posterior|superior|inferior)\b/i.test(labels.page), `${what}: the page names a patient side`);
}

