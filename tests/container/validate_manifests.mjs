// Offline checks of deploy/k8s/ and deploy/compose.yaml: no cluster, no engine.
//
//   node tests/container/validate_manifests.mjs        (after npm ci in tests/container)
//
// 1. Every Kubernetes document against its API schema (kubernetes-models: types, required
//    fields, formats; it does not reject unknown field names, so typos are caught only where
//    they leave a required field missing, or by `podman kube play` in container_test.sh).
// 2. The references between them, which no schema sees: selectors, ports, probe paths, the
//    grace period against preStop, the image name kustomization.yaml rewrites.

import { readFileSync, readdirSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";
import yaml from "js-yaml";

const repo = join(dirname(fileURLToPath(import.meta.url)), "..", "..");
const k8sDir = join(repo, "deploy", "k8s");
const SERVER_CLOSE_GRACE_S = 2;   // s: the server's wait for close handshakes (server/README.md)

let failures = 0;
function check(ok, what) {
  console.log(`${ok ? "ok  " : "FAIL"} ${what}`);
  if (!ok) failures += 1;
}

// "apps/v1" + "Deployment" → kubernetes-models/apps/v1/Deployment; core "v1" → v1/Service.
async function modelFor(apiVersion, kind) {
  const module = await import(`kubernetes-models/${apiVersion}/${kind}`);
  return module[kind];
}

// ---- 1. schemas ----------------------------------------------------------------------
const kustomization = yaml.load(readFileSync(join(k8sDir, "kustomization.yaml"), "utf8"));
const files = readdirSync(k8sDir).filter((f) => f.endsWith(".yaml") && f !== "kustomization.yaml").sort();
check(JSON.stringify([...kustomization.resources].sort()) === JSON.stringify(files),
  `kustomization.yaml lists every manifest (${files.join(", ")})`);

const docs = [];
for (const file of files) {
  for (const doc of yaml.loadAll(readFileSync(join(k8sDir, file), "utf8"))) {
    if (!doc) continue;
    const what = `${file}: ${doc.kind} ${doc.metadata?.name}`;
    try {
      const Model = await modelFor(doc.apiVersion, doc.kind);
      new Model(doc).validate();
      check(true, `${what} matches the ${doc.apiVersion} schema`);
    } catch (e) {
      check(false, `${what}: ${e.message}`);
    }
    docs.push(doc);
  }
}
const find = (kind) => docs.find((d) => d.kind === kind);
const deployment = find("Deployment");
const service = find("Service");
const ingress = find("Ingress");
const hpa = find("HorizontalPodAutoscaler");
const pdb = find("PodDisruptionBudget");
const pvc = find("PersistentVolumeClaim");
for (const [kind, doc] of Object.entries({ deployment, service, ingress, hpa, pdb, pvc })) {
  check(doc !== undefined, `${kind}: present`);
}
if (failures > 0) process.exit(1);

// ---- 2. references -------------------------------------------------------------------
const pod = deployment.spec.template;
const container = pod.spec.containers[0];
const env = Object.fromEntries((container.env ?? []).map((e) => [e.name, e.value]));
const matches = (selector, labels) => Object.entries(selector).every(([k, v]) => labels[k] === v);

check(matches(deployment.spec.selector.matchLabels, pod.metadata.labels), "the Deployment's selector matches its pods");
check(matches(service.spec.selector, pod.metadata.labels), "the Service selects the Deployment's pods");
check(matches(pdb.spec.selector.matchLabels, pod.metadata.labels), "the PodDisruptionBudget selects them too");
check(hpa.spec.scaleTargetRef.kind === "Deployment" && hpa.spec.scaleTargetRef.name === deployment.metadata.name,
  "the HorizontalPodAutoscaler scales the Deployment");
check(hpa.spec.minReplicas >= 2, "at least 2 replicas, so that a drained pod's sessions have somewhere to go");
check(container.resources?.requests?.cpu !== undefined, "CPU requests are set (the autoscaler's utilization needs them)");
const poclThreads = container.env?.find((e) => e.name === "POCL_MAX_PTHREAD_COUNT");
check(poclThreads?.valueFrom?.resourceFieldRef?.resource === "limits.cpu" &&
  poclThreads.valueFrom.resourceFieldRef.containerName === container.name,
  "PoCL's threads follow the CPU limit (POCL_MAX_PTHREAD_COUNT from limits.cpu)");

// The container listens where the probes, the Service and the Ingress look.
const port = container.ports.find((p) => p.name === "http");
check(port && port.containerPort === Number(env.VOLCAST_PORT ?? 8080), "containerPort is the server's port (VOLCAST_PORT, 8080 in the image)");
check(container.readinessProbe?.httpGet?.path === "/readyz" && container.readinessProbe.httpGet.port === "http",
  "readiness probe: /readyz on the http port");
check(container.livenessProbe?.httpGet?.path === "/healthz" && container.livenessProbe.httpGet.port === "http",
  "liveness probe: /healthz on the http port");
check(service.spec.ports.some((p) => p.targetPort === "http"), "the Service forwards to the http port");
const backend = ingress.spec.rules[0].http.paths[0].backend.service;
check(backend.name === service.metadata.name && service.spec.ports.some((p) => p.name === backend.port.name),
  "the Ingress sends to the Service's http port");

// Cookie affinity and WebSocket timeouts longer than the server's 150 s idle ping.
const a = ingress.metadata.annotations ?? {};
check(a["nginx.ingress.kubernetes.io/affinity"] === "cookie", "the Ingress pins a browser to a replica by cookie");
for (const t of ["proxy-read-timeout", "proxy-send-timeout"]) {
  check(Number(a[`nginx.ingress.kubernetes.io/${t}`]) > 150, `${t} outlasts the server's idle ping (150 s)`);
}

// Draining: preStop, then SIGTERM and the close handshakes, all inside the grace period.
const preStop = container.lifecycle?.preStop?.exec?.command ?? [];
const preStopS = preStop[0] === "sleep" ? Number(preStop[1]) : 0;
check(preStopS > 0, "preStop waits for the endpoints to forget the pod");
check(pod.spec.terminationGracePeriodSeconds >= preStopS + SERVER_CLOSE_GRACE_S + 10,
  `terminationGracePeriodSeconds (${pod.spec.terminationGracePeriodSeconds}) covers preStop (${preStopS} s), the close handshakes (${SERVER_CLOSE_GRACE_S} s) and a render in progress`);

// The scans: the claim, mounted read-only at the image's VOLCAST_DATA.
const dataVolume = pod.spec.volumes.find((v) => v.persistentVolumeClaim);
const dataMount = container.volumeMounts.find((m) => m.name === dataVolume?.name);
check(dataVolume?.persistentVolumeClaim.claimName === pvc.metadata.name, "the pods mount the data claim");
check(dataMount?.mountPath === (env.VOLCAST_DATA ?? "/data") && dataMount.readOnly === true && dataVolume.persistentVolumeClaim.readOnly === true,
  "the data are mounted read-only at /data");
check(pvc.spec.accessModes.includes("ReadOnlyMany"), "the claim can be mounted by every replica (ReadOnlyMany)");

// A read-only root file system needs somewhere writable for PoCL's kernel cache.
const sc = container.securityContext ?? {};
check(pod.spec.securityContext?.runAsNonRoot === true && sc.allowPrivilegeEscalation === false, "runs as non-root, no privilege escalation");
if (sc.readOnlyRootFilesystem) {
  check(container.volumeMounts.some((m) => m.mountPath === "/var/cache/volcast"), "read-only root: PoCL's kernel cache has a writable volume");
}
check(kustomization.images?.some((i) => i.name === container.image), `kustomization.yaml sets the image (${container.image})`);

// ---- compose.yaml --------------------------------------------------------------------
const compose = yaml.load(readFileSync(join(repo, "deploy", "compose.yaml"), "utf8"));
const svc = compose.services?.volcast;
check(svc !== undefined, "compose.yaml: a volcast service");
check(svc?.build?.dockerfile === "deploy/Containerfile", "compose.yaml: builds deploy/Containerfile");
check((svc?.volumes ?? []).some((v) => typeof v === "string" && v.endsWith(":/data:ro")), "compose.yaml: the scans are read-only at /data");
check((svc?.ports ?? []).every((p) => String(p).startsWith("127.0.0.1:")), "compose.yaml: published on loopback only");

console.log(failures === 0 ? "all manifests valid" : `${failures} check(s) failed`);
process.exit(failures === 0 ? 0 : 1);
