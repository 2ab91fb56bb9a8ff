"""Margins to failure at a run's output times: how much further uniform drawdown each part of the equations' terms
takes before it fails (a fault face slips, opens or breaks), from the converged state and its linear response.

The drawdown lam (m of head) lowers the pore pressure by rho_w g lam in every cell the pore-pressure source
changes (``loaded_cells``, pfault.sources: the materials with a table that is not zero; every cell of the flow
model; the cells of a groundwater model's heads that change at some saved time), the faces' own pore pressure with
them. One linear solve with the step's Jacobian at the converged state, in the branches the drawdown takes (a
fault's faces keep their states, a soil's cells on their cap compact on the virgin line), gives the state's rate
(pfault.solver.response); each term turns it into its margins (pfault.faults.margins for the faults). The response
is taken as linear up to a part's failure: nothing else fails first and redistributes the load
(docs/theory.md, "Margins to failure").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .errors import InputError
from .records import SolveCost, merge_json
from .solver.response import Response, drawdown_response
from .solver.terms import MarginSettings


def read_margin_settings(reader: Any, settings: Any, origin: tuple) -> MarginSettings | None:
    """-pfault_margins and -pfault_margin_thresholds (None: margins off); ``settings``: the scene's (water density,
    gravity); ``origin``: the site coordinates of the mesh's origin."""
    thresholds = tuple(float(v) for v in reader.get("pfault_margin_thresholds"))
    if not reader.get("pfault_margins"):
        return None
    if not thresholds or any(not (v > 0 and np.isfinite(v)) for v in thresholds):
        raise InputError(f"-pfault_margin_thresholds: give positive drawdowns in m of head, e.g. 1,5,10, got "
                         f"{','.join(f'{v:g}' for v in thresholds) or 'none'}")
    return MarginSettings(settings.water_density * settings.gravity, tuple(sorted(set(thresholds))), tuple(origin))


@dataclass(frozen=True)
class MarginStep:
    """The margins at an output time: each term's (``terms``: one per term, None for a term without), whether the
    linear solve converged (else the margins of parts that have not failed are NaN), its cost and whether it was
    solved (``solved``: not when every part has failed, whose margins are zero whatever the response)."""
    terms: tuple
    converged: bool
    cost: SolveCost
    solved: bool = True

    def as_json(self) -> dict:
        """The step record's part: ``margin_solve`` and each term's (a fault's ``faults``/NAME/``margin``)."""
        c = self.cost
        out: dict = {"margin_solve": {"solved": bool(self.solved), "converged": bool(self.converged),
                                      "ksp_its": int(c.ksp_its), "factorizations": int(c.factorizations),
                                      "jacobians": int(c.jacobians), "pc_setups": int(c.pc_setups),
                                      "wall_s": float(c.wall_s)}}
        for part in self.terms:
            if part is not None:
                merge_json(out, part.as_json())
        return out

    def fields(self) -> dict:
        """The output series' fields of every term ({"fault": ..., "cells": ...})."""
        out: dict = {}
        for part in self.terms:
            if part is not None:
                merge_json(out, part.fields())
        return out


class Margins:
    """The margins of the terms of ``model``'s equations, measured with the step solver ``solver`` (its KSP and
    factors) at a converged state; ``settings``: MarginSettings, None when they are off (-pfault_margins false).
    Keeps the last output time's response, whose rate the next one takes where its system is the same
    (pfault.solver.response.Response.reused)."""

    def __init__(self, model: Any, solver: Any, settings: MarginSettings | None) -> None:
        self.model, self.solver, self.settings = model, solver, settings
        self.response: Response | None = None

    def measure(self, state: Any, t: float) -> MarginStep | None:
        """The margins at the converged state ``state`` at time t (collective); None when they are off, the
        equations have no term, or the source loads no cell."""
        eq, source = self.model.equations, self.model.source
        if self.settings is None or not eq.terms:
            return None
        loaded = source.loaded_cells(t) if source.active else np.zeros(len(self.model.mesh.cells), dtype=bool)
        if not self.model.comm.tompi4py().allreduce(bool(np.any(loaded)), op=MPI.LOR):
            return None
        stage = PETSc.Log.Stage("Margins")
        stage.push()
        try:
            return self._measure(state, t, loaded)
        finally:
            stage.pop()

    def _measure(self, state: Any, t: float, loaded: np.ndarray) -> MarginStep:
        """``measure`` on the cells ``loaded`` (under -log_view, stage Margins)."""
        eq = self.model.equations
        x_loc = eq.local_array(state.u)
        live = sum(term.margin_parts(x_loc, load, h) for term, load, h in zip(eq.terms, eq.loads.term_loads,
                                                                              state.histories))
        response = drawdown_response(eq, self.solver, state, t, -self.settings.rho_g * loaded.astype(float),
                                     solve=live > 0, previous=self.response)
        if response.system is not None:
            self.response = response
        parts = tuple(term.margins(x_loc, response.dx, load, rate, h, self.model.mesh, self.settings)
                      for term, load, rate, h in zip(eq.terms, eq.loads.term_loads, response.rates, state.histories))
        return MarginStep(parts, response.converged, response.cost, live > 0)
