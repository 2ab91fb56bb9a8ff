"""Runs one scene: the model, the state, the solver, the time loop and its observers. Called by the command line
and by tests."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from petsc4py import PETSc

from . import provenance, run as loop
from .effects import EffectCosts
from .errors import InputError
from .io import checkpoint
from .io.observations import Observations, read_observation_settings
from .io.observers import (CheckpointObserver, FieldOutput, Observer, ProgressLine, RunOutput, SummaryObserver,
                           progress_line)
from .io.summary import RunSummary
from .model import Model, build_model
from .options import OptionReader, check_unused_petsc_options
from .margins import Margins
from .post import figures_apart
from .post.figures import write_run_figures
from .post.gis import write_gis
from .solver.policy import StepSolver
from .sources import coverage
from .state import State
from .surface import LandSurface
from .units import format_time


class Simulation:
    """One run of the scene in ``options_file``, built in one step: the model, the state, the solver, the run's
    output (opened after the first solve) and its summary; on a restart the state is the checkpoint's. ``run()``
    the time loop; ``write_summary`` the final summary.json and figures. The observers of every step are those
    ``observers`` returns."""

    def __init__(self, options_file: str = "", argv: list | tuple = ()) -> None:
        self.argv = list(argv)
        self.comm = PETSc.COMM_WORLD
        self.reader = OptionReader(PETSc)
        self.costs = EffectCosts(self.comm)
        # before build_model checks the options
        observed = read_observation_settings(self.reader, options_file)
        changed_inputs = provenance.read_changed_inputs(self.reader)
        self.model: Model = build_model(self.comm, self.reader, options_file)
        self.wall = {"mesh": 0.0, "setup": 0.0, "solve": 0.0, "margins": 0.0, "output": 0.0, **self.model.wall}
        self.times = np.linspace(0.0, self.settings.time_end, self.settings.time_steps + 1)
        state = solver = None
        try:
            self.observations = Observations.locate(self.model, observed)
            # the data files read, by size and SHA-256 (input_files.json, checkpoint.h5); what summary.json adds
            files = provenance.scene_files(self.model.scene, observed.stations_file, options_file)
            if observed.insar is not None and observed.insar.grid:
                files.append(("pfault_insar_grid", observed.insar.grid))
            self.inputs = provenance.record(self.comm, files)
            self.notes = {"pore_pressure": self._coverage()}
            state, solver = self._state_and_solver(self.model)
            # the records, grid index and step offset of the run a restart continues (None: a new run)
            self.resumed = self._restart(state, changed_inputs) if self.model.scene.restart_dir else None
        except BaseException:
            # every rank at once (the errors here are every rank's), as pfault.model.build_model does
            for part in (solver, state, self.model):
                if part is not None:
                    part.destroy()
            raise
        self.state: State = state
        self.solver: StepSolver = solver
        restart_step = None if self.resumed is None else self.resumed[1] + self.resumed[2]
        self.surface = LandSurface(self.model)
        self.stepper = loop.Stepper(self.model, state, solver, self.surface,
                                    Margins(self.model, solver, self.model.scene.margins))
        self.output = RunOutput(self.model, state, self.argv, self.surface, self.model.scene.restart_dir,
                                restart_step, metadata={provenance.DATASET: self.inputs})
        self.composer = RunSummary(self.model, state, solver, self.costs, restart_step)
        self.composer.extra.update(self.notes)
        georef = self.model.scene.georef
        if georef is not None and (georef.crs is not None or georef.start is not None):
            self.composer.extra["georef"] = georef.summary()
        self.gis = observed.gis and georef is not None and georef.crs is not None

    @property
    def settings(self) -> Any:
        return self.model.settings

    def _state_and_solver(self, m: Model) -> tuple[State, StepSolver]:
        t0 = time.perf_counter()
        stage = PETSc.Log.Stage("Setup")
        stage.push()
        state = State(m.equations.create_vec(), m.equations.initial_histories(), m.source.state())
        contact = m.scene.contact
        try:
            solver = StepSolver(m.equations, state, geostatic=m.settings.geostatic,
                                monitor=bool(contact is not None and contact.monitor))
        except BaseException:
            state.destroy()
            raise
        stage.pop()
        self.wall["setup"] += time.perf_counter() - t0
        return state, solver

    # ------------------------------------------------------------------------------------------
    def run(self) -> dict:
        """The time loop from the initial state, or from the checkpoint of a restart; returns the summary."""
        m = self.model
        if self.resumed is not None:
            records, first, offset = self.resumed
        else:
            records, first, offset = self._initial_state(), 0, 0
        self.costs.mark_setup()
        converged, stop = loop.time_loop(self.stepper, self.observers(self.output, records), self.times, first,
                                         offset, records, self.wall, self._open_output)
        self.output.close()
        return self.composer.compose(records, converged, stop)

    def _initial_state(self) -> list[dict]:
        """The geostatic initial equilibrium (step 0), when the scene asks for one, and the output step of the
        initial state with its margins to failure; returns the initial step records' JSON."""
        records = []
        if self.settings.geostatic:
            stage = PETSc.Log.Stage("Solve")
            stage.push()
            rec = self.stepper.initial()
            stage.pop()
            self.wall["solve"] += rec.solve.cost.wall_s
            self.wall["margins"] += rec.margins_wall_s
            records.append(rec.as_json())
            PETSc.Sys.Print(progress_line(0, records[-1]))
            margins = rec.margins
        else:
            margins = self.stepper.initial_margins()
        self.output.capture_initial(margins)
        return records

    def observers(self, output: RunOutput, records: list) -> list[Observer]:
        """The observers of every step, in the order they see it: the progress line, the fields, the stations and
        the LOS raster (pfault.io.observations), the checkpoint and the summary (``records``: the run's step
        records, which the last two write)."""
        candidates = tuple(f.name for f in self.model.scene.fault_settings if f.candidate)
        return [ProgressLine(candidates), FieldOutput(output), *self.observations.observers(output),
                CheckpointObserver(output, self.state, records), SummaryObserver(output, self.composer, records)]

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

    def _coverage(self) -> dict:
        """The cells the pore-pressure source leaves unloaded (pfault.sources.coverage), said once; summary.json's
        ``pore_pressure``."""
        cov = coverage.measure(self.comm, self.model.source, self.model.assembler.vol, self.settings.time_end)
        if cov.line():
            PETSc.Sys.Print(cov.line())
        return cov.summary()

    def _restart(self, state: State, changed_inputs: tuple = ()) -> tuple[list, int, int]:
        """Restore ``state`` from the checkpoint of the run in -pfault_restart and check that this run's data files are
        that run's (or named in ``changed_inputs``): returns its step records, the grid index of its time and its step
        number minus that index."""
        times = self.times
        restart_dir = self.model.scene.restart_dir
        attrs, records = checkpoint.load(self.comm, restart_dir, self.model, state)
        self.notes["restart"] = provenance.check_restart(self.comm, restart_dir, checkpoint.NAME, self.inputs,
                                                         changed_inputs)
        step, t = int(attrs["step"]), float(attrs["time_s"])
        index = int(np.argmin(np.abs(times - t)))
        if abs(times[index] - t) > 1e-9 * times[-1]:
            raise InputError(f"-pfault_restart {restart_dir}: its last completed step ends at t = {t:g} s, "
                             f"which is not a point of the time grid (-pfault_time_end {times[-1]:g} s in "
                             f"{len(times) - 1} steps); choose -pfault_time_end and -pfault_time_steps so that it is")
        if index == len(times) - 1:
            raise InputError(f"-pfault_restart {restart_dir}: the run is complete at t = {t:g} s; give a "
                             "later -pfault_time_end to continue it")
        PETSc.Sys.Print(f"pfault: continuing {restart_dir} after step {step} (t = {format_time(t).strip()})")
        return records, index, step - index     # the checkpoint's records end at its step

    # ------------------------------------------------------------------------------------------
    def write_summary(self, summary: dict, total: float) -> None:
        """The final summary.json, then the figures and the GIS layers. Rank 0 only, under ``run_on_root``
        (pfault.cli): the other ranks wait for its verdict, so that none ends (with a non-zero exit code that makes
        mpirun kill the others) while files are written, and a failure to write ends them all."""
        self.wall["total"] = total
        self.wall["assembly"] = self.model.equations.assembly_wall
        summary["wall_s"] = dict(self.wall)
        if self.comm.rank == 0:
            run_dir = self.output.finish(summary)
            if run_dir is not None and not summary["interrupted"]:
                self.write_figures(run_dir)
            if self.gis and run_dir is not None:
                t0 = time.perf_counter()
                written = write_gis(run_dir)
                PETSc.Sys.Print(f"pfault: {len(written)} GIS files in gis/ in {time.perf_counter() - t0:.1f} s")

    def write_figures(self, run_dir: str) -> None:
        """Rank 0: the figures of the finished run as -pfault_figures asks: ``apart``, drawn by a process of their
        own that this run starts and does not wait for (pfault.post.figures_apart); ``true``, drawn here;
        ``false``, none."""
        figures = self.model.scene.figures
        if figures == "apart":
            pid = figures_apart.start(run_dir)
            PETSc.Sys.Print(f"pfault: figures drawn apart by process {pid} into {run_dir} (python -m "
                            f"pfault.post.figures {run_dir} draws them again)")
        elif figures == "true":
            t0 = time.perf_counter()
            paths = write_run_figures(run_dir)
            PETSc.Sys.Print(f"pfault: {len(paths)} figures in {time.perf_counter() - t0:.1f} s")

    def record_failure(self, line: str, code: int) -> None:
        """Rank 0, after every rank failed together (RunOutput.record_failure)."""
        self.output.record_failure(line, code)

    def last_words(self, line: str, code: int) -> None:
        """This rank failed alone and aborts the MPI job next (RunOutput.last_words)."""
        self.output.last_words(line, code)

    def destroy(self) -> None:
        """Collective: every rank destroys the run at once."""
        self.output.destroy()
        self.solver.destroy()
        self.state.destroy()
        self.model.destroy()


__all__ = ["Simulation", "Observer"]
