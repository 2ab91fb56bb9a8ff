"""The state of a run: everything that changes from one step to the next.

The model (pfault.model) is built once and does not change during the run. What does is held here: the
solution (displacements and the faults' multipliers, a PETSc Vec) and the initial state it is measured from, the
state converged before it (the predictor's history), the time, the geostatic initial stress, and the histories
of the equations' terms (one per term, plain frozen data: a fault's is pfault.faults.history.FaultHistory), which
the terms take and return anew. The pore-pressure source is a part of the model with a state of its own (a flow
model's heads): ``source_state`` records it after each step (pfault.sources). The checkpoint
(pfault.io.checkpoint) writes the state as a whole and a restart reads it; a cut step restores a ``snapshot``;
the time loop hands the state to the observers read-only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Snapshot:
    """A copy of a state (its own Vecs: ``destroy`` them)."""
    u: Any
    previous: tuple[float, Any] | None
    time: float
    histories: tuple

    def destroy(self) -> None:
        self.u.destroy()
        if self.previous is not None:
            self.previous[1].destroy()


class State:
    """``u`` (the solution at ``time``), ``u_ref`` (the state at t = 0, after a geostatic initial state), the
    state converged before ``u`` (``previous``: (time, Vec) or None), ``sigma0`` (cells x 3 x 3, Pa, or None: the
    geostatic initial stress), ``histories`` (the equations' terms', in order) and ``source_state`` (the
    pore-pressure source's, pfault.sources: None for one without a state)."""

    def __init__(self, u: Any, histories: tuple = (), source_state: Any = None) -> None:
        self.u = u
        self.u.setName("displacement")
        self.u_ref = u.duplicate()
        self.previous: tuple[float, Any] | None = None
        self.time = 0.0
        self.sigma0: np.ndarray | None = None
        self.histories = tuple(histories)
        self.source_state = source_state

    def set_previous(self, t: float, u: Any) -> None:
        """Record the state u converged at time t before the current one (the predictor's history)."""
        if self.previous is not None:
            self.previous[1].destroy()
        self.previous = (float(t), u.copy())

    def snapshot(self) -> Snapshot:
        """What a step changes: the solution, the predictor's history, the time and the histories."""
        prev = None if self.previous is None else (self.previous[0], self.previous[1].copy())
        return Snapshot(self.u.copy(), prev, self.time, self.histories)

    def restore(self, snap: Snapshot) -> None:
        """Back to ``snap`` (which stays the caller's)."""
        snap.u.copy(self.u)
        if self.previous is not None:
            self.previous[1].destroy()
        self.previous = None if snap.previous is None else (snap.previous[0], snap.previous[1].copy())
        self.time, self.histories = snap.time, snap.histories

    def destroy(self) -> None:
        self.u.destroy()
        self.u_ref.destroy()
        if self.previous is not None:
            self.previous[1].destroy()
            self.previous = None
