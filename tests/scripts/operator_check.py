#!/usr/bin/env python
"""The constant operator of a scene as pfault builds it (pfault.solver.equations.Equations: exactly the blocks the
cells and the terms touch, where every dof comes in aligned triples) against the DM's matrix extended by the
terms' pattern, which it replaced: their largest entry difference relative to the largest entry, their nonzeros
and block sizes, and whether every entry of the DM's pattern that holds a value is in the operator's pattern.

    mpirun -n 2 python tests/scripts/operator_check.py [--scene config/two_blocks.opts] [options]

Prints JSON {"ranks", "rel_diff", "nnz", "nnz_dm", "bs", "bs_dm", "missing"}.
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
from mpi4py import MPI  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from pfault.simulation import Simulation  # noqa: E402
from pfault.solver.operator import build_from_dm  # noqa: E402

sim = Simulation(SCENE, sys.argv)
eq = sim.model.equations
K = eq.K
D = build_from_dm(eq.dm, eq.asm, eq.terms)
D.zeroRowsColumns(eq.bc_rows, diag=1.0)
comm = MPI.COMM_WORLD
scale = comm.allreduce(float(np.abs(K.getValuesCSR()[2]).max(initial=0.0)), op=MPI.MAX)
# entries of the DM's matrix that hold a value (not an explicit zero) but are not in the operator's pattern
ip, jk, vk = K.getValuesCSR()
id_, jd, vd = D.getValuesCSR()
start, _ = K.getOwnershipRange()
ncols = K.getSize()[1]
keys_k = np.repeat(np.arange(len(ip) - 1), np.diff(ip)) * ncols + jk
keys_d = np.repeat(np.arange(len(id_) - 1), np.diff(id_)) * ncols + jd
missing = int(np.count_nonzero(~np.isin(keys_d[vd != 0.0], keys_k)))
diff = D.copy()
diff.axpy(-1.0, K, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
rel = comm.allreduce(float(np.abs(diff.getValuesCSR()[2]).max(initial=0.0)), op=MPI.MAX) / scale
out = {"ranks": comm.size, "rel_diff": rel,
       "nnz": int(K.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"]),
       "nnz_dm": int(D.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"]),
       "bs": K.getBlockSize(), "bs_dm": D.getBlockSize(), "missing": comm.allreduce(missing)}
for m in (diff, D):
    m.destroy()
sim.destroy()
if comm.rank == 0:
    print(json.dumps(out))
