"""Runs one scene: mesh, setup, time loop, output. Called by the command line and by tests."""

from __future__ import annotations

import sys
import time

import numpy as np
from petsc4py import PETSc

from . import fields, scene as scn
from .assembly.elastic import ElasticAssembler
from .errors import InputError, run_on_root
from .mesh import distributed
from .options import OptionReader, check_unused_petsc_options
from .solver.problem import ElasticProblem


class NotConverged(Exception):
    pass


def _print(*args):
    PETSc.Sys.Print(" ".join(str(a) for a in args))


class Simulation:
    def __init__(self, options_file="", argv=()):
        self.options_file = options_file
        self.argv = list(argv)
        self.comm = PETSc.COMM_WORLD
        self.reader = OptionReader(PETSc)
        self.wall = {"mesh": 0.0, "setup": 0.0, "solve": 0.0, "output": 0.0}
        self.summary = None

    # ------------------------------------------------------------------------------------------
    def setup(self):
        comm, reader = self.comm, self.reader
        t0 = time.perf_counter()
        stage = PETSc.Log.Stage("Mesh")
        stage.push()
        self.settings = s = scn.read_settings(reader, self.options_file)
        from .solver.setup import apply_solver_file
        self.solver_file = apply_solver_file(reader.get("pfault_solver"), self.options_file)
        build_serial = scn.generator_options(reader, s)
        serial = run_on_root(comm, build_serial)
        names = comm.tompi4py().bcast((serial.material_names, sorted(serial.surfaces)) if comm.rank == 0 else None)
        self.material_names, self.surface_names = names
        self.materials = scn.read_materials(reader, self.material_names)
        self.drawdown = scn.read_drawdown(reader, self.material_names, s.water_density, s.gravity)
        self.boundaries = scn.read_boundaries(reader, self.surface_names)
        reader.check_pfault_options()

        def arrays():
            return scn.boundary_arrays(serial, self.boundaries, s.ground_surface)
        arr = run_on_root(comm, arrays)
        mask, face_tag, ground = arr if arr is not None else (None, None, None)
        self.serial = serial
        self.mesh = distributed.build(comm, serial, cell_face_tag=face_tag, vert_constraint=mask, vert_ground=ground)
        stage.pop()
        self.wall["mesh"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        stage = PETSc.Log.Stage("Setup")
        stage.push()
        self.dofmap = fields.build(self.mesh)
        self.asm = ElasticAssembler(self.mesh, self.dofmap, self.materials)
        self.problem = ElasticProblem(self.mesh, self.dofmap, self.asm, self.boundaries, self.drawdown, s)
        self.snes = self.problem.create_snes()
        check_unused_petsc_options(PETSc, reader)
        stage.pop()
        self.wall["setup"] = time.perf_counter() - t0

    # ------------------------------------------------------------------------------------------
    def _solve(self, t):
        p = self.problem
        p.set_load(t)
        t0 = time.perf_counter()
        self.snes.solve(None, p.u)
        wall = time.perf_counter() - t0
        reason = self.snes.getConvergedReason()
        return {"time_s": float(t), "newton_its": int(self.snes.getIterationNumber()),
                "ksp_its": int(self.snes.getLinearSolveIterations()), "wall_s": wall,
                "converged": bool(reason > 0), "reason": int(reason)}

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

    def _output(self, step, t, u_rel_local):
        p = self.problem
        pts = distributed.gather_vertex_values(self.mesh, u_rel_local[self.dofmap.vertex_dofs(0)])
        u_total = p.local_array(p.u)
        sig = p.cell_total_stress(u_total, t).reshape(-1, 9)
        dp = p.cell_dp(t) if p.drawdown.active else np.zeros(len(sig))
        cells = distributed.gather_cell_values(self.mesh, np.column_stack([dp, sig]))
        if self.comm.rank == 0:
            self.writer.write_step(t, {"displacement": pts},
                                   {"pore_pressure_change": cells[:, 0], "stress": cells[:, 1:10]})

    def run(self):
        s = self.settings
        p = self.problem
        solve_stage = PETSc.Log.Stage("Solve")
        out_stage = PETSc.Log.Stage("Output")
        steps = []
        times = np.linspace(0.0, s.time_end, s.time_steps + 1)
        if s.geostatic:
            solve_stage.push()
            t0 = time.perf_counter()
            p.geostatic_prestress(self.snes)
            rec = self._solve(0.0)
            rec["initial"] = True
            rec["wall_s"] = time.perf_counter() - t0
            p.u.copy(p.u_ref)
            solve_stage.pop()
            self.wall["solve"] += rec["wall_s"]
            steps.append(rec)
            self._progress(0, rec)
            if not rec["converged"]:
                return self._finish(steps, converged=False)
        t0 = time.perf_counter()
        out_stage.push()
        if self.comm.rank == 0:
            from .io.output import RunWriter
            self.writer = RunWriter(s.output_dir, self.serial.points, self.serial.tets, self.serial.cell_material,
                                    self.material_names)
            self.writer.write_metadata(dict(PETSc.Options().getAll()), self.argv)
        self._output(0, 0.0, np.zeros(self.dofmap.n_local))
        out_stage.pop()
        self.wall["output"] += time.perf_counter() - t0
        converged = True
        for step in range(1, s.time_steps + 1):
            t = times[step]
            solve_stage.push()
            rec = self._solve(t)
            solve_stage.pop()
            self.wall["solve"] += rec["wall_s"]
            sub, hor, u_rel = self._surface_figures()
            rec["max_subsidence_m"], rec["max_horizontal_displacement_m"] = sub, hor
            steps.append(rec)
            self._progress(step, rec)
            t0 = time.perf_counter()
            out_stage.push()
            if step % s.output_every == 0 or step == s.time_steps or not rec["converged"]:
                self._output(step, t, u_rel)
            out_stage.pop()
            self.wall["output"] += time.perf_counter() - t0
            if not rec["converged"]:
                converged = False
                break
        return self._finish(steps, converged)

    def _progress(self, step, rec):
        extra = ""
        if "max_subsidence_m" in rec:
            extra = f" subsidence {rec['max_subsidence_m']:.4g} m"
        _print(f"step {step:4d} t = {rec['time_s'] / (365.25 * 86400):9.4g} yr  newton {rec['newton_its']:2d}  "
               f"ksp {rec['ksp_its']:4d}  wall {rec['wall_s']:7.2f} s{extra}"
               + ("" if rec["converged"] else f"  NOT CONVERGED (reason {rec['reason']})"))

    def _finish(self, steps, converged):
        last = [r for r in steps if "max_subsidence_m" in r]
        self.summary = {
            "scene": self.settings.scene,
            "ranks": self.comm.size,
            "mesh": {"nodes": int(self.mesh.n_global_vertices), "cells": int(self.mesh.n_global_cells),
                     "fault_faces": 0},
            "fields": list(self.dofmap.fields),
            "dofs": int(self.problem.u.getSize()),
            "steps": steps,
            "max_subsidence_m": max([r["max_subsidence_m"] for r in last], default=0.0),
            "max_horizontal_displacement_m": max([r["max_horizontal_displacement_m"] for r in last], default=0.0),
            "final_subsidence_m": last[-1]["max_subsidence_m"] if last else 0.0,
            "converged": bool(converged),
        }
        return self.summary

    def write_summary(self, total):
        self.wall["total"] = total
        self.wall["assembly"] = self.problem.assembly_wall
        self.summary["wall_s"] = dict(self.wall)
        if self.comm.rank == 0 and hasattr(self, "writer"):
            self.writer.close()
            self.writer.write_summary(self.summary)

    def destroy(self):
        if hasattr(self, "snes"):
            self.snes.destroy()
        if hasattr(self, "problem"):
            self.problem.destroy()
        if hasattr(self, "mesh"):
            if self.mesh.migration is not None:
                self.mesh.migration.destroy()
            self.mesh.dm.destroy()
