#!/bin/sh
# Install tests/web/node_modules (playwright-core, pinned in package-lock.json) when it is
# missing or not the locked version. Run by CTest's web.npm_ci fixture; needs npm and the
# npm registry once, then nothing.
set -eu
cd "$(dirname "$0")"
if ! command -v npm >/dev/null 2>&1; then
  echo "tests/web: npm not found; install Debian's nodejs and npm (deploy/install.sh does)" >&2
  exit 1
fi
if node -e '
  const want = require("./package-lock.json").packages["node_modules/playwright-core"].version;
  const have = require("./node_modules/playwright-core/package.json").version;
  process.exit(want === have ? 0 : 1);' 2>/dev/null; then
  echo "tests/web: playwright-core already installed"
  exit 0
fi
echo "tests/web: npm ci (playwright-core, no browsers: the tests use Debian's chromium)"
if ! PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm ci --no-audit --no-fund --cafile /etc/ssl/certs/ca-certificates.crt; then
  # Not a failure of ours: web.browser then reports itself skipped, with this reason.
  echo "tests/web: npm ci failed (registry unreachable, or its TLS CA not trusted): browser tests will be skipped" >&2
fi
