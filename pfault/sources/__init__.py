"""Pore-pressure sources: where a scene's pore-pressure change comes from.

A source is a part the model is given. The time loop moves it with ``advance_to(t)`` before each step; the
equations and the output read it with ``cell_dp(t)``, which changes nothing. Every source has:

- ``active``: whether it changes the pore pressure at all (an inactive source loads nothing);
- ``advance_to(t)``: bring the source to time t (a flow model solves up to t; a table has nothing to do);
- ``cell_dp(t)``: the pore-pressure change per local cell (Pa) at a time t between the time the source was
  last advanced from and the time it was advanced to (a step cut into sub-steps reads it within the step:
  a flow model's field is interpolated linearly in time there);
- ``loaded_cells(t)``: the local cells whose pore pressure the source changes (a bool per cell), which a
  uniform further drawdown lowers (pfault.margins): a table's materials with a table that is not zero, every
  cell of a flow model (it solves for all of them), the cells of a groundwater model's heads that are inside it
  and change at some saved time;
- ``step_record()``: figures of the last advance for the step's record (empty for a table);
- ``kind`` (``tables``, ``heads``, ``flow``) and ``unchanged(t_end)``: per local cell, whether the source changes
  its pore pressure at no time of [0, t_end] (None where that is known only as the run goes: the flow model's);
  pfault.sources.coverage counts those cells;
- ``has_state``; ``state()`` / ``restore(state)``: its state (a flow model's ``FlowState``; a table has none: None),
  which the run's state records after every advance and a restart gives back;
- ``destroy()``.

``Unchanged`` gives any source the materials whose pore pressure does not change
(-pfault_pore_pressure_unchanged_materials): it is the source, with zero change in their cells.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from mpi4py import MPI

from ..solver.flow import after


@dataclass(frozen=True)
class FlowState:
    """A flow model's state: its head change per local vertex (m), its time (s) and its step records."""
    head: np.ndarray
    time: float
    history: tuple


def zero_on(breakpoints: Any, values: Any, t_end: float) -> np.ndarray:
    """Whether piecewise-linear functions of time, constant beyond their ends, are zero on [0, t_end]: ``values``
    (n breakpoints, ...) at the increasing ``breakpoints``; a function is zero there when it is at 0, at t_end and at
    its breakpoints between. Returns one flag per function (the trailing shape of ``values``)."""
    t = np.asarray(breakpoints, dtype=float)
    v = np.asarray(values, dtype=float).reshape(len(t), -1)
    ends = np.stack([_value_at(t, v, x) for x in (0.0, t_end)])
    return np.all(np.concatenate([v[(t > 0.0) & (t < t_end)], ends]) == 0.0, axis=0).reshape(np.shape(values)[1:])


def _value_at(t: np.ndarray, v: np.ndarray, x: float) -> np.ndarray:
    """The rows ``v`` (one per breakpoint ``t``) interpolated linearly at time x, constant beyond the ends."""
    if x <= t[0]:
        return v[0]
    if x >= t[-1]:
        return v[-1]
    i = int(np.searchsorted(t, x, side="right")) - 1
    theta = (x - t[i]) / (t[i + 1] - t[i])
    return (1.0 - theta) * v[i] + theta * v[i + 1]


class TableSource:
    """dp(t) uniform within each material, from per-material tables (pfault.physics.loading.MaterialDrawdown)."""

    has_state = False       # nothing to checkpoint
    kind = "tables"

    def __init__(self, drawdown: Any, cell_material: np.ndarray) -> None:
        self.drawdown = drawdown
        self.cell_material = cell_material

    @property
    def active(self) -> bool:
        return self.drawdown.active

    def advance_to(self, t: float) -> None:
        """A table is known at every time: nothing to do."""

    def cell_dp(self, t: float) -> np.ndarray:
        return self.drawdown.cell_values(t, self.cell_material)

    def unchanged(self, t_end: float) -> np.ndarray:
        """Per local cell: its material has no table, or one that is zero on [0, t_end]."""
        still = np.array([tab is None or bool(zero_on(tab.times, tab.values, t_end))
                          for tab in self.drawdown.tables], dtype=bool)
        return still[self.cell_material] if len(still) else np.ones(len(self.cell_material), dtype=bool)

    def loaded_cells(self, t: float) -> np.ndarray:
        """The cells of the materials with a table that is not zero throughout."""
        loaded = np.array([tab is not None and any(v != 0 for v in tab.values) for tab in self.drawdown.tables],
                          dtype=bool)
        return loaded[self.cell_material] if len(loaded) else np.zeros(len(self.cell_material), dtype=bool)

    def step_record(self) -> dict:
        return {}

    def vertex_head(self) -> None:
        """No head field: the tables give the pressure change directly."""
        return None

    def state(self) -> None:
        return None

    def restore(self, state: None) -> None:
        """Nothing to restore."""

    def destroy(self) -> None:
        pass


class FlowSource:
    """The pore-pressure change of pfault's groundwater-flow model (pfault.solver.flow.GroundwaterFlow):
    dp = rho_w g h, h the cell average of the P1 head change. ``advance_to`` solves the flow up to t; within the
    interval of the last advance ``cell_dp`` interpolates linearly in time between the fields at its ends."""

    has_state = True        # its head, time and records are checkpointed
    kind = "flow"

    def __init__(self, flow: Any) -> None:
        self.flow = flow
        self._before: tuple[float, np.ndarray] | None = None     # (time, dp) before the last advance

    @property
    def active(self) -> bool:
        return self.flow.active

    @property
    def time(self) -> float:
        return self.flow.time

    def _current(self) -> np.ndarray:
        return self.flow.cell_dp()

    def advance_to(self, t: float) -> None:
        if not after(t, self.flow.time):
            return
        self._before = (self.flow.time, self._current())
        self.flow.advance_to(t)

    def cell_dp(self, t: float) -> np.ndarray:
        now = self.flow.time
        if self._before is not None and self._before[0] < t < now:
            t0, dp0 = self._before
            theta = (t - t0) / (now - t0)
            return (1.0 - theta) * dp0 + theta * self._current()
        if after(t, now) or after(now, t):
            raise ValueError(f"groundwater flow is at t = {now:g} s; its pore pressure at {t:g} s is not known")
        return self._current()

    def unchanged(self, t_end: float) -> None:
        """Known only as the flow is solved."""
        return None

    def loaded_cells(self, t: float) -> np.ndarray:
        """Every cell: the flow model solves for the head of all of them."""
        return np.ones(len(self._current()), dtype=bool)

    def step_record(self) -> dict:
        """The flow's Krylov iterations in its last step and the largest drawdown (m) now (collective)."""
        if not self.flow.history:
            return {}
        h = self.flow.vertex_head()
        mpi = self.flow.comm.tompi4py()
        return {"flow_ksp_its": int(self.flow.history[-1].get("ksp_its", 0)),
                "max_drawdown_m": mpi.allreduce(float(np.max(-h, initial=0.0)), op=MPI.MAX)}

    def vertex_head(self) -> np.ndarray:
        return self.flow.vertex_head()

    def state(self) -> FlowState:
        """Its head per local vertex (m), time (s) and step records."""
        return FlowState(self.flow.vertex_head(), float(self.flow.time), tuple(self.flow.history))

    def restore(self, state: FlowState) -> None:
        self.flow.restore(state.head, state.time, list(state.history))
        self._before = None

    def destroy(self) -> None:
        self.flow.destroy()


class Unchanged:
    """The pore-pressure change of ``source`` except in the cells of ``mask`` (bool per local cell), where the
    pore pressure stays at its initial value (the materials of -pfault_pore_pressure_unchanged_materials: an
    impermeable rock, a clay the wells do not drain): no Biot load there, nor at the fault faces whose minus cell
    it is, and zero in the output's pore_pressure_change. Everything else (advancing, the flow model's head and
    records, its state) is the source's."""

    def __init__(self, source: Any, mask: np.ndarray) -> None:
        self.source = source
        self.mask = np.asarray(mask, dtype=bool)
        self.has_state = source.has_state
        self.kind = source.kind

    @property
    def active(self) -> bool:
        return self.source.active

    def advance_to(self, t: float) -> None:
        self.source.advance_to(t)

    def cell_dp(self, t: float) -> np.ndarray:
        return np.where(self.mask, 0.0, self.source.cell_dp(t))

    def unchanged(self, t_end: float) -> np.ndarray | None:
        """The source's unchanged cells and those of the mask (None where the source knows only as it runs)."""
        inner = self.source.unchanged(t_end)
        return None if inner is None else inner | self.mask

    def loaded_cells(self, t: float) -> np.ndarray:
        return self.source.loaded_cells(t) & ~self.mask

    def step_record(self) -> dict:
        return self.source.step_record()

    def vertex_head(self) -> np.ndarray | None:
        return self.source.vertex_head()

    def state(self) -> Any:
        return self.source.state()

    def restore(self, state: Any) -> None:
        self.source.restore(state)

    def destroy(self) -> None:
        self.source.destroy()
