#!/bin/sh
# npm ci in a test folder (tests/web, tests/container) unless node_modules already holds every
# package of its package.json at the lockfile's version. Run by deploy/install.sh and by each
# folder's CTest *.npm_ci fixture; needs npm and the npm registry once, then nothing.
#
#   tests/npm-ci.sh tests/web
#
# A failed npm ci is not a failure of ours: the tests that need the packages then report
# themselves skipped, with the reason.
set -eu
dir="${1:?usage: tests/npm-ci.sh FOLDER}"
cd "$dir"
name="$(basename "$(pwd)")"
if ! command -v npm >/dev/null 2>&1; then
  echo "tests/$name: npm not found; install Node.js and npm (deploy/install.sh does)" >&2
  exit 1
fi
if node -e '
  const pkg = require("./package.json"), lock = require("./package-lock.json").packages;
  for (const dep of Object.keys({...pkg.dependencies, ...pkg.devDependencies}))
    if (require(`./node_modules/${dep}/package.json`).version !== lock[`node_modules/${dep}`].version)
      process.exit(1);' 2>/dev/null; then
  echo "tests/$name: npm packages already installed"
  exit 0
fi
echo "tests/$name: npm ci"
# Debian's npm trusts only its own CA list; the system's also holds any registry proxy's CA.
# No browser download: the browser tests drive Debian's chromium.
if ! PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm ci --no-audit --no-fund --loglevel=error \
    --cafile /etc/ssl/certs/ca-certificates.crt; then
  echo "tests/$name: WARNING: npm ci failed (registry unreachable, or its TLS CA not trusted):" \
       "the tests that need these packages will report themselves skipped" >&2
fi
