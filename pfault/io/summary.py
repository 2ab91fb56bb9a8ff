"""summary.json: what a run computed and what it cost, composed from the model, the state, the solver's counts,
the effects' costs and the step records (those of the faults included).

``RunSummary.compose`` makes it after every step (SummaryObserver, ``running``: true) and at the end of the run
(pfault.simulation); a run that fails after its first completed step amends the last one written
(pfault.io.output.record_failure).
"""

from __future__ import annotations

import resource
import sys
from typing import Any

import numpy as np

from ..hazard import summary_maxima


class RunSummary:
    """Composes summary.json for the run of ``model`` (``state``: its solution; ``solver``: the step solver;
    ``costs``: pfault.effects.EffectCosts; ``restart_step``: the step a restarted run continues after, or
    None)."""

    def __init__(self, model: Any, state: Any, solver: Any, costs: Any, restart_step: int | None = None) -> None:
        self.model, self.state, self.solver, self.costs = model, state, solver, costs
        self.restart_step = restart_step
        # keys the run adds (the pore-pressure source's coverage, a restart's data files); a dict merges into the
        # key of that name
        self.extra: dict[str, Any] = {}
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
                     "fault_faces": int(m.faces.total)},
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
        for term in m.equations.terms:
            summary.update(term.summary(last, m.mesh))
        summary.update(summary_maxima(last, m.settings.hazard_strain_threshold))
        if m.scene.warnings:
            summary["warnings"] = list(m.scene.warnings)
        if stop is not None:
            summary["stop_signal"] = stop
        if m.scene.restart_dir:
            summary["restart"] = {"from": m.scene.restart_dir, "step": self.restart_step}
        for key, value in self.extra.items():
            both = isinstance(value, dict) and isinstance(summary.get(key), dict)
            summary[key] = {**summary[key], **value} if both else value
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


def partition(model: Any) -> dict:
    """What each rank owns, in rank order: its cells, vertices and fault faces (a rank may own none on a small
    mesh; the results do not depend on it). Collective."""
    mesh = model.mesh
    nf = len(model.faces.face)
    counts = model.comm.tompi4py().allgather((len(mesh.cells), int(np.count_nonzero(mesh.vert_owned)), int(nf)))
    return {key: [int(c[k]) for c in counts] for k, key in enumerate(("cells", "vertices", "fault_faces"))}


def memory_peak_mib(comm: Any) -> list:
    """The largest resident set size of each rank's process so far, in MiB (a list in rank order; collective)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss      # KiB on Linux, bytes on macOS
    mib = peak / (1024.0 * 1024.0 if sys.platform == "darwin" else 1024.0)
    return [round(m, 1) for m in comm.tompi4py().allgather(mib)]
