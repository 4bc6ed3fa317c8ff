#!/usr/bin/env bash
# Install Debian/Ubuntu packages: as root, or through sudo when it needs no password.
# Usage: scripts/apt-install.sh PACKAGE...   (exit status 1 if they could not be installed)
# apt can fail right after a machine boots (a mirror not reachable yet, the dpkg lock held by
# unattended-upgrades) and succeed a minute later: the package lists are updated and the install
# tried again, SOFTPLC_APT_ATTEMPTS times (default 4) after 10, 20, 40 s (SOFTPLC_APT_DELAY: the first).
set -euo pipefail
cd "$(dirname "$0")/.."
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
log=$(mktemp)
trap 'rm -f "$log"' EXIT
# One try: fresh package lists (a failed update leaves the old ones: the install may still work),
# then the install, waiting up to 2 minutes for a dpkg lock someone else holds.
# shellcheck disable=SC2016
try='"$@" apt-get update -qq >"$0" 2>&1; "$@" DEBIAN_FRONTEND=noninteractive apt-get install -y -qq -o DPkg::Lock::Timeout=120 $PACKAGES >>"$0" 2>&1'
if PACKAGES="$*" RETRY_NAME="apt-get install $*" scripts/retry.sh "${SOFTPLC_APT_ATTEMPTS:-4}" "${SOFTPLC_APT_DELAY:-10}" bash -c "$try" "$log" "${as_root[@]}" env; then
  exit 0
fi
echo "apt-get install $* failed; its last words:" >&2
tail -n 5 "$log" >&2
exit 1
