#!/usr/bin/env bash
# Install Debian/Ubuntu packages: as root, or through sudo when it needs no password.
# Usage: scripts/apt-install.sh PACKAGE...   (exit status 1 if they could not be installed)
set -euo pipefail
if ! command -v apt-get >/dev/null 2>&1; then
  echo "no apt-get on this machine: install $* with your package manager" >&2
  exit 1
fi
if [ "$(id -u)" = 0 ]; then
  as_root=()
elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
  as_root=(sudo -n)
else
  echo "not root and no password-less sudo: install $* yourself (apt-get install $*)" >&2
  exit 1
fi
"${as_root[@]}" apt-get update -qq >/dev/null 2>&1 || true
"${as_root[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$@" >/dev/null 2>&1
