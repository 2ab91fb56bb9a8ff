"""The time loop: advance the pore-pressure source, solve the step, measure it, hand the result to the observers.

``Stepper`` solves a step (the policy's solve, in whose Newton solve the terms settle: a fault's faces that
break), commits the terms' histories and measures the converged state into a typed record (pfault.records.
StepRecord). An observer has ``step_started(step, t)`` (before the step is solved) and ``step_done(result)`` (a
``StepResult``); each reads the result, none changes it or the state.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .effects import logged
from .initial import GeostaticStart
from .interrupt import StopRequest
from .records import Solve, SolveCost, StepRecord
from .surface import LandSurface, SurfaceStep


@dataclass(frozen=True)
class StepResult:
    """A completed step: its number and time, its record, the displacement relative to the initial state (local
    array), whether its fields are written (``output``), the stop signal agreed after it (or None), the land
    surface's step (rank 0, output steps with a land surface; None otherwise)."""
    step: int
    t: float
    record: StepRecord
    u_rel: np.ndarray
    output: bool = False
    stop: str | None = None
    surface: SurfaceStep | None = None


def surface_figures(model: Any, u_rel: np.ndarray) -> tuple[float, float]:
    """Maximum subsidence and horizontal displacement on the ground surface (relative to the initial state)."""
    mesh, dofmap = model.mesh, model.dofmap
    ground = (mesh.vert_data[:, 1] == 1) & mesh.vert_owned
    sub, hor = 0.0, 0.0
    for side in range(dofmap.max_sides):
        sel = ground & (dofmap.vert_sides > side)
        u = u_rel[dofmap.vertex_dofs(side)[sel]]
        if len(u):
            sub = max(sub, float(np.max(-u[:, 2])))
            hor = max(hor, float(np.max(np.hypot(u[:, 0], u[:, 1]))))
    mpi = model.comm.tompi4py()
    return mpi.allreduce(sub, op=MPI.MAX), mpi.allreduce(hor, op=MPI.MAX)


def relative_displacement(model: Any, state: Any) -> np.ndarray:
    """u - u_ref as a local array."""
    du = state.u.duplicate()
    state.u.copy(du)
    du.axpy(-1.0, state.u_ref)
    loc = model.equations.local_array(du)
    du.destroy()
    return loc


def per_side(model: Any, u_rel: np.ndarray) -> np.ndarray:
    """The displacement of every local vertex, its sides (pieces) in order, side 0 repeated where a vertex has
    fewer (nv, 3 * max sides)."""
    dofmap = model.dofmap
    return np.concatenate([u_rel[dofmap.vertex_dofs(side)] for side in range(dofmap.max_sides)], axis=1)


class Stepper:
    """Solves and measures the steps of ``model`` from ``state`` with ``solver`` (pfault.solver.policy.StepSolver);
    ``surface``: the land surface and ``margins`` the margins to failure (pfault.margins.Margins), measured at
    output steps."""

    def __init__(self, model: Any, state: Any, solver: Any, surface: LandSurface, margins: Any) -> None:
        self.model, self.state, self.solver, self.surface, self.margins = model, state, solver, surface, margins
        self.eq = model.equations

    def terms_measures(self, x_loc: np.ndarray, x_rel: np.ndarray, at_rest: bool = False) -> tuple:
        """The terms' measures for the record (collective); ``at_rest``: under the loads of the initial state."""
        return tuple(term.measures(x_loc, x_rel, term.at_rest(load) if at_rest else load, h, self.model.mesh)
                     for term, load, h in zip(self.eq.terms, self.eq.loads.term_loads, self.state.histories))

    def initial(self) -> StepRecord:
        """The geostatic initial equilibrium (step 0): its record (with the margins of the initial state)."""
        t0 = time.perf_counter()
        with logged("pfaultGeostatic"):
            GeostaticStart(self.eq, self.model.settings).compute(self.state, self.solver.solve_linear)
        loc = self.eq.local_array(self.state.u)
        counts = self.eq.counts(self.state.u, self.state.histories)
        terms = self.terms_measures(loc, np.zeros_like(loc), at_rest=True)    # its own jumps: zero
        solve = Solve(0.0, True, 0, SolveCost(wall_s=time.perf_counter() - t0), counts=counts)
        return StepRecord(0, solve, terms=terms, initial=True, margins=self.initial_margins())

    def initial_margins(self) -> Any:
        """The margins to failure of the initial state (pfault.margins.MarginStep or None; collective)."""
        return self.margins.measure(self.state, self.state.time)

    def solve(self, t_prev: float, t: float) -> Solve:
        """Solve the step from t_prev to t (the source advanced to t; the terms settle within its Newton solve: a
        fault's faces that break, pfault.solver.policy.Settling); a converged step commits the terms' histories
        (a fault's faces slipping or open now have slid)."""
        eq, state = self.eq, self.state
        solve = self.solver.solve_interval(t_prev, t, self.model.settings.max_cuts)
        if solve.converged and eq.terms:
            x_loc = eq.local_array(state.u)
            state.histories = tuple(term.commit(x_loc, load, h)
                                    for term, load, h in zip(eq.terms, eq.loads.term_loads, state.histories))
        return solve

    def measure(self, step: int, solve: Solve, source: dict, due: bool
                ) -> tuple[StepRecord, np.ndarray, SurfaceStep | None]:
        """The record of the solved step (``source``: the pore-pressure source's figures; on an output step
        (``due``) of a converged one the margins to failure), the displacement relative to the initial state and,
        on an output step, the land surface's step."""
        model = self.model
        u_rel = relative_displacement(model, self.state)
        sub, hor = surface_figures(model, u_rel)
        x_loc = self.eq.local_array(self.state.u)
        terms = self.terms_measures(x_loc, u_rel)
        hazard, surface = (self.surface.measure(per_side(model, u_rel), (x_loc, self.eq.loads.term_loads,
                                                                         self.state.histories))
                           if due else ({}, None))
        margins = self.margins.measure(self.state, solve.time_s) if due and solve.converged else None
        return StepRecord(step, solve, sub, hor, hazard or {}, terms, source, margins=margins), u_rel, surface


def time_loop(stepper: Stepper, observers: list, times: np.ndarray, first: int, offset: int, records: list,
              wall: dict, after_first_solve: Callable[[], None]) -> tuple[bool, str | None]:
    """Steps first+1 .. len(times)-1 of the time grid ``times`` (step number = grid index + ``offset``), each
    record's JSON appended to ``records``; ``after_first_solve`` is called once the first step is solved (every
    solver option has been read by then). Returns (every step converged, the stop signal or None)."""
    model = stepper.model
    every = model.settings.output_every
    solve_stage, out_stage = PETSc.Log.Stage("Solve"), PETSc.Log.Stage("Output")
    converged, stop = True, None
    with StopRequest(model.comm) as request:       # after meshing: gmsh resets the SIGINT handler
        for index in range(first + 1, len(times)):
            step, t = index + offset, float(times[index])
            for obs in observers:
                obs.step_started(step, t)
            solve_stage.push()
            model.source.advance_to(t)
            stepper.state.source_state = model.source.state()
            solve = stepper.solve(float(times[index - 1]), t)
            source = model.source.step_record()
            solve_stage.pop()
            after_first_solve()
            wall["solve"] += solve.cost.wall_s
            stop = request.agreed()
            due = index % every == 0 or index == len(times) - 1 or not solve.converged or stop is not None
            record, u_rel, surface = stepper.measure(step, solve, source, due)
            wall["margins"] = wall.get("margins", 0.0) + record.margins_wall_s
            records.append(record.as_json())
            result = StepResult(step, t, record, u_rel, output=due, stop=stop, surface=surface)
            t0 = time.perf_counter()
            out_stage.push()
            for obs in observers:
                obs.step_done(result)
            out_stage.pop()
            wall["output"] += time.perf_counter() - t0
            if not solve.converged:
                converged = False
                break
            if stop is not None:
                PETSc.Sys.Print(f"pfault: stopped after step {step} ({stop})")
                break
    return converged, stop
