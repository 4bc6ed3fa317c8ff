#!/usr/bin/env bash
# Run a command until it succeeds, at most ATTEMPTS times, waiting DELAY seconds before the second
# try and twice as long before each next one (what fails right after boot — a package mirror not
# reachable yet, the dpkg lock held by unattended-upgrades — usually works a minute later).
# Usage: [RETRY_NAME=TEXT] scripts/retry.sh ATTEMPTS DELAY COMMAND...   (exit status: the command's last)
set -uo pipefail
attempts=$1 delay=$2
shift 2
# The command as the messages name it: $RETRY_NAME, else its first two words ("bash -c ...").
name=${RETRY_NAME:-"$1${2:+ $2}${3:+ ...}"}
for ((attempt = 1; ; attempt++)); do
  "$@"
  status=$?
  [ "$status" -eq 0 ] && exit 0
  if [ "$attempt" -ge "$attempts" ]; then
    echo "$name failed $attempt times (exit status $status); giving up" >&2
    exit "$status"
  fi
  echo "$name failed (attempt $attempt of $attempts, exit status $status); trying again in ${delay} s" >&2
  sleep "$delay"
  delay=$(awk -v d="$delay" 'BEGIN { printf "%g", d * 2 }')
done
