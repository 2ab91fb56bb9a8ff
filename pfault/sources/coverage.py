"""Where the pore-pressure source changes nothing: the cells it leaves unloaded over a run, counted at start-up.

A cell gets no pore-pressure change when the source says so at every time of the run: a material without a table
(or with a table of zeros), a cell outside a groundwater model given no change (-pfault_heads_outside zero), a cell
whose heads equal the reference heads at every saved time. ``measure`` counts them and their share of the volume
(every rank's cells; collective), ``Coverage.line`` says it once at start-up and ``Coverage.summary`` gives
summary.json's ``pore_pressure`` (docs/outputs.md). The flow model's change is known only as it is solved: its
counts are None.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from mpi4py import MPI


@dataclass(frozen=True)
class Coverage:
    """The source's kind (``tables``, ``heads``, ``flow``; ``none`` when it changes nothing by construction), the
    mesh's cells, and of them the cells without a pore-pressure change on [0, t_end] and, for heads, those
    outside the groundwater model: counts and volume fractions (None where not known before the run). ``notes``:
    what the source adds (the heads' reference)."""
    source: str
    cells: int
    unloaded_cells: int | None
    unloaded_volume_fraction: float | None
    outside_cells: int | None = None
    outside_volume_fraction: float | None = None
    notes: dict = field(default_factory=dict)

    def line(self) -> str | None:
        """The start-up line when the source leaves cells unloaded, else None."""
        if self.source == "none" or not self.unloaded_cells:
            return None
        loaded = self.cells - self.unloaded_cells
        text = (f"pfault: pore-pressure change in {loaded:,} of {self.cells:,} cells "
                f"({_percent(1.0 - self.unloaded_volume_fraction)} of the volume); none in {self.unloaded_cells:,} "
                f"({_percent(self.unloaded_volume_fraction)})")
        if self.outside_cells:
            text += (f", {self.outside_cells:,} of them ({_percent(self.outside_volume_fraction)} of the volume) "
                     "outside the groundwater model (-pfault_heads_outside zero)")
        return text

    def summary(self) -> dict:
        """summary.json's ``pore_pressure``."""
        return {"source": self.source, "cells": self.cells, "unloaded_cells": self.unloaded_cells,
                "unloaded_volume_fraction": self.unloaded_volume_fraction, "outside_cells": self.outside_cells,
                "outside_volume_fraction": self.outside_volume_fraction, **self.notes}


def _percent(fraction: float) -> str:
    return f"{100.0 * fraction:.3g} %"


def measure(comm: Any, source: Any, volumes: np.ndarray, t_end: float) -> Coverage:
    """The coverage of ``source`` over [0, t_end] on this rank's cells of volumes ``volumes``. Collective."""
    mpi = comm.tompi4py() if hasattr(comm, "tompi4py") else comm
    active = bool(source.active)
    unchanged = source.unchanged(t_end) if active else np.ones(len(volumes), dtype=bool)
    known = mpi.allreduce(unchanged is not None, op=MPI.LAND)
    outside = getattr(source, "outside", None)
    masks = [unchanged, outside] if known else [outside]
    sums = np.array([[len(volumes), float(np.sum(volumes))]]
                    + [[int(np.count_nonzero(m)), float(np.sum(volumes[m]))] if m is not None else [0, 0.0]
                       for m in masks])
    sums = mpi.allreduce(sums, op=MPI.SUM)
    cells, volume = int(sums[0, 0]), max(float(sums[0, 1]), 1e-300)
    figures = [(int(n), float(v) / volume) for n, v in sums[1:]]
    unloaded = figures[0] if known else (None, None)
    out = figures[-1] if outside is not None else (None, None)
    return Coverage(source.kind if active else "none", cells, *unloaded, *out,
                    notes=dict(getattr(source, "notes", {})))
