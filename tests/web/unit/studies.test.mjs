// core/studies.js: the search form's fields become exactly the `find_studies` request
// protocol/README.md describes, bad fields are refused naming the field, and what comes
// back (dates, names, progress, errors) reads as a person expects.
import { test } from "node:test";
import assert from "node:assert/strict";

import {
  MAX_STUDY_LIMIT, QueryError, buildStudyQuery, describeError, formatBytes, formatPatientName, formatStudyDate,
  normaliseStudies, overallProgress, parseStudyDate, patientNameQuery, progressText, sourceOf,
} from "../../../web/core/studies.js";
import { REPLY_TYPE, requests } from "../../../web/core/protocol.js";

test("a search with every field becomes the protocol's find_studies request", () => {
  const q = buildStudyQuery({
    source: "orthanc", patientName: " Doe, J* ", patientId: "PID-0042", studyDate: "2024-01-01 – 2024-01-31",
    modality: "ct", accessionNumber: "ACC7", limit: "50",
  });
  assert.deepEqual(q, {
    type: "find_studies", source: "orthanc", limit: 50,
    filters: { patient_name: "Doe^J*", patient_id: "PID-0042", study_date: "20240101-20240131", modality: "CT", accession_number: "ACC7" },
  });
  assert.equal(REPLY_TYPE[q.type], "studies", "the connection waits for a `studies` answer");
  assert.deepEqual(requests.findStudies("orthanc", q.filters, 50), q);
});

test("empty fields are left out; no filter at all asks for the source's studies up to 100", () => {
  assert.deepEqual(buildStudyQuery({ source: "pacs_1", patientName: "  ", patientId: "", studyDate: "" }),
    { type: "find_studies", source: "pacs_1", filters: {}, limit: 100 });
});

test("a patient name without a wildcard matches names starting with it; * and ? are kept", () => {
  assert.equal(patientNameQuery("doe"), "doe*");
  assert.equal(patientNameQuery("DOE^JOHN"), "DOE^JOHN*");
  assert.equal(patientNameQuery("D?E*"), "D?E*");
  assert.equal(patientNameQuery("Doe , John"), "Doe^John*");
  assert.equal(patientNameQuery(""), "");
});

test("study dates: one day, a range with any dash or 'to', an open end; compact or ISO", () => {
  const cases = [
    ["2024-01-31", "20240131"], ["20240131", "20240131"],
    ["2024-01-01 – 2024-01-31", "20240101-20240131"], ["2024-01-01—2024-01-31", "20240101-20240131"],
    ["20240101-20240131", "20240101-20240131"], ["2024-01-01-2024-01-31", "20240101-20240131"],
    ["2024-01-01 to 2024-01-31", "20240101-20240131"], ["2024-01-01..2024-01-31", "20240101-20240131"],
    ["2024-01-01 –", "20240101-"], ["– 2024-01-31", "-20240131"], ["-20240131", "-20240131"], ["2024-02-29", "20240229"],
  ];
  for (const [typed, wire] of cases) assert.equal(parseStudyDate(typed), wire, typed);
});

test("bad fields are refused, naming the field and what is wrong", () => {
  const cases = [
    [{}, "source", /choose a source/],
    [{ source: "a/b" }, "source", /choose a source/],
    [{ source: "s", studyDate: "2023-02-29" }, "study_date", /not a date/],
    [{ source: "s", studyDate: "2024-13-01" }, "study_date", /not a date/],
    [{ source: "s", studyDate: "yesterday" }, "study_date", /give a date/],
    [{ source: "s", studyDate: "–" }, "study_date", /give a date/],
    [{ source: "s", studyDate: "2024-02-01 – 2024-01-01" }, "study_date", /ends before it starts/],
    [{ source: "s", patientName: "a\\b" }, "patient_name", /backslash/],
    [{ source: "s", patientName: "x".repeat(64) }, "patient_name", /at most 63/],
    [{ source: "s", patientId: "p\u0001" }, "patient_id", /control/],
    [{ source: "s", modality: "C-T" }, "modality", /letters and digits/],
    [{ source: "s", limit: 0 }, "limit", /1 to 1000/],
    [{ source: "s", limit: MAX_STUDY_LIMIT + 1 }, "limit", /1 to 1000/],
    [{ source: "s", limit: 2.5 }, "limit", /whole number/],
  ];
  for (const [fields, field, why] of cases) {
    assert.throws(() => buildStudyQuery(fields), (e) => e instanceof QueryError && e.field === field && why.test(e.message),
      `${JSON.stringify(fields)} should be refused on ${field}`);
  }
});

test("dates and patient names read as people write them", () => {
  assert.equal(formatStudyDate("20240131"), "2024-01-31");
  assert.equal(formatStudyDate(""), "");
  assert.equal(formatStudyDate("2024"), "2024");
  assert.equal(formatPatientName("DOE^JOHN^Q^DR"), "DOE, JOHN Q");
  assert.equal(formatPatientName("DOE"), "DOE");
  assert.equal(formatPatientName("^JOHN"), "JOHN");
  assert.equal(formatPatientName("Yamada^Tarou=山田^太郎"), "Yamada, Tarou");
  assert.equal(formatPatientName(undefined), "");
});

test("a studies answer is kept leniently, newest study first, series without a volume dropped", () => {
  const studies = normaliseStudies({
    type: "studies", studies: [
      { study_uid: "1.2.1", patient_name: "A^B", study_date: "20200101", modalities: ["CT"], series: [
        { series_uid: "1.2.1.1", modality: "CT", description: "axial", instances: 3, volume: "dicomweb:o/1.2.1/1.2.1.1" },
        { series_uid: "1.2.1.2", modality: "SR" },
      ] },
      { study_uid: "1.2.2", study_date: "20240101", extra: true },
      null,
    ],
  });
  assert.deepEqual(studies.map((s) => s.study_uid), ["1.2.2", "1.2.1"]);
  assert.deepEqual(studies[1].series, [{ series_uid: "1.2.1.1", modality: "CT", description: "axial", instances: 3, volume: "dicomweb:o/1.2.1/1.2.1.1" }]);
  assert.deepEqual(studies[0].series, []);
  assert.equal(studies[0].patient_name, "");
  assert.deepEqual(normaliseStudies({}), []);
});

test("retrieval progress in words: images done of total and the bytes so far", () => {
  assert.equal(progressText({ stage: "retrieving", instances: [120, 300], bytes: 62_000_000, fraction: 0.4 }),
    "Retrieving 120 of 300 images, 62 MB");
  assert.equal(progressText({ stage: "retrieving", instances: [0, 300], fraction: 0 }), "Retrieving 0 of 300 images");
  assert.equal(progressText({ stage: "retrieving", bytes: 850_000, fraction: 0 }), "Retrieving images, 850 kB");
  assert.equal(progressText({ stage: "loading", task: "reading_slices", fraction: 0.35 }), "loading · reading slices · 35 %");
  assert.equal(progressText(null), "asking the server…");
  assert.equal(formatBytes(6_240_000), "6.2 MB");
  assert.equal(formatBytes(1_400_000_000), "1.4 GB");
  assert.equal(formatBytes(512), "512 B");
});

test("the progress bar: retrieval takes most of a PACS series' bar, and never goes back across stages", () => {
  const name = "dicomweb:o/1.2/1.3";
  assert.equal(overallProgress(name, null), true, "indeterminate before any progress");
  const steps = [
    { stage: "retrieving", instances: [0, 10], fraction: 0 },
    { stage: "retrieving", instances: [5, 10] },               // no fraction: from the instances
    { stage: "retrieving", instances: [10, 10], fraction: 1 },
    { stage: "loading", fraction: 0.5 },
    { stage: "preprocessing", fraction: 1 },
  ].map((p) => overallProgress(name, p));
  assert.equal(steps[1], 0.35, "half the images: half of retrieval's 70 % share");
  for (let i = 1; i < steps.length; i++) assert.ok(steps[i] >= steps[i - 1], `step ${i}: ${steps}`);
  assert.equal(overallProgress("ct/head.nrrd", { stage: "loading", fraction: 0.5 }), 0.3, "a file keeps loading's 60 % share");
});

test("errors in words a user understands, the server's reason kept as the detail", () => {
  const expired = describeError({ code: "not_found", message: "no volume upload:ab" }, { volume: "upload:ab" });
  assert.equal(expired.title, "This uploaded file has expired; open it again.");
  const down = describeError({ code: "source_failed", message: "orthanc: connection refused" }, { volume: "dicomweb:orthanc/1/2" });
  assert.match(down.title, /archive "orthanc" did not answer/);
  assert.equal(down.detail, "orthanc: connection refused");
  assert.match(describeError({ code: "not_found", message: "x" }, { source: "nope" }).title, /no image archive called "nope"/);
  assert.match(describeError({ code: "not_found", message: "x" }, { volume: "dicomweb:o/1/2" }).title, /no longer has this series/);
  const unreachable = describeError({ code: "load_failed", message: "dicomweb:pacs/1/2: DICOMweb source 'pacs' is unreachable" }, { volume: "dicomweb:pacs/1/2" });
  assert.deepEqual(unreachable, { title: 'The series from "pacs" could not be opened.', detail: "DICOMweb source 'pacs' is unreachable" });
  assert.equal(sourceOf("dicomweb:my-pacs/1.2/3.4"), "my-pacs");
  assert.equal(sourceOf("ct/head.nrrd"), null);
});
