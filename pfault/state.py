"""The state of a run: everything that changes from one step to the next.

The model (pfault.model) is built once and does not change during the run. What does is held here: the
solution (displacements and fault multipliers), the initial state it is measured from, the state converged
before it (the predictor's history), the time, the geostatic initial stress, and the histories of the parts
that have one (each fault face's initial traction, pore pressure and start of step: ``faults``; whether each
fault face has slid: ``fault_slid``; which faces of candidate surfaces have broken, and when: ``fault_broken``,
``fault_break_time``; the flow model's head: the pore-pressure source's ``checkpoint()``). The checkpoint
(pfault.io.checkpoint) writes it and a restart reads it; the time loop hands it to the observers read-only.
"""

from __future__ import annotations

from typing import Any

import numpy as np


class State:
    """``u`` (the solution at ``time``), ``u_ref`` (the state at t = 0, after a geostatic initial state), the
    state converged before ``u`` (``previous``: (time, Vec) or None), ``sigma0`` (cells x 3 x 3, Pa, or None),
    ``faults`` (the fault interface whose per-face history it carries, or None), ``fault_slid`` (per owned fault
    face: slipping or open at the end of a completed step, now or before; its tangential jump is then the
    fault's slip, pfault.run.fault_figures), ``fault_broken`` (per owned fault face: broken, pfault.faults.breaking;
    every face of a pre-existing fault from the start), ``fault_break_time`` (s: when it broke; NaN while intact
    and on a pre-existing fault) and ``source`` (the pore-pressure source, whose state a flow model
    carries)."""

    def __init__(self, u: Any, faults: Any = None, source: Any = None) -> None:
        self.u = u
        self.u.setName("displacement")
        self.u_ref = u.duplicate()
        self.previous: tuple[float, Any] | None = None
        self.time = 0.0
        self.sigma0: np.ndarray | None = None
        self.faults = faults
        nf = 0 if faults is None else faults.faces.nf
        self.fault_slid = np.zeros(nf, dtype=bool)
        self.fault_broken = np.ones(nf, dtype=bool) if faults is None else faults.strength.initially_broken()
        self.fault_break_time = np.full(nf, np.nan)
        self.source = source

    def break_faces(self, new: np.ndarray, t: float) -> None:
        """The owned faces ``new`` broke at time t: broken for good, and their laws told (not collective)."""
        new = np.asarray(new, dtype=bool) & ~self.fault_broken
        self.fault_broken = self.fault_broken | new
        self.fault_break_time = np.where(new, float(t), self.fault_break_time)
        self.faults.set_broken(self.fault_broken)

    def set_broken(self, broken: np.ndarray, break_time: np.ndarray) -> None:
        """The broken faces and their break times (a checkpoint's), given to the faults' laws too."""
        self.fault_broken = np.asarray(broken, dtype=bool).copy()
        self.fault_break_time = np.asarray(break_time, dtype=float).copy()
        self.faults.set_broken(self.fault_broken)

    def set_previous(self, t: float, u: Any) -> None:
        """Record the state u converged at time t before the current one (the predictor's history)."""
        if self.previous is not None:
            self.previous[1].destroy()
        self.previous = (float(t), u.copy())

    def destroy(self) -> None:
        self.u.destroy()
        self.u_ref.destroy()
        if self.previous is not None:
            self.previous[1].destroy()
            self.previous = None
