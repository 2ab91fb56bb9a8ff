"""Runs one scene: the model, the state, the solver, the time loop and its observers. Called by the command line
and by tests."""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np
from petsc4py import PETSc

from . import run as loop
from .effects import EffectCosts
from .errors import InputError
from .io.observations import Observations, read_observation_settings
from .io.observers import (CheckpointObserver, FieldOutput, Observer, ProgressLine, RunOutput, SummaryObserver,
                           format_time, progress_line)
from .model import Model, build_model
from .options import OptionReader, check_unused_petsc_options
from .solver.policy import StepSolver
from .state import State


class Simulation:
    """One run of the scene in ``options_file``: ``setup()`` builds the model, the state and the solver;
    ``run()`` the time loop; ``write_summary`` the final summary.json and figures. The observers of every step
    are those ``observers`` returns."""

    def __init__(self, options_file: str = "", argv: list | tuple = ()) -> None:
        self.options_file = options_file
        self.argv = list(argv)
        self.comm = PETSc.COMM_WORLD
        self.reader = OptionReader(PETSc)
        self.wall = {"mesh": 0.0, "setup": 0.0, "solve": 0.0, "output": 0.0}
        self.summary: dict | None = None
        self.model: Model | None = None
        self.state: State | None = None
        self.solver: StepSolver | None = None
        self.output: RunOutput | None = None
        self.restart_step: int | None = None
        self.observations: Observations | None = None

    @property
    def settings(self) -> Any:
        return self.model.settings

    def setup(self) -> None:
        self.costs = EffectCosts(self.comm)
        observed = read_observation_settings(self.reader, self.options_file)      # before build_model checks the -pfault_ options
        self.model = m = build_model(self.comm, self.reader, self.options_file)
        self.observations = Observations.locate(m, observed)
        self.wall.update(m.wall)
        t0 = time.perf_counter()
        stage = PETSc.Log.Stage("Setup")
        stage.push()
        self.state = State(m.equations.create_vec(), m.faults, m.source)
        contact = m.scene.contact
        self.solver = StepSolver(m.equations, self.state, geostatic=m.settings.geostatic,
                                 monitor=bool(contact is not None and contact.monitor))
        stage.pop()
        self.wall["setup"] += time.perf_counter() - t0

    # ------------------------------------------------------------------------------------------
    def run(self) -> dict:
        m, s = self.model, self.model.settings
        times = np.linspace(0.0, s.time_end, s.time_steps + 1)
        if m.scene.restart_dir:
            records, first, offset = self._restart(times)
        else:
            records, first, offset = loop.initial_state(m, self.state, self.solver, self.wall), 0, 0
            for rec in records:
                PETSc.Sys.Print(progress_line(0, rec))
        self.costs.mark_setup()
        self.output = RunOutput(m, self.state, self.argv, m.scene.restart_dir, self.restart_step)
        converged, stop = loop.time_loop(m, self.state, self.solver, self.observers(self.output, records), times,
                                         first, offset, records, self.wall, self._open_output)
        self.output.close()
        self.summary = self._summary(records, converged, stop)
        return self.summary

    def observers(self, output: RunOutput, records: list) -> list[Observer]:
        """The observers of every step, in the order they see it: the progress line, the fields, the stations and
        the LOS raster (pfault.io.observations), the checkpoint and the summary (``records``: the run's step
        records, which the last two write)."""
        return [ProgressLine(), FieldOutput(output), *self.observations.observers(output),
                CheckpointObserver(output, self.state, records), SummaryObserver(output, self._summary, records)]

    def _open_output(self) -> None:
        """After the first solve (every solver option has been read by then): reject unused options, then open
        the run's output (RunOutput.open)."""
        if self.output.is_open:
            return
        check_unused_petsc_options(PETSc, self.reader)
        t0 = time.perf_counter()
        stage = PETSc.Log.Stage("Output")
        stage.push()
        self.output.open()
        stage.pop()
        self.wall["output"] += time.perf_counter() - t0

    def _restart(self, times: np.ndarray) -> tuple[list, int, int]:
        """State, step records and place on the time grid of the run in -pfault_restart: returns (records,
        grid index of the checkpoint's time, step number minus grid index)."""
        from .io import checkpoint
        restart_dir = self.model.scene.restart_dir
        attrs, records = checkpoint.load(self.comm, restart_dir, self.model, self.state)
        step, t = int(attrs["step"]), float(attrs["time_s"])
        index = int(np.argmin(np.abs(times - t)))
        if abs(times[index] - t) > 1e-9 * times[-1]:
            raise InputError(f"-pfault_restart {restart_dir}: its last completed step ends at t = {t:g} s, "
                             f"which is not a point of the time grid (-pfault_time_end {times[-1]:g} s in "
                             f"{len(times) - 1} steps); choose -pfault_time_end and -pfault_time_steps so that it is")
        if index == len(times) - 1:
            raise InputError(f"-pfault_restart {restart_dir}: the run is complete at t = {t:g} s; give a "
                             "later -pfault_time_end to continue it")
        self.restart_step = step
        PETSc.Sys.Print(f"pfault: continuing {restart_dir} after step {step} (t = {format_time(t).strip()})")
        return records, index, step - index     # the checkpoint's records end at its step

    # ------------------------------------------------------------------------------------------
    def _summary(self, steps: list, converged: bool, stop: str | None, running: bool = False) -> dict:
        m = self.model
        last = [r for r in steps if "max_subsidence_m" in r]
        summary = {
            "scene": m.settings.scene,
            "ranks": self.comm.size,
            "mesh": {"nodes": int(m.mesh.n_global_vertices), "cells": int(m.mesh.n_global_cells),
                     "fault_faces": int(len(m.fault_id)) if m.faults is not None else 0},
            "fields": list(m.dofmap.fields),
            "dofs": int(self.state.u.getSize()),
            "solver": self._solver_record(steps),
            "steps": steps,
            "max_subsidence_m": max([r["max_subsidence_m"] for r in last], default=0.0),
            "max_horizontal_displacement_m": max([r["max_horizontal_displacement_m"] for r in last], default=0.0),
            "final_subsidence_m": last[-1]["max_subsidence_m"] if last else 0.0,
            "max_fault_opening_m": max([r.get("max_fault_opening_m", 0.0) for r in last], default=0.0),
            "max_fault_slip_m": max([r.get("max_fault_slip_m", 0.0) for r in last], default=0.0),
            "memory_peak_mib": self._memory_peak_mib(),
            "converged": bool(converged),
            "effects": self.costs.record(m.scene.effects, len([r for r in steps if not r.get("initial")])),
            # a run in progress, or one killed before it could say how it ended, reads running: true
            "running": bool(running),
            "interrupted": stop is not None,
            "completed_steps": [r["step"] for r in last if r["converged"]],
        }
        from .io.hazard import summary_maxima
        summary.update(summary_maxima(last, m.settings.hazard_strain_threshold))
        if stop is not None:
            summary["stop_signal"] = stop
        if m.scene.restart_dir:
            summary["restart"] = {"from": m.scene.restart_dir, "step": self.restart_step}
        return summary

    def _solver_record(self, steps: list) -> dict:
        """The linear solver and its iterations: Krylov iterations per Newton iteration over the run (each
        step's own is in its record, ``ksp_per_newton``)."""
        ksp_type, pc_type = self.solver.ksp_types()
        newton = sum(r.get("newton_its", 0) for r in steps)
        krylov = sum(r.get("ksp_its", 0) for r in steps)
        return {"file": self.model.solver_file, "ksp_type": ksp_type, "pc_type": pc_type,
                "newton_its": int(newton), "ksp_its": int(krylov),
                "ksp_per_newton": krylov / newton if newton else 0.0,
                "max_ksp_per_newton": max([r.get("ksp_per_newton", 0.0) for r in steps], default=0.0)}

    def _memory_peak_mib(self) -> list:
        """The largest resident set size of each rank's process so far, in MiB (a list in rank order; collective)."""
        import resource
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss      # KiB on Linux, bytes on macOS
        mib = peak / (1024.0 * 1024.0 if sys.platform == "darwin" else 1024.0)
        return [round(m, 1) for m in self.comm.tompi4py().allgather(mib)]

    # ------------------------------------------------------------------------------------------
    def write_summary(self, total: float) -> None:
        """The final summary.json, then the figures. Rank 0 only, under ``run_on_root`` (pfault.cli): the other
        ranks wait for its verdict, so that none ends (with a non-zero exit code that makes mpirun kill the
        others) while files are written, and a failure to write ends them all."""
        self.wall["total"] = total
        self.wall["assembly"] = self.model.equations.assembly_wall
        self.summary["wall_s"] = dict(self.wall)
        if self.comm.rank == 0:
            self.output.finish(self.summary, self.model.scene.figures)

    def record_failure(self, line: str, code: int) -> None:
        """Rank 0, after every rank failed together (RunOutput.record_failure)."""
        if self.output is not None:
            self.output.record_failure(line, code)

    def last_words(self, line: str, code: int) -> None:
        """This rank failed alone and aborts the MPI job next (RunOutput.last_words)."""
        if self.output is not None:
            self.output.last_words(line, code)

    def destroy(self) -> None:
        """Collective: every rank destroys the run at once."""
        if self.output is not None:
            self.output.destroy()
        if self.solver is not None:
            self.solver.destroy()
        if self.state is not None:
            self.state.destroy()
        if self.model is not None:
            self.model.destroy()


__all__ = ["Simulation", "Observer"]
