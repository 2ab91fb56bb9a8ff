#!/usr/bin/env bash
# The main job: installs what is missing, then runs the main scene on 2 MPI ranks.
# Ctrl-C or SIGTERM stops the run after its current step (exit code 7; -pfault_restart continues it):
# Open MPI's mpirun would kill the ranks a second after either signal, so mpirun runs in a session of its own
# (out of reach of the terminal's Ctrl-C) and is sent SIGUSR1, which it forwards to the ranks.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
source scripts/env.sh
SCENE="${SCENE:-config/wuxi.opts}"
setsid mpirun -n "${RANKS:-2}" .venv/bin/python -m pfault "$SCENE" "$@" < /dev/null &
pid=$!
trap 'kill -USR1 "$pid" 2>/dev/null || true' INT TERM
status=0
while true; do
  wait "$pid" && status=0 || status=$?
  # a trapped signal interrupts wait; the job goes on until it has stopped
  kill -0 "$pid" 2>/dev/null || break
done
exit "$status"
