#!/usr/bin/env python
"""Time to write checkpoint.h5, by every rank (pfault.io.parallel) and gathered to rank 0, from one state.

    mpirun -n 2 .venv/bin/python benchmarks/checkpoint_write.py [SCENE.opts] [-pfault_... value ...]

Runs the scene (default: calibrated Queretaro at size factor 2, one step of a year), then writes the checkpoint
of its last step ``-repeat`` times (default 20) each way, alternating, into runs/bench_checkpoint/; every write
is timed between two barriers. Prints the median and the fastest write of each way, the file's size and a JSON
line with the figures. Both ways write the same file (tests/parallel/test_parallel_output.py).
"""
import json
import os
import sys
import time

import petsc4py

from pfault.optionsfile import petsc_arguments

args = sys.argv[1:]
scene = args.pop(0) if args and not args[0].startswith("-") else "config/queretaro_calibrated.opts"
repeat = 20
if "-repeat" in args:
    i = args.index("-repeat")
    repeat = int(args[i + 1])
    del args[i:i + 2]
defaults = {"-pfault_mesh_size_factor": "2", "-pfault_time_steps": "1", "-pfault_time_end": "1*year",
            "-pfault_output_dir": "runs/bench_checkpoint/run", "-pfault_figures": "false"}
for k, v in defaults.items():
    if k not in args and not (k == "-pfault_mesh_size_factor" and "queretaro" not in scene):
        args += [k, v]
petsc4py.init([sys.argv[0]] + petsc_arguments(scene, args))
from petsc4py import PETSc  # noqa: E402

import numpy as np  # noqa: E402

from pfault.io import checkpoint, parallel  # noqa: E402
from pfault.simulation import Simulation  # noqa: E402

comm = PETSc.COMM_WORLD
mpi = comm.tompi4py()
sim = Simulation(scene, sys.argv)
summary = sim.run()
step, t = summary["steps"][-1]["step"], summary["steps"][-1]["time_s"]
directory = os.path.join(os.path.dirname(sim.output.run_path), "checkpoints")
if mpi.rank == 0:
    os.makedirs(directory, exist_ok=True)
mpi.Barrier()
ways = {"gathered": False}
if parallel.available(comm):
    ways["parallel"] = True
writers = {name: checkpoint.Writer(comm, sim.model.mesh, faces=sim.model.faces.face, n_faces=sim.model.faces.total,
                                   parallel_io=p)
           for name, p in ways.items()}
times = {name: [] for name in ways}
for _ in range(repeat):
    for name, writer in writers.items():
        mpi.Barrier()
        t0 = time.perf_counter()
        writer.write(directory, sim.model, sim.state, step, t, summary["steps"])
        mpi.Barrier()
        times[name].append(time.perf_counter() - t0)
size = os.path.getsize(os.path.join(directory, checkpoint.NAME)) if mpi.rank == 0 else 0
fig = {"scene": summary["scene"], "ranks": comm.size, "nodes": summary["mesh"]["nodes"],
       "cells": summary["mesh"]["cells"], "fault_faces": summary["mesh"]["fault_faces"], "bytes": size,
       "repeat": repeat}
for name, ts in times.items():
    fig[f"{name}_median_s"], fig[f"{name}_min_s"] = float(np.median(ts)), float(np.min(ts))
    PETSc.Sys.Print(f"checkpoint {name}: median {np.median(ts) * 1e3:.1f} ms, fastest {np.min(ts) * 1e3:.1f} ms "
                    f"per write ({size / 1e6:.2f} MB, {comm.size} ranks)")
PETSc.Sys.Print(json.dumps(fig))
sim.destroy()
