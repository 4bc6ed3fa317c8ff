#!/usr/bin/env bash
# Install softplc into .venv (first time) and run the default plant (tagdb.yaml); the plant shows
# in a browser at the HMI's address (printed; opened when there is a screen).
# Extra arguments go to `softplc run`, e.g. ./run.sh --sim --speed 10
set -euo pipefail
cd "$(dirname "$0")"
scripts/bootstrap.sh
exec .venv/bin/softplc run tagdb.yaml --hmi-open "$@"
