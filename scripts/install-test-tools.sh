#!/usr/bin/env bash
# System packages and independent clients the integration tests use (installed once).
set -euo pipefail
cd "$(dirname "$0")/.."
apt_packages=()
command -v mbpoll >/dev/null 2>&1 || apt_packages+=(mbpoll)
# node-opcua (tests/node) needs Node.js >= 18 and npm.
command -v npm >/dev/null 2>&1 || apt_packages+=(nodejs npm)
if [ ${#apt_packages[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "installing system packages: ${apt_packages[*]}" >&2
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${apt_packages[@]}") >/dev/null 2>&1 \
      || echo "warning: could not install ${apt_packages[*]}; tests that need them will say so" >&2
  else
    echo "warning: not root or no apt-get; missing: ${apt_packages[*]}" >&2
  fi
fi
if command -v npm >/dev/null 2>&1 && [ ! -d tests/node/node_modules/node-opcua-client ] && [ -f tests/node/package.json ]; then
  (cd tests/node && npm install --silent --no-audit --no-fund >/dev/null 2>&1) \
    || echo "warning: npm install in tests/node failed; node-opcua tests will say so" >&2
fi
