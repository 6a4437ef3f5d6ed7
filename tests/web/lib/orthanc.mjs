// A real Orthanc PACS with its DICOMweb plugin, started by the test on loopback: a JSON
// config, a temporary storage folder, free ports; instances go in over its REST API.
//
//   ORTHANC          the Orthanc binary (default /usr/sbin/Orthanc)
//   ORTHANC_DICOMWEB the DICOMweb plugin (default /usr/share/orthanc/plugins/libOrthancDicomWeb.so)

import { spawn } from "node:child_process";
import { createWriteStream, existsSync, mkdtempSync, rmSync, writeFileSync } from "node:fs";
import os from "node:os";
import path from "node:path";

import { SUITE, artifact, freePort } from "../browser/harness.mjs";

export const ORTHANC = process.env.ORTHANC || "/usr/sbin/Orthanc";
export const ORTHANC_DICOMWEB = process.env.ORTHANC_DICOMWEB || "/usr/share/orthanc/plugins/libOrthancDicomWeb.so";
const START_TIMEOUT_MS = 30000;   // ms: Orthanc answers /system within ~1 s here

export function orthancMissing() {
  const missing = [];
  if (!existsSync(ORTHANC)) missing.push(`Orthanc not found at ${ORTHANC} (apt-get install orthanc, or set ORTHANC)`);
  if (!existsSync(ORTHANC_DICOMWEB)) missing.push(`the DICOMweb plugin not found at ${ORTHANC_DICOMWEB} (apt-get install orthanc-dicomweb, or set ORTHANC_DICOMWEB)`);
  return missing;
}

let runs = 0;
export async function startOrthanc() {
  const dir = mkdtempSync(path.join(os.tmpdir(), "volcast-orthanc-"));
  const httpPort = await freePort(), dicomPort = await freePort();
  const config = {
    Name: "volcast-web-test",
    StorageDirectory: path.join(dir, "db"),
    IndexDirectory: path.join(dir, "db"),
    HttpPort: httpPort,
    DicomPort: dicomPort,
    RemoteAccessAllowed: false,      // loopback clients only
    AuthenticationEnabled: false,
    Plugins: [ORTHANC_DICOMWEB],
    DicomWeb: { Enable: true, Root: "/dicom-web/" },
  };
  const configPath = path.join(dir, "orthanc.json");
  writeFileSync(configPath, JSON.stringify(config, null, 2));
  const log = createWriteStream(artifact(`${SUITE}-orthanc-${++runs}.log`));
  const proc = spawn(ORTHANC, [configPath], { stdio: ["ignore", "pipe", "pipe"] });
  proc.stdout.pipe(log);
  proc.stderr.pipe(log);
  const exited = new Promise((resolve) => proc.once("exit", (code, signal) => resolve({ code, signal })));
  let gone = null;
  exited.then((e) => { gone = e; });
  const url = `http://127.0.0.1:${httpPort}`;
  const deadline = Date.now() + START_TIMEOUT_MS;
  for (;;) {
    if (gone) throw new Error(`Orthanc exited (${JSON.stringify(gone)}); log: ${log.path}`);
    try { if ((await fetch(`${url}/system`)).ok) break; } catch { /* not listening yet */ }
    if (Date.now() > deadline) throw new Error(`Orthanc did not answer within ${START_TIMEOUT_MS} ms; log: ${log.path}`);
    await new Promise((r) => setTimeout(r, 100));
  }
  return {
    url,
    dicomWeb: `${url}/dicom-web`,
    logPath: log.path,
    // Store DICOM files (Buffers) over the REST API; fails naming Orthanc's answer.
    async store(files) {
      for (const body of files) {
        const r = await fetch(`${url}/instances`, { method: "POST", body, headers: { "Content-Type": "application/dicom" } });
        if (!r.ok) throw new Error(`Orthanc refused an instance: HTTP ${r.status} ${await r.text()}`);
      }
    },
    async stop() {
      if (!gone) {
        proc.kill("SIGTERM");
        const timer = setTimeout(() => proc.kill("SIGKILL"), 10000);
        await exited;
        clearTimeout(timer);
      }
      rmSync(dir, { recursive: true, force: true });
    },
  };
}
