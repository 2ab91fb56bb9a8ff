#!/usr/bin/env bash
# The test suite: installs what is missing, then runs every test (serial, verification, 2-rank, CLI), the test
# files shared out between one pytest worker per core (pytest-xdist; a file's tests on one worker, so that the
# runs a file shares between its tests are made once). PFAULT_TEST_WORKERS=1 runs them in this process.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# the cores this process may run on (nproc would answer OMP_NUM_THREADS, which env.sh sets to 1)
workers="${PFAULT_TEST_WORKERS:-$(.venv/bin/python -c 'import os; print(len(os.sched_getaffinity(0)))')}"
source scripts/env.sh
if [ "$workers" -le 1 ]; then
  exec .venv/bin/python -m pytest -q "$@"
fi
exec .venv/bin/python -m pytest -q -n "$workers" --dist loadfile "$@"
