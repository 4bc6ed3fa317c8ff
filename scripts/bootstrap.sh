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
if [ "${1:-}" = "test" ]; then
  scripts/install-test-tools.sh
fi
