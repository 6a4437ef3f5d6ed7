#!/bin/sh
# Install tests/container/node_modules (kubernetes-models and js-yaml, pinned in
# package-lock.json) when missing or not the locked versions. Run by CTest's container.npm_ci
# fixture; needs npm and the npm registry once, then nothing.
set -eu
cd "$(dirname "$0")"
if ! command -v npm >/dev/null 2>&1; then
  echo "tests/container: npm not found; install Debian's nodejs and npm (deploy/install.sh does)" >&2
  exit 1
fi
if node -e '
  const lock = require("./package-lock.json").packages;
  for (const name of ["kubernetes-models", "js-yaml"]) {
    const have = require(`./node_modules/${name}/package.json`).version;
    if (have !== lock[`node_modules/${name}`].version) process.exit(1);
  }' 2>/dev/null; then
  echo "tests/container: kubernetes-models and js-yaml already installed"
  exit 0
fi
echo "tests/container: npm ci (kubernetes-models, js-yaml)"
if ! npm ci --no-audit --no-fund --cafile /etc/ssl/certs/ca-certificates.crt; then
  # Not a failure of ours: container.manifests then reports itself skipped, with this reason.
  echo "tests/container: npm ci failed (registry unreachable, or its TLS CA not trusted): manifest validation will be skipped" >&2
fi
