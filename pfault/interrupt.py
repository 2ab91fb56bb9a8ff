"""Stop requests: SIGTERM, SIGINT (Ctrl-C) and SIGUSR1 end a run after the step in progress.

The handlers only note the signal; the time loop asks ``StopRequest.agreed()`` once per step, an allreduce,
so every rank stops after the same step even when only one of them was signalled. A second signal of the
same kind ends the process at once (the completed steps are on disk already).

Open MPI's mpirun (4.1) does not pass SIGTERM or SIGINT on as such: it sends the ranks SIGCONT, then SIGTERM
``odls_base_sigkill_timeout`` seconds later (default 1) and SIGKILL after as long again, and exits with 1.
Once it has the signal it also stops reading the ranks' output, so with a longer timeout a rank can block in
its next progress line until it is killed: the steps completed before are on disk either way.
It forwards SIGUSR1 untouched: ``kill -USR1 <mpirun pid>`` stops a run after its current step with exit code
7 (pfault.errors.EXIT_INTERRUPTED), as SIGTERM to the ranks themselves does (what batch systems such as Slurm send).
"""

from __future__ import annotations

import os
import signal
import sys
from typing import Any, Literal

from mpi4py import MPI

from .errors import STOP_SIGNALS, raise_swallowed_stop


class StopRequest:
    """Context manager installing the handlers (main thread only; restored on exit).

    Install it after meshing: gmsh resets the SIGINT handler when it initialises."""

    def __init__(self, comm: Any) -> None:
        self.mpi = comm.tompi4py() if hasattr(comm, "tompi4py") else comm
        self.received: int | None = None
        self._previous: dict[signal.Signals, Any] = {}

    def _handler(self, signum, frame):
        name = signal.Signals(signum).name
        if self.received == signum:
            # the same signal again: stop now
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        if self.received is None:
            sys.stderr.write(f"pfault: {name} received (rank {self.mpi.rank}): stopping after the current step "
                             f"(send it again to stop at once)\n")
            sys.stderr.flush()
        self.received = signum

    def __enter__(self) -> StopRequest:
        raise_swallowed_stop()          # a stop signal at start-up whose exception something swallowed
        for sig in STOP_SIGNALS:
            try:
                self._previous[sig] = signal.signal(sig, self._handler)
            except ValueError:          # not the main thread: no handlers, no stop requests
                break
        return self

    def __exit__(self, *exc: object) -> Literal[False]:
        for sig, prev in self._previous.items():
            signal.signal(sig, prev if prev is not None else signal.SIG_DFL)
        self._previous = {}
        return False

    def agreed(self) -> str | None:
        """The name of the signal any rank received (the highest number if several), or None: the same on
        every rank (collective: call it on every rank at the same point of the time loop)."""
        signum = self.mpi.allreduce(int(self.received or 0), op=MPI.MAX)
        return signal.Signals(signum).name if signum else None
