#!/usr/bin/env bash
# System packages and independent clients the integration tests use (installed once).
# A tool that cannot be installed is a warning (its tests say so and are skipped), except under CI
# (CI=true), where it stops the run here with the reason: a CI run must not pass by skipping.
set -euo pipefail
cd "$(dirname "$0")/.."
case "${CI:-}" in true | TRUE | True | 1 | yes) under_ci=1 ;; *) under_ci=0 ;; esac
trouble() {
  if [ "$under_ci" = 1 ]; then
    echo "error: $1 — under CI (CI=true) every test tool must be installed" >&2
    exit 1
  fi
  echo "warning: $1; tests that need them will say so" >&2
}
apt_packages=()
command -v mbpoll >/dev/null 2>&1 || apt_packages+=(mbpoll)
# node-opcua (tests/node) needs Node.js >= 18 and npm.
command -v npm >/dev/null 2>&1 || apt_packages+=(nodejs npm)
# The storage tests (historian, alarm journal) start a real PostgreSQL server (tests/postgres_server.py).
compgen -G "/usr/lib/postgresql/*/bin/initdb" >/dev/null || apt_packages+=(postgresql)
# The HMI's browser tests drive Debian's Chromium with the playwright package (never `playwright install`).
command -v chromium >/dev/null 2>&1 || apt_packages+=(chromium)
# tests/adapters/metrics/test_metrics_prometheus.py has a real Prometheus server scrape the HMI's /metrics.
command -v prometheus >/dev/null 2>&1 || apt_packages+=(prometheus)
# tests/app/test_service.py checks contrib/softplc.service with systemd-analyze verify.
command -v systemd-analyze >/dev/null 2>&1 || apt_packages+=(systemd)
# The MQTT users (VDA 5050, Sparkplug B) are tested against a real broker (tests/mosquitto_server.py).
command -v mosquitto >/dev/null 2>&1 || [ -x /usr/sbin/mosquitto ] || apt_packages+=(mosquitto)
# A redundant pair is coordinated by etcd (tests/etcd_server.py starts Debian's etcd-server on loopback ports).
command -v etcd >/dev/null 2>&1 || apt_packages+=(etcd-server)
if [ ${#apt_packages[@]} -gt 0 ]; then
  echo "installing system packages: ${apt_packages[*]}" >&2
  # apt-install.sh tries again with backoff: apt often fails once right after a machine boots.
  scripts/apt-install.sh "${apt_packages[@]}" || trouble "could not install ${apt_packages[*]}"
fi
if [ -f tests/node/package.json ] && [ ! -d tests/node/node_modules/node-opcua-client ]; then
  if ! command -v npm >/dev/null 2>&1; then
    trouble "npm is missing, so node-opcua (tests/node) is not installed"
  elif ! RETRY_NAME="npm install in tests/node" scripts/retry.sh 3 10 \
      bash -c 'cd tests/node && npm install --silent --no-audit --no-fund >/dev/null 2>&1'; then
    trouble "npm install in tests/node failed (node-opcua)"
  fi
fi
# The Sparkplug B tests' independent host (tests/sparkplug/host.py) is pysparkplug, which needs
# paho-mqtt < 2 while softplc's aiomqtt needs 2: it gets a virtualenv of its own.
if [ ! -x tests/sparkplug/.venv/bin/python ] || ! tests/sparkplug/.venv/bin/python -c 'import pysparkplug' 2>/dev/null; then
  { python3 -m venv tests/sparkplug/.venv \
      && RETRY_NAME="pip install pysparkplug" scripts/retry.sh 3 10 \
        tests/sparkplug/.venv/bin/pip install --quiet --disable-pip-version-check pysparkplug==0.6.1 paho-mqtt==1.6.1; } \
    || trouble "could not make tests/sparkplug/.venv (pysparkplug, the Sparkplug host)"
fi
# The VDA 5050 tests drive vda-5050-lib's virtual vehicles (tests/vda5050_node/vehicles.js), a counterpart nobody here wrote.
if [ -f tests/vda5050_node/package.json ] && [ ! -d tests/vda5050_node/node_modules/vda-5050-lib ]; then
  if ! command -v npm >/dev/null 2>&1; then
    trouble "npm is missing, so vda-5050-lib (tests/vda5050_node) is not installed"
  elif ! RETRY_NAME="npm ci in tests/vda5050_node" scripts/retry.sh 3 10 \
      bash -c 'cd tests/vda5050_node && npm ci --silent --no-audit --no-fund >/dev/null 2>&1'; then
    trouble "npm ci in tests/vda5050_node failed (vda-5050-lib)"
  fi
fi
