"""Runs one scene: mesh, setup, time loop, output. Called by the command line and by tests."""

from __future__ import annotations

import dataclasses
import errno
import os
import sys
import time

import numpy as np
from petsc4py import PETSc

from . import checks, fields, scene as scn
from .assembly.elastic import ElasticAssembler
from .effects import EffectCosts, logged
from .effects import decide as decide_effects
from .errors import InputError, OutputError, run_on_root
from .interrupt import StopRequest
from .mesh import distributed
from .options import OptionReader, check_unused_petsc_options
from .solver.problem import Problem, constrained_local


class NotConverged(Exception):
    pass


def _check_iterative_faults(fault_settings):
    """The Schur fieldsplit eliminates each face's multipliers through the 3x3 blocks the traction-jump
    stabilisation gives a stuck face (every rank reads the same settings, so every rank raises)."""
    if PETSc.Options().getString("pc_type", "") != "fieldsplit":
        return
    for f in fault_settings:
        if f.method == "lagrange" and not f.stabilization:
            raise InputError(f"-pfault_fault_{f.name}_stabilization false: the fieldsplit solver eliminates the "
                             "multipliers through the stabilisation's face blocks; keep the stabilisation or "
                             "use -pfault_solver mumps")


def _fmt_time(t):
    year = 365.25 * 86400.0
    if t >= 0.01 * year:
        return f"{t / year:8.4g} yr"
    if t >= 86400.0:
        return f"{t / 86400.0:8.4g} d"
    return f"{t:8.4g} s"


def _print(*args):
    PETSc.Sys.Print(" ".join(str(a) for a in args))


def _check_restart_dir(path):
    if not os.path.isdir(path):
        raise InputError(f"-pfault_restart {path}: no such run directory")


class Simulation:
    def __init__(self, options_file="", argv=()):
        self.options_file = options_file
        self.argv = list(argv)
        self.comm = PETSc.COMM_WORLD
        self.reader = OptionReader(PETSc)
        self.wall = {"mesh": 0.0, "setup": 0.0, "solve": 0.0, "output": 0.0}
        self.summary = None
        self.staging = self.run_path = None      # where the output goes (every rank, once it is opened)
        self.committed = False                   # the run's directory is in place

    # ------------------------------------------------------------------------------------------
    def setup(self):
        comm, reader = self.comm, self.reader
        self.costs = EffectCosts(comm)
        t0 = time.perf_counter()
        stage = PETSc.Log.Stage("Mesh")
        stage.push()
        self.settings = s = scn.read_settings(reader, self.options_file)
        self.restart_dir = reader.get("pfault_restart")
        self.figures = reader.get("pfault_figures")
        if self.restart_dir:
            run_on_root(comm, _check_restart_dir, self.restart_dir)
            if not reader.has("pfault_output_dir"):
                # a restarted run continues in the directory of the run it continues
                self.settings = s = dataclasses.replace(s, output_dir=self.restart_dir)
        run_on_root(comm, checks.probe_output_dir, s.output_dir)
        from .solver.setup import apply_solver_file
        self.solver_file = apply_solver_file(reader.get("pfault_solver"), self.options_file)
        build_serial = scn.generator_options(reader, s, index_bytes=np.dtype(PETSc.IntType).itemsize)
        serial = run_on_root(comm, build_serial)
        names = comm.tompi4py().bcast((serial.material_names, sorted(serial.surfaces)) if comm.rank == 0 else None)
        self.material_names, self.surface_names = names
        scn.check_ground_surface(reader, s, self.surface_names)
        self.materials = scn.read_materials(reader, self.material_names)
        self.drawdown = scn.read_drawdown(reader, self.material_names, s.water_density, s.gravity)
        self.flow_settings = None
        if reader.get("pfault_flow"):
            from .solver.flow import read_flow_settings
            if self.drawdown.active:
                raise InputError("-pfault_flow: the pore pressure comes from the flow model; remove the "
                                 "per-material head_drawdown/pressure_change tables")
            self.flow_settings = read_flow_settings(reader, self.material_names, self.materials, self.surface_names,
                                                    s.water_density, s.gravity)
        self.fault_settings = scn.read_faults(reader, self.surface_names)
        fault_names = [f.name for f in self.fault_settings]
        self.boundaries = scn.read_boundaries(reader, self.surface_names, exclude=fault_names)
        self.contact = scn.read_contact_options(reader) if fault_names else None
        reader.check_pfault_options()
        self.effects = decide_effects(s, self.materials, self.drawdown, self.flow_settings is not None,
                                      self.fault_settings, self.boundaries)
        _print("pfault:", self.effects.line())

        def arrays():
            out = scn.boundary_arrays(serial, self.boundaries, s.ground_surface)
            checks.check_held(serial.points, out[0], [b.name for b in self.boundaries])
            if self.flow_settings is not None:
                from .solver.flow import FIXED_HEAD_BIT, fixed_head_vertices
                out[0][:] |= FIXED_HEAD_BIT * fixed_head_vertices(serial, self.flow_settings.fixed_head_surfaces)
            split = topology = None
            if fault_names:
                from .faults.interface import fault_topology
                from .mesh.fault import split_faults
                split = split_faults(serial, fault_names)
                topology = fault_topology(serial, split, self.materials)
            written = 1 + s.time_steps // s.output_every + (s.time_steps % s.output_every > 0)
            checks.check_output_space(s.output_dir, checks.output_bytes(
                len(serial.points) + (len(split.split_vertices) if split else 0), len(serial.tets),
                len(split.faces) if split else 0, written, flow=self.flow_settings is not None))
            return out, split, topology
        arr = run_on_root(comm, arrays)
        (mask, face_tag, ground), split, topology = arr if arr is not None else ((None, None, None), None, None)
        self.serial = serial
        self.split = split
        self.mesh = distributed.build(comm, serial, cell_face_tag=face_tag, vert_constraint=mask, vert_ground=ground,
                                      split=split)
        if fault_names:
            mpi = comm.tompi4py()
            self.fault_topology = mpi.bcast(topology if comm.rank == 0 else None)
            self.fault_id = self.fault_topology.fault_id
        stage.pop()
        self.wall["mesh"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        stage = PETSc.Log.Stage("Setup")
        stage.push()
        if self.fault_settings:
            lagrange = any(f.method == "lagrange" for f in self.fault_settings)
            lm_faces = None
            if lagrange:
                fid = self.mesh.cell_fault_face
                is_lag = np.array([f.method == "lagrange" for f in self.fault_settings])
                lm_faces = ((fid >= 0) & is_lag[np.where(fid >= 0, self.fault_id[np.maximum(fid, 0)], 0)]).sum(axis=1)
            self.dofmap = fields.build(self.mesh, vert_sides=self.mesh.vert_sides, cell_side=self.mesh.cell_side,
                                       cell_multipliers=lm_faces)
        else:
            self.dofmap = fields.build(self.mesh)
        self.asm = ElasticAssembler(self.mesh, self.dofmap, self.materials)
        self.flow = None
        if self.flow_settings is not None:
            from .solver.flow import FIXED_HEAD_BIT, GroundwaterFlow
            fs, mat = self.flow_settings, self.mesh.cell_material
            self.flow = GroundwaterFlow(self.mesh, fs.conductivity[mat], fs.storage[mat], wells=fs.wells,
                                        fixed_head=(self.mesh.vert_data[:, 0] & FIXED_HEAD_BIT) != 0,
                                        substeps=fs.substeps, water_density=s.water_density, gravity=s.gravity)
            self.drawdown = self.flow
        faults = None
        if self.effects.faults:
            from .faults.interface import FaultInterface
            _check_iterative_faults(self.fault_settings)
            with logged("pfaultFaultSetup"):
                faults = FaultInterface(self.mesh, self.dofmap, self.fault_settings, self.fault_topology,
                                        self.materials, constrained_local(self.mesh, self.dofmap),
                                        self.mesh.dm.getLGMap(), self.contact)
        self.problem = Problem(self.mesh, self.dofmap, self.asm, self.boundaries, self.drawdown, s, faults,
                               self.contact)
        self.snes = self.problem.create_snes()
        stage.pop()
        self.wall["setup"] = time.perf_counter() - t0

    # ------------------------------------------------------------------------------------------
    def _solve(self, t, t_prev=0.0):
        rec = self.problem.solve_interval(self.snes, t_prev, t, self.settings.max_cuts)
        if self.flow is not None and self.flow.history:
            rec["flow_ksp_its"] = int(self.flow.history[-1].get("ksp_its", 0))
            from mpi4py import MPI
            h = self.flow.vertex_head()
            rec["max_drawdown_m"] = self.comm.tompi4py().allreduce(float(np.max(-h, initial=0.0)), op=MPI.MAX)
        return rec

    def _surface_figures(self):
        """Maximum subsidence and horizontal displacement on the ground surface (relative to the initial state)."""
        p = self.problem
        du = p.u.duplicate()
        p.u.copy(du)
        du.axpy(-1.0, p.u_ref)
        loc = p.local_array(du)
        du.destroy()
        ground = (self.mesh.vert_data[:, 1] == 1) & self.mesh.vert_owned
        sub, hor = 0.0, 0.0
        for side in (0, 1):
            sel = ground & (self.dofmap.vert_sides > side)
            u = loc[self.dofmap.vertex_dofs(side)[sel]]
            if len(u):
                sub = max(sub, float(np.max(-u[:, 2])))
                hor = max(hor, float(np.max(np.hypot(u[:, 0], u[:, 1]))))
        mpi = self.comm.tompi4py()
        from mpi4py import MPI
        return mpi.allreduce(sub, op=MPI.MAX), mpi.allreduce(hor, op=MPI.MAX), loc

    def _output_mesh(self):
        """Output mesh on rank 0: split fault vertices appear twice, plus-side cells use the copies."""
        pts, tets = self.serial.points, self.serial.tets
        if self.split is None:
            return pts, tets
        sv = self.split.split_vertices
        copy = np.full(len(pts), -1)
        copy[sv] = len(pts) + np.arange(len(sv))
        tets = np.where(self.split.cell_side == 1, copy[tets], tets)
        return np.concatenate([pts, pts[sv]]), tets

    def _output(self, step, t, u_rel_local, initial=False):
        """Write one output step (fields, fault, land surface); returns the hazard maxima of the land surface
        (every rank)."""
        from .io.steps import LocalStep
        p = self.problem
        both = np.concatenate([u_rel_local[self.dofmap.vertex_dofs(0)], u_rel_local[self.dofmap.vertex_dofs(1)]],
                              axis=1)
        u_total = p.local_array(p.u_ref if initial else p.u)
        dp = p.cell_dp(t) if (p.drawdown.active and not initial) else np.zeros(len(self.mesh.cells))
        sig = p.cell_total_stress(u_total, dp).reshape(-1, 9)
        faults = self._fault_fields(u_total, u_rel_local) if self.fault_settings else None
        head = None if self.flow is None else self.flow.vertex_head()
        return self.output.write(step, t, LocalStep(both, head, {"pore_pressure_change": dp, "stress": sig}, faults))

    def _open_output(self):
        """After the first solve (every solver option has been read by then): reject unused options, then
        stage the output directory and write the initial state, or on a restart the output steps of the run
        it continues. Nothing is written before this, and the output directory is replaced only after the
        first completed step (pfault.io.output.RunWriter.commit)."""
        if hasattr(self, "writer_ready"):
            return
        check_unused_petsc_options(PETSc, self.reader)
        self.writer_ready = True
        t0 = time.perf_counter()
        stage = PETSc.Log.Stage("Output")
        stage.push()
        self.writer = run_on_root(self.comm, self._create_writer)
        # where the run writes, known to every rank: one that fails alone says there how the run ended
        # (last_words)
        w = self.writer
        self.staging, self.run_path = self.comm.tompi4py().bcast((w.dir, w.path) if self.comm.rank == 0 else None)
        self.output = self._step_output(self.writer)
        self.checkpoint = self._checkpoint_writer(self.output.parallel)
        if not self.restart_dir:
            self._output(0, 0.0, np.zeros(self.dofmap.n_local), initial=True)
        stage.pop()
        self.wall["output"] += time.perf_counter() - t0

    def _step_output(self, writer, parallel=None):
        """The StepOutput of this run's writer (every rank); ``parallel``: whether the volume and fault fields
        are written by every rank (default: where h5py can, pfault.io.parallel.available)."""
        from .io import parallel as par
        from .io.steps import StepOutput
        if parallel is None:
            parallel = par.available(self.comm)
        mpi = self.comm.tompi4py()
        split = mpi.bcast(self.split.split_vertices if self.comm.rank == 0 and self.split is not None else None)
        faults = self.problem.faults if self.fault_settings else None
        return StepOutput(self.comm, self.mesh, writer, np.zeros(0, np.int64) if split is None else split,
                          faces=None if faults is None else faults.face,
                          fault_id=None if faults is None else self.fault_id,
                          surface=self.surface if self.comm.rank == 0 else None, parallel=parallel)

    def _checkpoint_writer(self, parallel):
        """The writer of checkpoint.h5 (every rank); ``parallel``: written by every rank, as the fields are."""
        from .io import checkpoint
        faults = self.problem.faults if self.fault_settings else None
        return checkpoint.Writer(self.comm, self.mesh, faces=None if faults is None else faults.face,
                                 n_faces=0 if faults is None else len(self.fault_id), parallel_io=parallel)

    def _create_writer(self):
        from .io import hazard
        from .io.output import RunWriter
        points, tets = self._output_mesh()
        self.surface = hazard.land_surface(points, tets, self.serial, self.split, self.settings.ground_surface)
        out = self.settings.output_dir
        try:
            writer = RunWriter(out, points, tets, self.serial.cell_material, self.material_names,
                               fault_mesh=None if self.split is None else (self.serial.points, self.split.faces,
                                                                           self.split.fault_id),
                               surface_mesh=None if self.surface is None else (self.surface.points,
                                                                               self.surface.triangles))
            writer.write_metadata(dict(PETSc.Options().getAll()), self.argv)
            if self.restart_dir:
                writer.continue_from(self.restart_dir, self.restart_step)
        except ValueError as exc:       # the series of the run it continues are of another mesh
            raise InputError(f"-pfault_restart {self.restart_dir}: {exc}") from None
        except OSError as exc:
            if exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
                raise                   # a full disk: pfault.errors.as_pfault_error words it
            raise OutputError(f"-pfault_output_dir {out}: cannot write there ({exc})") from None
        return writer

    def _fault_fields(self, u_total, u_rel):
        """Per fault face this rank owns: tractions from the total state, jumps relative to the initial state."""
        fs = self.problem.faults
        t_loc, _, t_glob, _, state = fs.face_fields(u_total)
        g, gl = fs.jumps(u_rel)
        return {"traction_normal": t_loc[:, 0], "traction_shear": t_glob - t_loc[:, :1] * fs.normal,
                "opening": gl[:, 0], "slip": g - gl[:, :1] * fs.normal,
                "slip_magnitude": np.linalg.norm(gl[:, 1:], axis=1), "state": np.asarray(state, dtype=np.int64),
                "traction_normal_effective": fs.effective(t_loc)[:, 0]}

    def _fault_figures(self, u_rel_local):
        fs = self.problem.faults
        g, gl = fs.jumps(u_rel_local)
        op = float(np.max(gl[:, 0], initial=0.0))
        sl = float(np.max(np.linalg.norm(gl[:, 1:], axis=1), initial=0.0))
        from mpi4py import MPI
        mpi = self.comm.tompi4py()
        return mpi.allreduce(op, op=MPI.MAX), mpi.allreduce(sl, op=MPI.MAX)

    def run(self):
        s = self.settings
        solve_stage = PETSc.Log.Stage("Solve")
        out_stage = PETSc.Log.Stage("Output")
        self.surface = None
        times = np.linspace(0.0, s.time_end, s.time_steps + 1)
        if self.restart_dir:
            steps, first, offset = self._restart(times)
        else:
            steps, first, offset = self._initial_state(solve_stage), 0, 0
        self.costs.mark_setup()
        converged, stop = True, None
        # after meshing: gmsh resets the SIGINT handler
        with StopRequest(self.comm) as request:
            for index in range(first + 1, s.time_steps + 1):
                step, t = index + offset, times[index]
                solve_stage.push()
                rec = self._solve(t, times[index - 1])
                solve_stage.pop()
                rec["step"] = step
                self._open_output()
                self.wall["solve"] += rec["wall_s"]
                sub, hor, u_rel = self._surface_figures()
                rec["max_subsidence_m"], rec["max_horizontal_displacement_m"] = sub, hor
                if self.fault_settings:
                    rec["max_fault_opening_m"], rec["max_fault_slip_m"] = self._fault_figures(u_rel)
                steps.append(rec)
                self._progress(step, rec)
                stop = request.agreed()
                t0 = time.perf_counter()
                out_stage.push()
                if (index % s.output_every == 0 or index == s.time_steps or not rec["converged"]
                        or stop is not None):
                    hz = self._output(step, t, u_rel)
                    if hz is not None:
                        rec.update(hz)
                self._step_done(steps, rec, step, t)
                out_stage.pop()
                self.wall["output"] += time.perf_counter() - t0
                if not rec["converged"]:
                    converged = False
                    break
                if stop is not None:
                    _print(f"pfault: stopped after step {step} ({stop})")
                    break
        return self._finish(steps, converged, stop)

    def _initial_state(self, solve_stage):
        """The geostatic initial equilibrium (step 0), when the scene asks for one; returns the step records."""
        p = self.problem
        if not self.settings.geostatic:
            return []
        solve_stage.push()
        t0 = time.perf_counter()
        with logged("pfaultGeostatic"):
            p.geostatic_prestress(self.snes)
        p.u.copy(p.u_ref)
        rec = {"time_s": 0.0, "newton_its": 0, "ksp_its": 0, "wall_s": time.perf_counter() - t0,
               "converged": True, "initial": True, "step": 0}
        if self.fault_settings:
            rec.update(p.faults.counts_by_state(p.local_array(p.u)))
        solve_stage.pop()
        self.wall["solve"] += rec["wall_s"]
        self._progress(0, rec)
        return [rec]

    def _restart(self, times):
        """State, step records and place on the time grid of the run in -pfault_restart: returns (records,
        grid index of the checkpoint's time, step number minus grid index)."""
        from .io import checkpoint
        attrs, records = checkpoint.load(self.comm, self.restart_dir, self)
        step, t = int(attrs["step"]), float(attrs["time_s"])
        index = int(np.argmin(np.abs(times - t)))
        if abs(times[index] - t) > 1e-9 * times[-1]:
            raise InputError(f"-pfault_restart {self.restart_dir}: its last completed step ends at t = {t:g} s, "
                             f"which is not a point of the time grid (-pfault_time_end {times[-1]:g} s in "
                             f"{len(times) - 1} steps); choose -pfault_time_end and -pfault_time_steps so that it is")
        if index == len(times) - 1:
            raise InputError(f"-pfault_restart {self.restart_dir}: the run is complete at t = {t:g} s; give a "
                             "later -pfault_time_end to continue it")
        self.restart_step = step
        _print(f"pfault: continuing {self.restart_dir} after step {step} (t = {_fmt_time(t).strip()})")
        return records, index, step - index     # the checkpoint's records end at its step

    def _step_done(self, steps, rec, step, t):
        """A step is complete: its checkpoint (when it converged) and the summary so far are written, and the
        first completed step puts the run's directory in place."""
        if rec["converged"]:
            with logged("pfaultCheckpoint"):
                self.checkpoint.write(self.run_path if self.committed else self.staging, self, step, t, steps)
        summary = self._summary(steps, rec["converged"], None, running=True)

        def write():
            self.writer.write_summary(summary)
            self.writer.commit()
        run_on_root(self.comm, write)      # a failure to write ends every rank
        self.committed = True              # the run's directory is in place (RunWriter.commit)

    def _progress(self, step, rec):
        extra = ""
        if "stick" in rec:
            extra += f"  stick/slip/open {rec['stick']}/{rec['slip']}/{rec['open']}"
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
                        "but open or unstabilised fault faces")
            extra += f"  NOT CONVERGED ({why})"
        _print(f"step {step:4d} t = {_fmt_time(rec['time_s'])}  newton {rec['newton_its']:2d}  "
               f"ksp {rec['ksp_its']:4d}" + (f"  LU {rec['factorizations']:2d}" if "factorizations" in rec else "")
               + f"  wall {rec['wall_s']:7.2f} s{extra}")

    def _summary(self, steps, converged, stop, running=False):
        last = [r for r in steps if "max_subsidence_m" in r]
        summary = {
            "scene": self.settings.scene,
            "ranks": self.comm.size,
            "mesh": {"nodes": int(self.mesh.n_global_vertices), "cells": int(self.mesh.n_global_cells),
                     "fault_faces": int(len(self.fault_id)) if self.fault_settings else 0},
            "fields": list(self.dofmap.fields),
            "dofs": int(self.problem.u.getSize()),
            "solver": self._solver_record(steps),
            "steps": steps,
            "max_subsidence_m": max([r["max_subsidence_m"] for r in last], default=0.0),
            "max_horizontal_displacement_m": max([r["max_horizontal_displacement_m"] for r in last], default=0.0),
            "final_subsidence_m": last[-1]["max_subsidence_m"] if last else 0.0,
            "max_fault_opening_m": max([r.get("max_fault_opening_m", 0.0) for r in last], default=0.0),
            "max_fault_slip_m": max([r.get("max_fault_slip_m", 0.0) for r in last], default=0.0),
            "memory_peak_mib": self._memory_peak_mib(),
            "converged": bool(converged),
            "effects": self.costs.record(self.effects, len([r for r in steps if not r.get("initial")])),
            # a run in progress, or one killed before it could say how it ended, reads running: true
            "running": bool(running),
            "interrupted": stop is not None,
            "completed_steps": [r["step"] for r in last if r["converged"]],
        }
        from .io.hazard import summary_maxima
        summary.update(summary_maxima(last))
        if stop is not None:
            summary["stop_signal"] = stop
        if self.restart_dir:
            summary["restart"] = {"from": self.restart_dir, "step": self.restart_step}
        return summary

    def _solver_record(self, steps):
        """The linear solver and its iterations: Krylov iterations per Newton iteration over the run (each
        step's own is in its record, ``ksp_per_newton``)."""
        ksp = self.snes.getKSP() if hasattr(self, "snes") else None
        newton = sum(r.get("newton_its", 0) for r in steps)
        krylov = sum(r.get("ksp_its", 0) for r in steps)
        return {"file": self.solver_file, "ksp_type": ksp.getType() if ksp else None,
                "pc_type": ksp.getPC().getType() if ksp else None, "newton_its": int(newton),
                "ksp_its": int(krylov), "ksp_per_newton": krylov / newton if newton else 0.0,
                "max_ksp_per_newton": max([r.get("ksp_per_newton", 0.0) for r in steps], default=0.0)}

    def _memory_peak_mib(self):
        """The largest resident set size of each rank's process so far, in MiB (a list in rank order; collective)."""
        import resource
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss      # KiB on Linux, bytes on macOS
        mib = peak / (1024.0 * 1024.0 if sys.platform == "darwin" else 1024.0)
        return [round(m, 1) for m in self.comm.tompi4py().allgather(mib)]

    def _finish(self, steps, converged, stop):
        if getattr(self, "output", None) is not None:
            self.output.close()
        self.summary = self._summary(steps, converged, stop)
        return self.summary

    def write_summary(self, total):
        """The final summary.json, then the figures. Rank 0 only, under ``run_on_root`` (pfault.cli): the other
        ranks wait for its verdict, so that none ends (with a non-zero exit code that makes mpirun kill the
        others) while files are written, and a failure to write ends them all."""
        self.wall["total"] = total
        self.wall["assembly"] = self.problem.assembly_wall
        self.summary["wall_s"] = dict(self.wall)
        if self.comm.rank == 0 and getattr(self, "writer", None) is not None:
            self.writer.write_summary(self.summary)
            self.writer.commit()
            self.writer.close()
            if self.figures and not self.summary["interrupted"]:
                from .io.figures import write_run_figures
                t0 = time.perf_counter()
                paths = write_run_figures(self.writer.dir)
                _print(f"pfault: {len(paths)} figures in {time.perf_counter() - t0:.1f} s")

    def record_failure(self, line, code):
        """Rank 0, after every rank failed together: summary.json of a run in place says how it ended (best
        effort: the failure may be the full disk itself)."""
        from .errors import EXIT_NOT_CONVERGED
        if getattr(self, "writer", None) is None:
            return
        try:
            self.writer.write_failure(line, code, not_converged=code == EXIT_NOT_CONVERGED)
        except (OSError, ValueError):
            pass

    def last_words(self, line, code):
        """This rank failed alone and aborts the MPI job next (pfault.errors.RunGuard.settle); the other ranks
        wait in a collective call, write nothing and are stopped with the job. Whichever rank this is, it
        says how the run ended in the summary.json of a run directory in place (that of the last completed
        step: every rank knows it is in place once that step is done), or removes the staging directory of a
        run that has not completed a step. Best effort: the failure may be the full disk itself."""
        import shutil
        from .errors import EXIT_NOT_CONVERGED
        from .io.output import record_failure
        writer = getattr(self, "writer", None)
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

    def destroy(self):
        if getattr(self, "output", None) is not None:
            try:
                self.output.close()       # collective: every rank destroys the simulation after a failure
            except Exception:  # noqa: BLE001  (best effort: the run has failed already)
                pass
        if self.comm.rank == 0 and getattr(self, "writer", None) is not None:
            self.writer.abandon()         # nothing happens to a run directory already in place
        if hasattr(self, "snes"):
            self.snes.destroy()
        if hasattr(self, "problem"):
            self.problem.destroy()
        if getattr(self, "flow", None) is not None:
            self.flow.destroy()
        if hasattr(self, "dofmap"):
            # destroyed here, on every rank at once: left to the garbage collector, which may free it on some
            # ranks only (a traceback holding the simulation on another), PETSc 3.18's PetscFinalize waits
            # for ever in its collective cleanup of such objects
            self.dofmap.section.destroy()
        if hasattr(self, "mesh"):
            if self.mesh.migration is not None:
                self.mesh.migration.destroy()
            self.mesh.dm.destroy()
