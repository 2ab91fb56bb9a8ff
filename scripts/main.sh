#!/usr/bin/env bash
# The main job: installs what is missing, then runs the main scene on 2 MPI ranks.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
source scripts/env.sh
SCENE="${SCENE:-config/wuxi.opts}"
exec mpirun -n "${RANKS:-2}" .venv/bin/python -m pfault "$SCENE" "$@"
