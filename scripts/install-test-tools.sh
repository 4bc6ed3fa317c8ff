#!/usr/bin/env bash
# System packages and independent clients the integration tests use (installed once).
set -euo pipefail
cd "$(dirname "$0")/.."
apt_packages=()
command -v mbpoll >/dev/null 2>&1 || apt_packages+=(mbpoll)
# node-opcua (tests/node) needs Node.js >= 18 and npm.
command -v npm >/dev/null 2>&1 || apt_packages+=(nodejs npm)
# The storage tests (historian, alarm journal) start a real PostgreSQL server (tests/postgres_server.py).
compgen -G "/usr/lib/postgresql/*/bin/initdb" >/dev/null || apt_packages+=(postgresql)
# The HMI's browser tests drive Debian's Chromium with the playwright package (never `playwright install`).
command -v chromium >/dev/null 2>&1 || apt_packages+=(chromium)
# tests/adapters/metrics/test_metrics_prometheus.py has a real Prometheus server scrape the HMI's /metrics.
[ -x /usr/bin/prometheus ] || apt_packages+=(prometheus)
# The MQTT users (VDA 5050, Sparkplug B) are tested against a real broker (tests/mosquitto_server.py).
[ -x /usr/sbin/mosquitto ] || apt_packages+=(mosquitto)
if [ ${#apt_packages[@]} -gt 0 ]; then
  echo "installing system packages: ${apt_packages[*]}" >&2
  scripts/apt-install.sh "${apt_packages[@]}" \
    || echo "warning: could not install ${apt_packages[*]}; tests that need them will say so" >&2
fi
if command -v npm >/dev/null 2>&1 && [ ! -d tests/node/node_modules/node-opcua-client ] && [ -f tests/node/package.json ]; then
  (cd tests/node && npm install --silent --no-audit --no-fund >/dev/null 2>&1) \
    || echo "warning: npm install in tests/node failed; node-opcua tests will say so" >&2
fi
# The VDA 5050 tests drive vda-5050-lib's virtual vehicles (tests/vda5050_node/vehicles.js), a counterpart nobody here wrote.
if command -v npm >/dev/null 2>&1 && [ ! -d tests/vda5050_node/node_modules/vda-5050-lib ] && [ -f tests/vda5050_node/package.json ]; then
  (cd tests/vda5050_node && npm ci --silent --no-audit --no-fund >/dev/null 2>&1) \
    || echo "warning: npm ci in tests/vda5050_node failed; the VDA 5050 tests with vda-5050-lib will say so" >&2
fi
