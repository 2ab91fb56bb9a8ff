#!/usr/bin/env python
"""Fault faces owned by each rank for the two-blocks scene, or the scene named by --scene (extra options from the
command line).

    mpirun -n 2 python tests/scripts/fault_partition.py -pfault_box_cells 8,4,4
    mpirun -n 2 python tests/scripts/fault_partition.py --scene junction.opts -pfault_box_fault_planes ...

Prints JSON {"ranks": N, "faces_per_rank": [...], "fault_faces": total, "cell_ranks": [...]} (cell_ranks: the
rank of each cell, in serial order). A face belongs to the rank that owns its minus cell
(pfault.faults.term.FaultTerm); the 2-rank fault tests need faces on every rank.
"""
import json
import sys

import numpy as np
import petsc4py
from pfault.optionsfile import petsc_arguments  # noqa: E402


SCENE = "config/two_blocks.opts"
if sys.argv[1:2] == ["--scene"]:
    SCENE = sys.argv[2]
    del sys.argv[1:3]
petsc4py.init([sys.argv[0], *petsc_arguments(SCENE, [])] + sys.argv[1:])
from petsc4py import PETSc  # noqa: E402

from pfault.simulation import Simulation  # noqa: E402

sim = Simulation(SCENE, sys.argv)
faults = sim.model.equations.terms[0]
counts = [int(c) for c in faults.faces.mpi.allgather(faults.faces.nf)]
mesh = sim.model.mesh
owned = faults.faces.mpi.gather(mesh.cell_serial)      # (no overlap: every local cell is owned)
out = {"ranks": PETSc.COMM_WORLD.size, "faces_per_rank": counts, "fault_faces": int(faults.faces.nf_total)}
if owned is not None:
    cell_ranks = np.zeros(sum(len(ids) for ids in owned), int)
    for r, ids in enumerate(owned):
        cell_ranks[ids] = r
    out["cell_ranks"] = cell_ranks.tolist()
sim.destroy()
if PETSc.COMM_WORLD.rank == 0:
    print(json.dumps(out))
