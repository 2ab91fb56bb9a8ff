#!/usr/bin/env bash
# The test suite: installs what is missing, then runs every test (serial, verification, 2-rank, CLI).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
source scripts/env.sh
exec .venv/bin/python -m pytest -q "$@"
