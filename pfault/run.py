"""The time loop: advance the pore-pressure source, solve the step, hand its result to the observers.

An observer has ``step_started(step, t)`` (before the step is solved) and ``step_done(result)`` (a
``StepResult``, once it is solved and measured); each reads the result, none changes the state or the step's
record. The output observers may derive figures from a step (the land surface's hazard maxima) into
``result.derived``, which the observers after them (checkpoint, summary) carry with the record.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .effects import logged
from .faults.contact import OPEN, SLIP, STICK
from .interrupt import StopRequest

INTEGRALS = ("slip_potency_m3", "open_volume_m3", "slipping_area_m2", "open_area_m2")    # per fault and step


@dataclass
class StepResult:
    """A completed step: its number and time, the solver's record with the step's measured figures, the
    displacement relative to the initial state (local array), whether its fields are written (``output``),
    the stop signal agreed after it (or None), and the figures the output observers derived from it."""
    step: int
    t: float
    record: dict
    u_rel: np.ndarray | None
    output: bool = False
    stop: str | None = None
    derived: dict = field(default_factory=dict)

    def full_record(self) -> dict:
        return {**self.record, **self.derived}


def surface_figures(model: Any, u_rel: np.ndarray) -> tuple[float, float]:
    """Maximum subsidence and horizontal displacement on the ground surface (relative to the initial state)."""
    mesh, dofmap = model.mesh, model.dofmap
    ground = (mesh.vert_data[:, 1] == 1) & mesh.vert_owned
    sub, hor = 0.0, 0.0
    for side in (0, 1):
        sel = ground & (dofmap.vert_sides > side)
        u = u_rel[dofmap.vertex_dofs(side)[sel]]
        if len(u):
            sub = max(sub, float(np.max(-u[:, 2])))
            hor = max(hor, float(np.max(np.hypot(u[:, 0], u[:, 1]))))
    mpi = model.comm.tompi4py()
    return mpi.allreduce(sub, op=MPI.MAX), mpi.allreduce(hor, op=MPI.MAX)


def fault_figures(model: Any, states: np.ndarray, slid: np.ndarray, u_rel: np.ndarray) -> dict:
    """Per fault (by name): how many faces are stuck, slipping and open (``states``: each owned face's, as
    reported), the largest opening of its open faces and the largest slip of its faces that have slid
    (``slid``: slipping or open at the end of a completed step, now or before), 0 where there are none; and
    the largest of these over the faults. The jumps are the face-mean jumps (with the bubbles' part) relative
    to the initial state; a closed face's opening and a stuck face's slip increment are zero to the solver's
    tolerance, and are not counted here (fault.h5 has every face's jump). The integrals over each fault, which
    converge under refinement where a largest value may not (it sits at a singular point: a fault's tip, its
    foot on a fixed boundary): the slip potency (m^3, the area integral of the slip of the faces that have slid),
    the open volume (m^3, of the opening of the open faces) and the slipping and open areas (m^2)."""
    faces = model.faults.faces
    names = [f.name for f in model.scene.fault_settings]
    gl = model.faults.relative_jumps(u_rel)[1]     # face-mean jumps with the bubbles' part
    opening = np.where(states == OPEN, gl[:, 0], 0.0)
    slip = np.where(slid, np.linalg.norm(gl[:, 1:], axis=1), 0.0)
    counts = np.zeros((len(names), 3), dtype=np.int64)
    np.add.at(counts, (faces.fault, states), 1)
    largest = np.zeros((len(names), 2))
    np.maximum.at(largest, faces.fault, np.column_stack([opening, slip]))
    a = faces.area
    integrals = np.zeros((len(names), 4))
    np.add.at(integrals, faces.fault, np.column_stack([a * slip, a * opening, a * (states == SLIP),
                                                       a * (states == OPEN)]))
    mpi = model.comm.tompi4py()
    mpi.Allreduce(MPI.IN_PLACE, counts, op=MPI.SUM)
    mpi.Allreduce(MPI.IN_PLACE, largest, op=MPI.MAX)
    mpi.Allreduce(MPI.IN_PLACE, integrals, op=MPI.SUM)
    per = {name: {"faces_stuck": int(c[STICK]), "faces_slipping": int(c[SLIP]), "faces_open": int(c[OPEN]),
                  "max_opening_m": float(m[0]), "max_slip_m": float(m[1]),
                  **dict(zip(INTEGRALS, (float(v) for v in i)))}
           for name, c, m, i in zip(names, counts, largest, integrals)}
    return {"max_fault_opening_m": float(largest[:, 0].max(initial=0.0)),
            "max_fault_slip_m": float(largest[:, 1].max(initial=0.0)), "faults": per}


def relative_displacement(model: Any, state: Any) -> np.ndarray:
    """u - u_ref as a local array."""
    du = state.u.duplicate()
    state.u.copy(du)
    du.axpy(-1.0, state.u_ref)
    loc = model.equations.local_array(du)
    du.destroy()
    return loc


def initial_state(model: Any, state: Any, solver: Any, wall: dict) -> list[dict]:
    """The geostatic initial equilibrium (step 0), when the scene asks for one; returns its step records."""
    if not model.settings.geostatic:
        return []
    stage = PETSc.Log.Stage("Solve")
    stage.push()
    t0 = time.perf_counter()
    with logged("pfaultGeostatic"):
        solver.geostatic()
    state.u.copy(state.u_ref)
    rec = {"time_s": 0.0, "newton_its": 0, "ksp_its": 0, "wall_s": time.perf_counter() - t0,
           "converged": True, "initial": True, "step": 0}
    if model.faults is not None:
        loc = model.equations.local_array(state.u)
        rec.update(model.faults.counts_by_state(loc))
        with model.faults.bubbles.unloaded():       # the initial state's own jumps: zero relative to itself
            rec.update(fault_figures(model, model.faults.states(loc), state.fault_slid, np.zeros_like(loc)))
    stage.pop()
    wall["solve"] += rec["wall_s"]
    return [rec]


def time_loop(model: Any, state: Any, solver: Any, observers: list, times: np.ndarray, first: int, offset: int,
              records: list, wall: dict, after_first_solve: Callable[[], None]) -> tuple[bool, str | None]:
    """Steps first+1 .. len(times)-1 of the time grid ``times`` (step number = grid index + ``offset``), each
    record appended to ``records``; ``after_first_solve`` is called once the first step is solved (every
    solver option has been read by then). Returns (every step converged, the stop signal or None)."""
    s = model.settings
    solve_stage, out_stage = PETSc.Log.Stage("Solve"), PETSc.Log.Stage("Output")
    converged, stop = True, None
    with StopRequest(model.comm) as request:       # after meshing: gmsh resets the SIGINT handler
        for index in range(first + 1, len(times)):
            step, t = index + offset, float(times[index])
            for obs in observers:
                obs.step_started(step, t)
            solve_stage.push()
            model.source.advance_to(t)
            rec = solver.solve_interval(times[index - 1], t, s.max_cuts)
            rec.update(model.source.step_record())
            solve_stage.pop()
            rec["step"] = step
            after_first_solve()
            wall["solve"] += rec["wall_s"]
            u_rel = relative_displacement(model, state)
            rec["max_subsidence_m"], rec["max_horizontal_displacement_m"] = surface_figures(model, u_rel)
            if model.faults is not None:
                states = model.faults.states(model.equations.local_array(state.u))
                if rec["converged"]:
                    state.fault_slid |= states != STICK
                rec.update(fault_figures(model, states, state.fault_slid, u_rel))
            records.append(rec)
            stop = request.agreed()
            due = index % s.output_every == 0 or index == len(times) - 1 or not rec["converged"] or stop is not None
            result = StepResult(step, t, rec, u_rel, output=due, stop=stop)
            t0 = time.perf_counter()
            out_stage.push()
            for obs in observers:
                obs.step_done(result)
                if result.derived:
                    records[-1] = result.full_record()      # the checkpoint and summary carry them
            out_stage.pop()
            wall["output"] += time.perf_counter() - t0
            if not rec["converged"]:
                converged = False
                break
            if stop is not None:
                PETSc.Sys.Print(f"pfault: stopped after step {step} ({stop})")
                break
    return converged, stop
