"""The time loop: advance the pore-pressure source, solve the step, hand its result to the observers.

An observer has ``step_started(step, t)`` (before the step is solved) and ``step_done(result)`` (a
``StepResult``, once it is solved and measured); each reads the result, none changes the state or the step's
record. A step on a fault with candidate surfaces ends once no intact face exceeds its strength
(``resolve_breaks``). The output observers may derive figures from a step (the land surface's hazard maxima) into
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
from .faults.breaking import exceeding
from .faults.contact import OPEN, SLIP, STICK
from .interrupt import StopRequest
from .solver.policy import combined_cost

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
    for side in range(dofmap.max_sides):
        sel = ground & (dofmap.vert_sides > side)
        u = u_rel[dofmap.vertex_dofs(side)[sel]]
        if len(u):
            sub = max(sub, float(np.max(-u[:, 2])))
            hor = max(hor, float(np.max(np.hypot(u[:, 0], u[:, 1]))))
    mpi = model.comm.tompi4py()
    return mpi.allreduce(sub, op=MPI.MAX), mpi.allreduce(hor, op=MPI.MAX)


def broken_figures(model: Any, broken: np.ndarray, break_time: np.ndarray) -> np.ndarray:
    """Per fault (rows in the order of the scene's faults): faces broken, their area (m^2), the depth of the
    deepest broken point below the land surface (m: below its highest point; the built-in scenes' land surfaces
    are flat), the length of the broken part's trace on the land surface (m: the broken faces' edges whose two
    vertices are on it) and the first break time (s, NaN if none broke in the run). Collective."""
    faces, mesh = model.faults.faces, model.mesh
    mpi = model.comm.tompi4py()
    ground = mesh.vert_data[:, 1] == 1
    top = mpi.allreduce(float(np.max(mesh.coords[ground, 2], initial=-np.inf)), op=MPI.MAX)
    nfaults = len(model.scene.fault_settings)
    xyz = mesh.coords[faces.verts]                                     # (nf, 3 vertices, 3)
    depth = np.where(broken, top - xyz[:, :, 2].min(axis=1), 0.0) if np.isfinite(top) else np.zeros(len(broken))
    on = ground[faces.verts]
    edges = [(0, 1), (1, 2), (2, 0)]
    trace = sum(np.where(on[:, a] & on[:, b], np.linalg.norm(xyz[:, a] - xyz[:, b], axis=1), 0.0)
                for a, b in edges) if len(broken) else np.zeros(0)
    sums = np.zeros((nfaults, 3))
    np.add.at(sums, faces.fault, np.column_stack([broken, faces.area * broken, trace * broken]))
    mx = np.full((nfaults, 2), -np.inf)
    np.fmax.at(mx, faces.fault, np.column_stack([depth, -np.where(broken, break_time, np.nan)]))   # NaN: none
    mpi.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    mpi.Allreduce(MPI.IN_PLACE, mx, op=MPI.MAX)
    first = np.where(np.isfinite(mx[:, 1]), -mx[:, 1], np.nan)
    return np.column_stack([sums[:, 0], sums[:, 1], np.maximum(mx[:, 0], 0.0), sums[:, 2], first])


def fault_figures(model: Any, states: np.ndarray, slid: np.ndarray, u_rel: np.ndarray,
                  broken: tuple[np.ndarray, np.ndarray] | None = None) -> dict:
    """Per fault (by name): how many faces are stuck, slipping and open (``states``: each owned face's, as
    reported), the largest opening of its open faces and the largest slip of its faces that have slid
    (``slid``: slipping or open at the end of a completed step, now or before), 0 where there are none; and
    the largest of these over the faults. The jumps are the face-mean jumps (with the bubbles' part) relative
    to the initial state; a closed face's opening and a stuck face's slip increment are zero to the solver's
    tolerance, and are not counted here (fault.h5 has every face's jump). The integrals over each fault, which
    converge under refinement where a largest value may not (it sits at a singular point: a fault's tip, its
    foot on a fixed boundary): the slip potency (m^3, the area integral of the slip of the faces that have slid),
    the open volume (m^3, of the opening of the open faces) and the slipping and open areas (m^2). ``broken``: each
    owned face's broken flag and break time, whose figures (``broken_figures``) join each fault's as
    ``faces_broken``, ``broken_area_m2``, ``broken_depth_m``, ``broken_length_m`` and ``first_break_time_s`` (None
    if none broke in the run)."""
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
    if broken is not None:
        for (name, p), b in zip(per.items(), broken_figures(model, *broken)):
            p.update({"faces_broken": int(b[0]), "broken_area_m2": float(b[1]), "broken_depth_m": float(b[2]),
                      "broken_length_m": float(b[3]),
                      "first_break_time_s": float(b[4]) if np.isfinite(b[4]) else None})
    return {"max_fault_opening_m": float(largest[:, 0].max(initial=0.0)),
            "max_fault_slip_m": float(largest[:, 1].max(initial=0.0)), "faults": per}


def resolve_breaks(model: Any, state: Any, solver: Any, t: float, rec: dict) -> None:
    """The fracture front of a converged step at time t: break every intact face whose traction exceeds its
    strength (pfault.faults.breaking), solve again at the same load, and repeat until none does (a failure
    redistributes load onto its neighbours, which may fail at the same load). Adds to the step's record the
    passes (``breaking_passes``: solves after the first) and the faces broken in the step (``faces_broken_step``),
    and the passes' iterations to its own. Collective; the broken set depends on each face's traction only."""
    faults, mpi = model.faults, model.comm.tompi4py()
    rec["breaking_passes"], rec["faces_broken_step"] = 0, 0
    if not any(f.candidate for f in model.scene.fault_settings):
        return
    while rec["converged"]:
        t_eff = faults.effective(faults.tractions(model.equations.local_array(state.u)))
        new = exceeding(faults.strength, t_eff, state.fault_broken)
        n = mpi.allreduce(int(np.count_nonzero(new)), op=MPI.SUM)
        if n == 0:
            break
        state.break_faces(new, t)
        rec["breaking_passes"] += 1
        rec["faces_broken_step"] += n
        again = solver.solve_step(t)
        rec.update(combined_cost([rec, again]))
        rec["converged"], rec["reason"] = again["converged"], again["reason"]
        for key in ("stick", "slip", "open"):
            rec[key] = again[key]


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
            rec.update(fault_figures(model, model.faults.states(loc), state.fault_slid, np.zeros_like(loc),
                                     (state.fault_broken, state.fault_break_time)))
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
            if model.faults is not None:
                resolve_breaks(model, state, solver, t, rec)
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
                rec.update(fault_figures(model, states, state.fault_slid, u_rel,
                                         (state.fault_broken, state.fault_break_time)))
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
