#!/usr/bin/env bash
# Install softplc, the test tools and the independent clients, then run the whole test suite.
# Extra arguments go to pytest, e.g. ./test.sh -k scan
set -euo pipefail
cd "$(dirname "$0")"
scripts/bootstrap.sh test
exec .venv/bin/python -m pytest "$@"
