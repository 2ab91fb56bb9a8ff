#!/usr/bin/env bash
# The test suite: installs what is missing, then runs every test (serial, verification, 2-rank, CLI), the test
# files shared out between one pytest worker per core (pytest-xdist; a file's tests on one worker, so that the
# runs a file shares between its tests are made once). PFAULT_TEST_WORKERS=1 runs them in this process.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
source scripts/env.sh
workers="${PFAULT_TEST_WORKERS:-$(nproc)}"
if [ "$workers" -le 1 ]; then
  exec .venv/bin/python -m pytest -q "$@"
fi
exec .venv/bin/python -m pytest -q -n "$workers" --dist loadfile "$@"
