#!/usr/bin/env bash
# Create .venv and install softplc into it (once per change of pyproject.toml).
# Usage: scripts/bootstrap.sh [test]   — "test" also installs the test tools and system packages.
set -euo pipefail
cd "$(dirname "$0")/.."
python=${PYTHON:-python3}
if ! "$python" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
  echo "softplc needs Python >= 3.11 (found: $("$python" --version 2>&1))" >&2
  exit 1
fi
if [ ! -x .venv/bin/python ]; then
  if ! "$python" -m venv .venv 2>/dev/null; then
    # Debian and Ubuntu ship the venv module separately (python3.X-venv).
    rm -rf .venv
    version=$("$python" -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')
    echo "installing the Python venv module (python${version}-venv)" >&2
    scripts/apt-install.sh "python${version}-venv" || scripts/apt-install.sh python3-venv || true
    "$python" -m venv .venv
  fi
fi
extras=""
[ "${1:-}" = "test" ] && extras="[test]"
stamp=".venv/.installed${extras:+-test}"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  .venv/bin/python -m pip install --quiet --disable-pip-version-check -e ".${extras}"
  touch "$stamp"
fi
# Bytecode for softplc and the plant's programs now (only what changed): a run then starts without
# compiling ~300 modules (0.35 s), even where PYTHONDONTWRITEBYTECODE keeps Python from saving it.
.venv/bin/python -m compileall -q -j 0 softplc programs robots >/dev/null 2>&1 || true
# Front-end libraries of the web HMI, pinned in hmi/package.json + package-lock.json, installed
# with npm ci (served under /vendor/) when it has any; skipped while the lock file is unchanged.
hmi_libraries=$(.venv/bin/python -c 'import json; print(len(json.load(open("hmi/package.json")).get("dependencies") or {}))')
if [ "$hmi_libraries" != 0 ] && { [ ! -f hmi/node_modules/.package-lock.json ] || [ hmi/package-lock.json -nt hmi/node_modules/.package-lock.json ]; }; then
  if ! command -v npm >/dev/null 2>&1; then
    echo "warning: npm is missing, so the HMI's front-end libraries are not installed (apt-get install npm)" >&2
  elif ! (cd hmi && npm ci --silent --no-audit --no-fund >/dev/null 2>&1); then
    echo "warning: npm ci in hmi/ failed; HMI pages that need a library will say so" >&2
  fi
fi
if [ "${1:-}" = "test" ]; then
  scripts/install-test-tools.sh
fi
