"""The observers of a run's steps (pfault.run): the progress line, the fields (volume, faults, land surface and
hazard map), the checkpoint and the summary. ``RunOutput`` is the run's directory they write into: staged, then
put in place after the first completed step, so that a run that fails before it leaves nothing behind."""

from __future__ import annotations

import errno
import json
import shutil
from typing import Any

import numpy as np
from petsc4py import PETSc

from ..effects import logged
from ..errors import EXIT_NOT_CONVERGED, InputError, OutputError, run_on_root
from ..mesh.fault import output_mesh
from ..run import per_side
from ..units import format_time
from . import checkpoint, parallel
from .output import RunWriter, record_failure
from .steps import LocalStep, StepOutput
from .summary import RunSummary


def progress_line(step: int, rec: dict, candidates: tuple = ()) -> str:
    """One line per step: time, Newton and Krylov iterations, factorisations, wall time, the faces' states (and
    each fault's, when there are several), the largest subsidence, the largest opening of an open face and slip
    of a face that has slid (pfault.run.fault_figures), the broken faces of each fault of ``candidates`` (those with a
    tensile strength) and the step's breaking passes, and why a step failed."""
    extra = ""
    if "stick" in rec:
        extra += f"  stick/slip/open {rec['stick']}/{rec['slip']}/{rec['open']}"
        if len(rec.get("faults", ())) > 1:
            extra += " (" + ", ".join(f"{name} {f['faces_stuck']}/{f['faces_slipping']}/{f['faces_open']}"
                                      for name, f in rec["faults"].items()) + ")"
    if candidates and "faults" in rec:
        extra += "  broken " + ", ".join(f"{name} {rec['faults'][name]['faces_broken']}" for name in candidates)
        if rec.get("breaking_passes"):
            n = rec["breaking_passes"]
            extra += f" (+{rec['faces_broken_step']} in {n} round{'s' if n > 1 else ''})"
    if "cells_virgin" in rec:
        extra += f"  virgin/elastic cells {rec['cells_virgin']}/{rec['cells_elastic']}"
    if "max_subsidence_m" in rec:
        extra += f"  subsidence {rec['max_subsidence_m']:.4g} m"
        if "subsidence_inelastic_at_max_m" in rec:
            extra += f" (inelastic {rec['subsidence_inelastic_at_max_m']:.4g} m)"
    if "max_fault_opening_m" in rec:
        extra += f"  opening {rec['max_fault_opening_m']:.3g} m  slip {rec['max_fault_slip_m']:.3g} m"
    if rec.get("substeps", 1) > 1:
        extra += f"  ({rec['substeps']} sub-steps)"
    if not rec["converged"]:
        why = f"reason {rec['reason']}"
        if rec.get("null_pivots"):
            why += (f"; singular Jacobian: {rec['null_pivots']} null pivots, part of the body held by nothing "
                    "but open fault faces")
        extra += f"  NOT CONVERGED ({why})"
    return (f"step {step:4d} t = {format_time(rec['time_s'])}  newton {rec['newton_its']:2d}  "
            f"ksp {rec['ksp_its']:4d}" + (f"  LU {rec['factorizations']:2d}" if "factorizations" in rec else "")
            + f"  wall {rec['wall_s']:7.2f} s{extra}")


class Observer:
    """Does nothing; observers override what they observe."""

    def step_started(self, step: int, t: float) -> None:
        pass

    def step_done(self, result: Any) -> None:
        pass


class ProgressLine(Observer):
    """The progress line of each step; ``candidates``: the names of the faults with a tensile strength."""

    def __init__(self, candidates: tuple = ()) -> None:
        self.candidates = tuple(candidates)

    def step_done(self, result: Any) -> None:
        PETSc.Sys.Print(progress_line(result.step, result.record.as_json(), self.candidates))


class RunOutput:
    """The run's output directory and its writers (pfault.io.output.RunWriter on rank 0, pfault.io.steps.StepOutput
    and pfault.io.checkpoint.Writer on every rank). ``surface``: the land surface (pfault.surface.LandSurface).
    Opened after the first solve (``open``); every method is collective unless it says otherwise."""

    def __init__(self, model: Any, state: Any, argv: list, surface: Any, restart_dir: str | None = None,
                 restart_step: int | None = None, metadata: dict | None = None) -> None:
        self.model, self.state, self.argv, self.surface = model, state, list(argv), surface
        # {name: JSON value} written as NAME.json beside options.txt and into every checkpoint (the data files read)
        self.metadata = dict(metadata or {})
        self.comm = model.comm
        self.restart_dir, self.restart_step = restart_dir, restart_step
        self.writer: Any = None             # rank 0, once open (a RunWriter)
        self.staging: str | None = None     # where the output goes (every rank, once it is opened)
        self.run_path: str | None = None
        self.committed = False              # the run's directory is in place (RunWriter.commit)
        self.fields: Any = None             # StepOutput, once open
        self.checkpoint: Any = None         # checkpoint.Writer, once open
        self.initial: tuple | None = None   # the initial state's output step (values, land surface's step)

    @property
    def is_open(self) -> bool:
        return self.fields is not None

    def capture_initial(self, margins: Any = None) -> None:
        """The output step of the initial state, taken before the first step is solved (its loads, the faces'
        pore pressure at time 0; ``margins``: its margins to failure, pfault.margins.MarginStep or None) and
        written when the output opens."""
        m, state = self.model, self.state
        zeros = np.zeros(m.dofmap.n_local)
        eq = m.equations
        rest = tuple(term.at_rest(load) for term, load in zip(eq.terms, eq.loads.term_loads))
        x_ref = eq.local_array(state.u_ref)
        values = self.step_values(zeros, x_ref, np.zeros(len(m.mesh.cells)), rest, margins)
        self.initial = (values, self.surface.measure(per_side(m, zeros), (x_ref, rest, state.histories))[1])

    def open(self) -> None:
        """Stage the output directory and write the initial state, or on a restart the output steps of the run
        it continues. Nothing is written before this, and the output directory is replaced only after the first
        completed step (RunWriter.commit)."""
        self.writer = run_on_root(self.comm, self._create_writer)
        # where the run writes, known to every rank: one that fails alone says there how the run ended
        w = self.writer
        self.staging, self.run_path = self.comm.tompi4py().bcast((w.dir, w.path) if self.comm.rank == 0 else None)
        m = self.model
        use_parallel = parallel.available(self.comm)
        sides = self.comm.tompi4py().bcast(m.split.vert_sides if self.comm.rank == 0 and m.split is not None
                                           else None)
        self.fields = StepOutput(self.comm, m.mesh, self.writer, sides, m.dofmap.max_sides, faces=m.faces.face,
                                 fault_id=m.fault_id, parallel=use_parallel)
        self.checkpoint = checkpoint.Writer(self.comm, m.mesh, faces=m.faces.face, n_faces=len(m.fault_id),
                                            parallel_io=use_parallel,
                                            texts={k: json.dumps(v).encode() for k, v in self.metadata.items()})
        if not self.restart_dir and self.initial is not None:
            self.fields.write(0, 0.0, *self.initial)

    def create_writer(self, output_dir: str) -> Any:
        """A RunWriter into ``output_dir`` (rank 0)."""
        m = self.model
        points, tets = output_mesh(m.serial.points, m.serial.tets, m.split)
        surface = self.surface.surface
        try:
            writer = RunWriter(output_dir, points, tets, m.serial.cell_material, m.scene.material_names,
                               fault_mesh=None if m.split is None else (m.serial.points, m.split.faces,
                                                                        m.split.fault_id),
                               surface_mesh=None if surface is None else (surface.points, surface.triangles))
            writer.write_metadata(dict(PETSc.Options().getAll()), self.argv, self.metadata)
            if self.restart_dir:
                writer.continue_from(self.restart_dir, int(self.restart_step or 0))
        except ValueError as exc:       # the series of the run it continues are of another mesh
            raise InputError(f"-pfault_restart {self.restart_dir}: {exc}") from None
        except OSError as exc:
            if exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
                raise                   # a full disk: pfault.errors.as_pfault_error words it
            raise OutputError(f"-pfault_output_dir {output_dir}: cannot write there ({exc})") from None
        return writer

    def _create_writer(self) -> Any:
        return self.create_writer(self.model.settings.output_dir)

    def step_values(self, u_rel: np.ndarray, u_total: np.ndarray, dp: np.ndarray, loads: tuple,
                    margins: Any = None) -> LocalStep:
        """This rank's values of one output step (pfault.io.steps.LocalStep): displacements relative to the initial
        state ``u_rel``, the total state ``u_total``, the pore-pressure change per cell ``dp``, the terms'
        loads ``loads`` (one per term) and the margins to failure (pfault.margins.MarginStep, or None)."""
        m, state = self.model, self.state
        eq = m.equations
        sig = eq.cell_total_stress(u_total, dp, state.sigma0, state.histories, loads).reshape(-1, 9)
        cells: dict = {"pore_pressure_change": dp, "stress": sig}
        faces: dict = {}
        parts = [term.fields(u_total, u_rel, load, h) for term, load, h in zip(eq.terms, loads, state.histories)]
        for fields in parts + ([margins.fields()] if margins is not None else []):
            for series, values in fields.items():
                (faces if series == "fault" else cells).update(values)
        return LocalStep(per_side(m, u_rel), m.source.vertex_head(), cells, faces)

    def write_step(self, result: Any, fields: Any = None) -> None:
        """Write the output step of a step's result (fields, faults, land surface) with the run's StepOutput, or
        with ``fields``."""
        eq = self.model.equations
        values = self.step_values(result.u_rel, eq.local_array(self.state.u), eq.loads.cell_dp(result.t),
                                  eq.loads.term_loads, result.record.margins)
        (fields or self.fields).write(result.step, result.t, values, result.surface)

    def write_summary(self, summary: dict) -> None:
        """The summary so far, and the first time the run's directory put in place (every rank)."""
        def write():
            self.writer.write_summary(summary)
            self.writer.commit()
        run_on_root(self.comm, write)      # a failure to write ends every rank
        self.committed = True              # the run's directory is in place (RunWriter.commit)

    def close(self) -> None:
        if self.fields is not None:
            self.fields.close()

    def finish(self, summary: dict) -> str | None:
        """Rank 0: the final summary.json; returns the run's directory (None when nothing was written)."""
        if self.writer is None:
            return None
        self.writer.write_summary(summary)
        self.writer.commit()
        self.writer.close()
        return self.writer.dir

    def record_failure(self, line: str, code: int) -> None:
        """Rank 0, after every rank failed together: summary.json of a run in place says how it ended (best
        effort: the failure may be the full disk itself)."""
        if self.writer is None:
            return
        try:
            self.writer.write_failure(line, code, not_converged=code == EXIT_NOT_CONVERGED)
        except (OSError, ValueError):
            pass

    def last_words(self, line: str, code: int) -> None:
        """This rank failed alone and aborts the MPI job next (pfault.errors.RunGuard.settle); the other ranks
        wait in a collective call, write nothing and are stopped with the job. Whichever rank this is, it
        says how the run ended in the summary.json of a run directory in place (that of the last completed
        step: every rank knows it is in place once that step is done), or removes the staging directory of a
        run that has not completed a step. Best effort: the failure may be the full disk itself."""
        writer = self.writer
        if self.run_path is None:
            return                                  # nothing written yet
        committed = writer.committed if writer is not None else self.committed
        try:
            if committed:
                record_failure(self.run_path, line, code, not_converged=code == EXIT_NOT_CONVERGED)
            elif writer is None:
                shutil.rmtree(self.staging, ignore_errors=True)
        except (OSError, ValueError):
            pass
        if writer is not None:
            writer.abandon()                        # closes its files; a directory in place stays

    def destroy(self) -> None:
        if self.fields is not None:
            try:
                self.fields.close()       # collective: every rank destroys the run after a failure
            except Exception:  # noqa: BLE001  (best effort: the run has failed already)
                pass
        if self.comm.rank == 0 and self.writer is not None:
            self.writer.abandon()         # nothing happens to a run directory already in place


class FieldOutput(Observer):
    """The fields of every output step (volume, faults, land surface)."""

    def __init__(self, output: RunOutput) -> None:
        self.output = output

    def step_done(self, result: Any) -> None:
        if result.output:
            self.output.write_step(result)


class CheckpointObserver(Observer):
    """checkpoint.h5 after every converged step: the state and the step records so far."""

    def __init__(self, output: RunOutput, state: Any, records: list) -> None:
        self.output, self.state, self.records = output, state, records

    def step_done(self, result: Any) -> None:
        if result.record.converged:
            out = self.output
            with logged("pfaultCheckpoint"):
                out.checkpoint.write(out.run_path if out.committed else out.staging, out.model, self.state,
                                     result.step, result.t, self.records)


class SummaryObserver(Observer):
    """summary.json after every step (``running``: true until the run ends); the first completed step puts the
    run's directory in place."""

    def __init__(self, output: RunOutput, summary: RunSummary, records: list) -> None:
        self.output, self.summary, self.records = output, summary, records

    def step_done(self, result: Any) -> None:
        self.output.write_summary(self.summary.compose(self.records, result.record.converged, None,
                                                       running=True))
