"""summary.json: what a run computed and what it cost, composed from the model, the state, the solver's counts,
the effects' costs and the step records (those of the faults included).

``RunSummary.compose`` makes it after every step (SummaryObserver, ``running``: true) and at the end of the run
(pfault.simulation); a run that fails after its first completed step amends the last one written
(pfault.io.output.record_failure).
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from .hazard import summary_maxima


class RunSummary:
    """Composes summary.json for the run of ``model`` (``state``: its solution; ``solver``: the step solver;
    ``costs``: pfault.effects.EffectCosts; ``restart_step``: the step a restarted run continues after, or
    None)."""

    def __init__(self, model: Any, state: Any, solver: Any, costs: Any, restart_step: int | None = None) -> None:
        self.model, self.state, self.solver, self.costs = model, state, solver, costs
        self.restart_step = restart_step
        self.partition = partition(model)

    def compose(self, steps: list, converged: bool, stop: str | None, running: bool = False) -> dict:
        """The summary of the step records ``steps`` (collective: the memory peak and the costs are every
        rank's); ``stop``: the signal that stopped the run, or None."""
        m = self.model
        last = [r for r in steps if "max_subsidence_m" in r]
        summary = {
            "scene": m.settings.scene,
            "ranks": m.comm.size,
            "mesh": {"nodes": int(m.mesh.n_global_vertices), "cells": int(m.mesh.n_global_cells),
                     "fault_faces": int(len(m.fault_id)) if m.faults is not None else 0},
            "fields": list(m.dofmap.fields),
            "dofs": int(self.state.u.getSize()),
            "solver": self.solver_record(steps),
            "steps": steps,
            "max_subsidence_m": max([r["max_subsidence_m"] for r in last], default=0.0),
            "max_horizontal_displacement_m": max([r["max_horizontal_displacement_m"] for r in last], default=0.0),
            "final_subsidence_m": last[-1]["max_subsidence_m"] if last else 0.0,
            "max_fault_opening_m": max([r.get("max_fault_opening_m", 0.0) for r in last], default=0.0),
            "max_fault_slip_m": max([r.get("max_fault_slip_m", 0.0) for r in last], default=0.0),
            "memory_peak_mib": memory_peak_mib(m.comm),
            "partition": self.partition,
            "converged": bool(converged),
            "effects": self.costs.record(m.scene.effects, len([r for r in steps if not r.get("initial")])),
            # a run in progress, or one killed before it could say how it ended, reads running: true
            "running": bool(running),
            "interrupted": stop is not None,
            "completed_steps": [r["step"] for r in last if r["converged"]],
        }
        if m.faults is not None:
            summary["faults"] = fault_summary(m, last)
        summary.update(summary_maxima(last, m.settings.hazard_strain_threshold))
        if stop is not None:
            summary["stop_signal"] = stop
        if m.scene.restart_dir:
            summary["restart"] = {"from": m.scene.restart_dir, "step": self.restart_step}
        return summary

    def solver_record(self, steps: list) -> dict:
        """The linear solver and its iterations: Krylov iterations per Newton iteration over the run (each
        step's own is in its record, ``ksp_per_newton``)."""
        ksp_type, pc_type = self.solver.ksp_types()
        newton = sum(r.get("newton_its", 0) for r in steps)
        krylov = sum(r.get("ksp_its", 0) for r in steps)
        return {"file": self.model.solver_file, "ksp_type": ksp_type, "pc_type": pc_type,
                "newton_its": int(newton), "ksp_its": int(krylov),
                "ksp_per_newton": krylov / newton if newton else 0.0,
                "max_ksp_per_newton": max([r.get("ksp_per_newton", 0.0) for r in steps], default=0.0)}


def fault_summary(model: Any, steps: list) -> dict:
    """Per fault (by name): its faces, the mean height of the cells beside it, the largest opening of an open
    face and slip of a face that has slid over the steps ``steps`` (0 where none did), and at the last of them
    its faces stuck, slipping, open and broken, its integrals (slip potency, open volume, slipping and open areas:
    pfault.run.fault_figures) and its broken part's area, depth, trace length and first break time
    (pfault.run.broken_figures). Collective."""
    names = [f.name for f in model.scene.fault_settings]
    faces = np.bincount(model.fault_id, minlength=len(names))
    height = beside_height(model, len(names))
    out = {}
    for k, name in enumerate(names):
        per = [r["faults"][name] for r in steps if "faults" in r]
        last = per[-1] if per else {}
        out[name] = {"faces": int(faces[k]), "beside_cell_height_m": height[k],
                     "max_opening_m": max([p["max_opening_m"] for p in per], default=0.0),
                     "max_slip_m": max([p["max_slip_m"] for p in per], default=0.0),
                     **dict.fromkeys(("faces_stuck", "faces_slipping", "faces_open", "faces_broken", "broken_area_m2",
                                      "broken_depth_m", "broken_length_m"), 0),
                     "first_break_time_s": None,
                     **{key: v for key, v in last.items() if key not in ("max_opening_m", "max_slip_m")}}
    return out


def beside_height(model: Any, n_faults: int) -> list:
    """Per fault, the mean height of the cells on both sides of its faces over them (3 x volume / face area,
    weighted by the face's area: the distance the P1 displacement spreads a jump over, the resolution of the
    fault's answer; m). Collective."""
    faces = model.faults.faces
    x = model.mesh.coords[model.mesh.cells[faces.sides.cell]]          # (nf, 2, 4, 3)
    e = x[:, :, 1:] - x[:, :, :1]
    volume = np.abs(np.einsum("nsi,nsi->ns", e[:, :, 0], np.cross(e[:, :, 1], e[:, :, 2]))) / 6.0
    sums = np.zeros((n_faults, 2))
    np.add.at(sums, faces.fault, np.column_stack([1.5 * volume.sum(axis=1), faces.area]))
    sums = model.comm.tompi4py().allreduce(sums)
    return [float(h / a) if a > 0 else 0.0 for h, a in sums]


def partition(model: Any) -> dict:
    """What each rank owns, in rank order: its cells, vertices and fault faces (a rank may own none on a small
    mesh; the results do not depend on it). Collective."""
    mesh = model.mesh
    nf = 0 if model.faults is None else model.faults.faces.nf
    counts = model.comm.tompi4py().allgather((len(mesh.cells), int(np.count_nonzero(mesh.vert_owned)), int(nf)))
    return {key: [int(c[k]) for c in counts] for k, key in enumerate(("cells", "vertices", "fault_faces"))}


def memory_peak_mib(comm: Any) -> list:
    """The largest resident set size of each rank's process so far, in MiB (a list in rank order; collective)."""
    import resource
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss      # KiB on Linux, bytes on macOS
    mib = peak / (1024.0 * 1024.0 if sys.platform == "darwin" else 1024.0)
    return [round(m, 1) for m in comm.tompi4py().allgather(mib)]
