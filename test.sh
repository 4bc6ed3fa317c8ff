#!/usr/bin/env bash
# Install softplc, the test tools and the independent clients, then run the whole test suite.
# Extra arguments go to pytest, e.g. ./test.sh -k scan
# The tests run in $SOFTPLC_TEST_WORKERS processes (default 3: most tests wait on servers and sockets, so
# three keep 2 CPUs busy), a test file's tests in one process
# (they share module fixtures: one runtime, one browser); SOFTPLC_TEST_WORKERS=0 runs them in this one.
set -euo pipefail
cd "$(dirname "$0")"
scripts/bootstrap.sh test
exec .venv/bin/python -m pytest -n "${SOFTPLC_TEST_WORKERS:-3}" --dist loadfile "$@"
