#!/usr/bin/env python
"""Direct fault solves keep their factors across a few faces' state changes (FactorReuse.budget); FGMRES on
the old factors must reach the same Newton iterates as a fresh factorisation.

    mpirun -n 2 python tests/scripts/factor_reuse.py -pfault_output_dir DIR

Runs Wuxi on a coarse mesh (size factor 3: faces change state in the first Newton iterations of steps 1-4)
twice in-process: as the scene is (MUMPS under FGMRES, its factors kept while few faces differ from the factored
states), and with -ksp_type preonly (no Krylov method: MUMPS factors every Jacobian that changed). Prints one JSON
line {"kept": run, "fresh": run}, each {newton, factorizations, krylov, ...} with the maxima of the run
(subsidence, horizontal displacement, opening, slip).
"""
import json
import os
import sys

import petsc4py
from pfault.optionsfile import petsc_arguments  # noqa: E402


SCENE = "config/wuxi.opts"
petsc4py.init([sys.argv[0], *petsc_arguments(SCENE, []), "-pfault_mesh_size_factor", "3"] + sys.argv[1:])
from mpi4py import MPI  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from pfault.simulation import Simulation  # noqa: E402


def run(fresh, outdir):
    if fresh:
        PETSc.Options().setValue("ksp_type", "preonly")
    PETSc.Options().setValue("pfault_output_dir", outdir)
    sim = Simulation(SCENE, sys.argv)
    summary = sim.run()
    figures = {k: summary[k] for k in ("max_subsidence_m", "max_horizontal_displacement_m", "max_fault_opening_m",
                                       "max_fault_slip_m")}
    steps = [s for s in summary["steps"] if not s.get("initial")]
    sim.destroy()
    return {"newton": [s["newton_its"] for s in steps], "factorizations": sum(s["factorizations"] for s in steps),
            "krylov": sum(s["ksp_its"] for s in steps), "converged": bool(summary["converged"]), **figures}


def main():
    base = PETSc.Options().getString("pfault_output_dir")
    out = {key: run(key == "fresh", os.path.join(base, key)) for key in ("kept", "fresh")}
    if MPI.COMM_WORLD.rank == 0:
        print(json.dumps(out))


if __name__ == "__main__":
    main()
