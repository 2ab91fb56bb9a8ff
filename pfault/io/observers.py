"""The observers of a run's steps (pfault.run): the progress line, the fields (volume, faults, land surface and
hazard map), the checkpoint and the summary. ``RunOutput`` is the run's directory they write into: staged, then
put in place after the first completed step, so that a run that fails before it leaves nothing behind."""

from __future__ import annotations

import errno
import json
import shutil
from contextlib import nullcontext
from typing import Any

import numpy as np
from petsc4py import PETSc

from ..effects import logged
from ..errors import EXIT_NOT_CONVERGED, InputError, OutputError, run_on_root
from ..mesh.fault import copy_index
from .summary import RunSummary


def format_time(t: float) -> str:
    year = 365.25 * 86400.0
    if t >= 0.01 * year:
        return f"{t / year:8.4g} yr"
    if t >= 86400.0:
        return f"{t / 86400.0:8.4g} d"
    return f"{t:8.4g} s"


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
            extra += f" (+{rec['faces_broken_step']} in {n} pass{'es' if n > 1 else ''})"
    if "max_subsidence_m" in rec:
        extra += f"  subsidence {rec['max_subsidence_m']:.4g} m"
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
        PETSc.Sys.Print(progress_line(result.step, result.record, self.candidates))


class RunOutput:
    """The run's output directory and its writers (pfault.io.output.RunWriter on rank 0, pfault.io.steps.StepOutput
    and pfault.io.checkpoint.Writer on every rank). Opened after the first solve (``open``); every method is
    collective unless it says otherwise."""

    def __init__(self, model: Any, state: Any, argv: list, restart_dir: str | None = None,
                 restart_step: int | None = None, metadata: dict | None = None) -> None:
        self.model, self.state, self.argv = model, state, list(argv)
        # {name: JSON value} written as NAME.json beside options.txt and into every checkpoint (the data files read)
        self.metadata = dict(metadata or {})
        self.comm = model.comm
        self.restart_dir, self.restart_step = restart_dir, restart_step
        self.writer: Any = None             # rank 0, once open (a RunWriter)
        self.staging: str | None = None     # where the output goes (every rank, once it is opened)
        self.run_path: str | None = None
        self.committed = False              # the run's directory is in place
        self.fields: Any = None             # StepOutput, once open
        self.checkpoint: Any = None         # checkpoint.Writer, once open
        self.surface: Any = None            # the land surface (rank 0), once the writer is made

    @property
    def is_open(self) -> bool:
        return self.fields is not None

    def open(self) -> None:
        """Stage the output directory and write the initial state, or on a restart the output steps of the run
        it continues. Nothing is written before this, and the output directory is replaced only after the first
        completed step (RunWriter.commit)."""
        from . import checkpoint, parallel as par
        self.writer = run_on_root(self.comm, self._create_writer)
        # where the run writes, known to every rank: one that fails alone says there how the run ended
        w = self.writer
        self.staging, self.run_path = self.comm.tompi4py().bcast((w.dir, w.path) if self.comm.rank == 0 else None)
        m = self.model
        parallel = par.available(self.comm)
        self.fields = self.step_output(self.writer, parallel)
        faces = None if m.faults is None else m.faults.faces.face
        self.checkpoint = checkpoint.Writer(self.comm, m.mesh, faces=faces,
                                            n_faces=0 if m.faults is None else len(m.fault_id),
                                            parallel_io=parallel,
                                            texts={k: json.dumps(v).encode() for k, v in self.metadata.items()})
        if not self.restart_dir:
            self.write_fields(0, 0.0, np.zeros(m.dofmap.n_local), initial=True)

    def step_output(self, writer: Any, parallel: bool) -> Any:
        """A StepOutput writing through ``writer`` (rank 0); ``parallel``: the volume and fault fields written
        by every rank."""
        from .steps import StepOutput
        m = self.model
        mpi = self.comm.tompi4py()
        sides = mpi.bcast(m.split.vert_sides if self.comm.rank == 0 and m.split is not None else None)
        return StepOutput(self.comm, m.mesh, writer, sides, m.dofmap.max_sides,
                          faces=None if m.faults is None else m.faults.faces.face,
                          fault_id=None if m.faults is None else m.fault_id,
                          surface=self.surface if self.comm.rank == 0 else None, parallel=parallel)

    def output_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """Output mesh on rank 0: a split fault vertex appears once per piece of its star (the copies after the
        serial vertices, pfault.mesh.fault.vertex_copies); each cell uses the copies of its pieces."""
        serial, split = self.model.serial, self.model.split
        pts, tets = serial.points, serial.tets
        if split is None:
            return pts, tets
        vertex, _ = split.copies
        piece = split.cell_side
        copy = len(pts) + copy_index(split.vert_sides, tets, np.maximum(piece, 1))
        return np.concatenate([pts, pts[vertex]]), np.where(piece > 0, copy, tets)

    def create_writer(self, output_dir: str) -> Any:
        """A RunWriter into ``output_dir`` (rank 0)."""
        from . import hazard
        from .output import RunWriter
        m = self.model
        points, tets = self.output_mesh()
        self.surface = hazard.land_surface(points, tets, m.serial, m.split, m.settings.ground_surface,
                                           m.settings.hazard_strain_threshold)
        try:
            writer = RunWriter(output_dir, points, tets, m.serial.cell_material, m.scene.material_names,
                               fault_mesh=None if m.split is None else (m.serial.points, m.split.faces,
                                                                        m.split.fault_id),
                               surface_mesh=None if self.surface is None else (self.surface.points,
                                                                               self.surface.triangles))
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

    def step_values(self, t: float, u_rel: np.ndarray, initial: bool = False) -> Any:
        """This rank's values of one output step (pfault.io.steps.LocalStep)."""
        from .steps import LocalStep
        m, state = self.model, self.state
        eq, dofmap = m.equations, m.dofmap
        both = np.concatenate([u_rel[dofmap.vertex_dofs(side)] for side in range(dofmap.max_sides)], axis=1)
        u_total = eq.local_array(state.u_ref if initial else state.u)
        dp = eq.loads.cell_dp(t) if not initial else np.zeros(len(m.mesh.cells))
        faults = None
        # the initial state is written after the first step is solved: its face bubbles (in the stress of the cells
        # beside a fault and in the faces' jumps) without that step's loads; no face has slid yet
        with m.faults.bubbles.unloaded() if initial and m.faults is not None else nullcontext():
            sig = eq.cell_total_stress(u_total, dp, state.sigma0).reshape(-1, 9)
            if m.faults is not None:
                slid = np.zeros_like(state.fault_slid) if initial else state.fault_slid
                broken = (m.faults.strength.initially_broken(), np.full(len(slid), np.nan)) if initial else \
                    (state.fault_broken, state.fault_break_time)
                faults = _fault_fields(m.faults, u_total, u_rel, slid, broken)
        head = m.source.vertex_head()
        return LocalStep(both, head, {"pore_pressure_change": dp, "stress": sig}, faults)

    def write_fields(self, step: int, t: float, u_rel: np.ndarray, initial: bool = False) -> dict | None:
        """Write one output step (fields, fault, land surface); returns the land surface's hazard maxima (every
        rank), None without a land surface."""
        return self.fields.write(step, t, self.step_values(t, u_rel, initial))

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

    def finish(self, summary: dict, figures: bool) -> None:
        """Rank 0: the final summary.json, then the figures."""
        import time
        if self.writer is None:
            return
        self.writer.write_summary(summary)
        self.writer.commit()
        self.writer.close()
        if figures and not summary["interrupted"]:
            from .figures import write_run_figures
            t0 = time.perf_counter()
            paths = write_run_figures(self.writer.dir)
            PETSc.Sys.Print(f"pfault: {len(paths)} figures in {time.perf_counter() - t0:.1f} s")

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
        from .output import record_failure
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


def _fault_fields(fs: Any, u_total: np.ndarray, u_rel: np.ndarray, slid: np.ndarray,
                  broken: tuple[np.ndarray, np.ndarray]) -> dict:
    """Per fault face this rank owns: tractions from the total state, jumps relative to the initial state (every
    face's, as computed), its state (stick 0, slip 1, open 2) and whether it has slid (slipping or open at the
    end of a completed step, now or before: its slip is in the reported maxima), whether it is broken and when it
    broke (``broken``: flags and times, s, NaN while intact and on a pre-existing fault)."""
    t_loc, _, t_glob, _, state = fs.face_fields(u_total)
    g, gl = fs.relative_jumps(u_rel)
    return {"traction_normal": t_loc[:, 0], "traction_shear": t_glob - t_loc[:, :1] * fs.faces.normal,
            "opening": gl[:, 0], "slip": g - gl[:, :1] * fs.faces.normal,
            "slip_magnitude": np.linalg.norm(gl[:, 1:], axis=1), "state": np.asarray(state, dtype=np.int64),
            "slid": np.asarray(slid, dtype=np.int64), "broken": np.asarray(broken[0], dtype=np.int64),
            "break_time": np.asarray(broken[1], dtype=float),
            "traction_normal_effective": fs.effective(t_loc)[:, 0]}


class FieldOutput(Observer):
    """The fields of every output step (volume, faults, land surface); the land surface's hazard maxima go to
    the step's derived figures."""

    def __init__(self, output: RunOutput) -> None:
        self.output = output

    def step_done(self, result: Any) -> None:
        if result.output:
            hz = self.output.write_fields(result.step, result.t, result.u_rel)
            if hz is not None:
                result.derived.update(hz)


class CheckpointObserver(Observer):
    """checkpoint.h5 after every converged step: the state and the step records so far."""

    def __init__(self, output: RunOutput, state: Any, records: list) -> None:
        self.output, self.state, self.records = output, state, records

    def step_done(self, result: Any) -> None:
        if result.record["converged"]:
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
        self.output.write_summary(self.summary.compose(self.records, result.record["converged"], None,
                                                       running=True))
