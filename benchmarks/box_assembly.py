#!/usr/bin/env python
"""Assembly and solve time on a ~1M-tetrahedron box (the reference for later work).

    mpirun -n 2 .venv/bin/python benchmarks/box_assembly.py [-pfault_box_cells 55,55,55] [-pfault_solver gamg]

Prints one line per phase and a JSON line with the figures. Uses the demo materials and drawdown.
"""
import json
import sys
import time

import petsc4py
from pfault.optionsfile import petsc_arguments  # noqa: E402


args = sys.argv[1:]
defaults = {"-pfault_box_cells": "55,55,55", "-pfault_solver": "gamg", "-pfault_time_steps": "1",
            "-pfault_geostatic": "false", "-pfault_output_dir": "runs/bench_box"}
for k, v in defaults.items():
    if k not in args:
        args += [k, v]
petsc4py.init([sys.argv[0], *petsc_arguments("config/demo.opts", [])] + args)
from petsc4py import PETSc  # noqa: E402

from pfault.simulation import Simulation  # noqa: E402

t0 = time.perf_counter()
sim = Simulation("config/demo.opts", sys.argv)
summary = sim.run()
sim.write_summary(summary, time.perf_counter() - t0)
fig = {"ranks": PETSc.COMM_WORLD.size, "cells": summary["mesh"]["cells"], "dofs": summary["dofs"],
       "mesh_s": sim.wall["mesh"], "setup_s": sim.wall["setup"], "assembly_s": sim.model.equations.assembly_wall,
       "solve_s": sim.wall["solve"], "ksp_its": sum(s["ksp_its"] for s in summary["steps"]),
       "total_s": sim.wall["total"], "converged": bool(summary["converged"])}
PETSc.Sys.Print(f"box benchmark: {fig['cells']} tets, {fig['dofs']} dofs on {fig['ranks']} ranks: "
                f"mesh {fig['mesh_s']:.2f} s, setup {fig['setup_s']:.2f} s (stiffness assembly "
                f"{fig['assembly_s']:.2f} s), solve {fig['solve_s']:.2f} s ({fig['ksp_its']} Krylov its), "
                f"total {fig['total_s']:.2f} s" + ("" if fig["converged"] else
                                                   "  NOT CONVERGED: the solve's figures are not comparable"))
PETSc.Sys.Print(json.dumps(fig))
sim.destroy()
