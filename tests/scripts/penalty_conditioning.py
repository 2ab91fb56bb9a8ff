#!/usr/bin/env python
"""Krylov iterations and condition-number estimates of the stick-state fault Jacobian: penalty contact with
stiffness k (normal = tangential) against Lagrange multipliers, two-blocks scene.

    python tests/scripts/penalty_conditioning.py [-pc jacobi,ilu] [-k 1e8,1e9,...] [pfault options ...]

In the closed stick configuration the fault system is linear, so its Jacobian is the matrix of the step. For each
method the state x0 has every face closed and sticking (the plus side pushed into the minus side by 1e-9 m; a
zero normal gap would count as open in pfault's penalty law), and the step J dx = -F(x0) is solved with
GMRES(30) and each preconditioner of -pc (jacobi, ilu), rtol 1e-10, at most 5000 iterations. The Krylov solver
also estimates the extreme singular values of the preconditioned operator. Prints one JSON line
{"lagrange": {pc: record}, "penalty": [{pc: record} per k]}.
"""
import json
import sys

import petsc4py
from pfault.optionsfile import petsc_arguments  # noqa: E402


SCENE = "config/two_blocks.opts"
argv = sys.argv[1:]
pcs, ks = ["jacobi", "ilu"], [1e8, 1e9, 1e10, 1e11]
if "-pc" in argv:
    i = argv.index("-pc")
    pcs = argv[i + 1].split(",")
    del argv[i:i + 2]
if "-k" in argv:
    i = argv.index("-k")
    ks = [float(v) for v in argv[i + 1].split(",")]
    del argv[i:i + 2]
petsc4py.init([sys.argv[0], *petsc_arguments(SCENE, [])] + argv)
import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from pfault.simulation import Simulation  # noqa: E402


def solve(sim, p, f, x, F, pc):
    ksp = PETSc.KSP().create(comm=PETSc.COMM_WORLD)
    ksp.setOptionsPrefix("cond_")
    ksp.setOperators(p.J, p.J)
    ksp.setType("gmres")
    ksp.getPC().setType(pc)
    ksp.setTolerances(rtol=1e-10, atol=0.0, max_it=5000)
    ksp.setComputeSingularValues(True)
    ksp.setFromOptions()
    dx = x.duplicate()
    ksp.solve(F, dx)
    its, reason = ksp.getIterationNumber(), ksp.getConvergedReason()
    smax, smin = ksp.computeExtremeSingularValues()
    # the solution's largest fault jump (stick: the exact answer is zero; penalty: ~ |t| / k)
    dx.axpy(1.0, x)
    x_loc = p.local_array(dx)
    gl = f.mean_jumps(x_loc, f.tractions(x_loc) - sim.state.histories[0].t0, p.loads.term_loads[0])[1]
    jump = float(np.max(np.linalg.norm(gl, axis=1), initial=0.0))
    jump = f.faces.mpi.allreduce(jump, op=MPI.MAX)
    ksp.destroy()
    dx.destroy()
    return {"ksp_its": int(its), "reason": int(reason), "converged": bool(reason > 0), "sigma_max": float(smax),
            "sigma_min": float(smin), "cond_estimate": float(smax / smin), "max_jump_m": jump}


def one(method, k=None):
    opts = PETSc.Options()
    opts.setValue("pfault_fault_fault_method", method)
    if k is not None:
        opts.setValue("pfault_fault_fault_penalty_normal", repr(k))
        opts.setValue("pfault_fault_fault_penalty_tangential", repr(k))
    sim = Simulation(SCENE, sys.argv)
    p, f, dm = sim.model.equations, sim.model.equations.terms[0], sim.model.dofmap
    p.loads.set(1.0)
    x = sim.state.u.duplicate()
    loc = np.zeros(dm.n_local)
    # a slight interpenetration: every face closed and stuck (Lagrange and penalty)
    loc[dm.vertex_dofs(1)[dm.vert_sides > 1]] = (-1e-9, 0.0, 0.0)
    p.to_global(loc, PETSc.InsertMode.INSERT_VALUES, out=x)
    F = x.duplicate()
    p.residual(x, F, sim.state.histories)
    F.scale(-1.0)
    p.assemble_jacobian(x, p.J, sim.state.histories)
    out = {}
    for pc in pcs:
        out[pc] = solve(sim, p, f, x, F, pc)
        out[pc].update(method=method, k=k)
    for obj in (x, F):
        obj.destroy()
    sim.destroy()
    return out


if __name__ == "__main__":
    res = {"pcs": pcs, "lagrange": one("lagrange"), "penalty": [one("penalty", k) for k in ks]}
    if PETSc.COMM_WORLD.rank == 0:
        print(json.dumps(res))
