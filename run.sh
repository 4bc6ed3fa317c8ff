#!/usr/bin/env bash
# Install softplc into .venv (first time) and run the default plant (tagdb.yaml).
# Extra arguments go to `softplc run`, e.g. ./run.sh --sim --duration 600
set -euo pipefail
cd "$(dirname "$0")"
scripts/bootstrap.sh
exec .venv/bin/softplc run tagdb.yaml "$@"
