#!/usr/bin/env python
"""A direct fault solve's factor reuse decides the same way however busy the machine is: Wuxi on a coarse mesh
run twice in-process with MUMPS, the second time on a machine shared with other jobs (``Busy``). Prints one JSON
line {"quiet": run, "slowed": run, "max_difference": x}: per run the Newton and Krylov iterations and
factorisations of each step; the largest difference between the two runs' output datasets (fields, fault,
surface), relative to the dataset's largest value over the steps.

    mpirun -n 2 python tests/scripts/reuse_determinism.py -pfault_output_dir DIR
"""
import json
import os
import subprocess
import sys
import time

import petsc4py
from pfault.optionsfile import petsc_arguments  # noqa: E402


SCENE = "config/wuxi.opts"
petsc4py.init([sys.argv[0], *petsc_arguments(SCENE, []), "-pfault_mesh_size_factor", "3", "-pfault_solver", "mumps",
               "-pfault_figures", "false"] + sys.argv[1:])
import h5py  # noqa: E402
import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from pfault.simulation import Simulation  # noqa: E402


class Busy:
    """A machine busy with other jobs: two processes spinning on the cores (started by rank 0) from the start of
    the run until the first factorisation, the ordering of the Jacobian gathered from the ranks, is done (the
    ranks' messages then arrive in another order), and 30 ms at every later Krylov iteration (KSP monitor)."""

    def __init__(self):
        spin = [sys.executable, "-c", "while True: pass"]
        self.spinning = [] if MPI.COMM_WORLD.rank else [subprocess.Popen(spin) for _ in range(2)]

    def stop(self):
        for p in self.spinning:
            p.kill()
            p.wait()
        self.spinning = []

    def monitor(self, ksp, its, rnorm):
        self.stop()                 # a first residual: the operator's factors are made
        if its > 0:
            time.sleep(0.03)


def run(outdir, slow):
    PETSc.Options().setValue("pfault_output_dir", outdir)
    busy = Busy() if slow else None
    try:
        sim = Simulation(SCENE, sys.argv)
        if busy:
            sim.solver.snes.getKSP().setMonitor(busy.monitor)   # appended to the factor reuse's own monitor
        summary = sim.run()
        sim.destroy()
    finally:
        if busy:
            busy.stop()
    steps = [s for s in summary["steps"] if not s.get("initial")]
    return {"converged": bool(summary["converged"]), "newton": [s["newton_its"] for s in steps],
            "factorizations": [s["factorizations"] for s in steps], "krylov": [s["ksp_its"] for s in steps]}


def difference(a, b):
    """The largest difference between the runs' datasets relative to the dataset's largest value over the steps."""
    worst = 0.0
    for name in ("fields", "fault", "surface"):
        with h5py.File(os.path.join(a, name + ".h5"), "r") as fa, h5py.File(os.path.join(b, name + ".h5"), "r") as fb:
            diff, scale = {}, {}
            for step in fa["steps"]:
                for key in fa["steps"][step]:
                    x, y = (np.nan_to_num(f["steps"][step][key][()].astype(float)) for f in (fa, fb))
                    diff[key] = max(diff.get(key, 0.0), float(np.max(np.abs(x - y), initial=0.0)))
                    scale[key] = max(scale.get(key, 0.0), float(np.max(np.abs(x), initial=0.0)))
            worst = max([worst] + [diff[k] / max(scale[k], 1e-300) for k in diff])
    return worst


def main():
    base = PETSc.Options().getString("pfault_output_dir")
    out = {key: run(os.path.join(base, key), key == "slowed") for key in ("quiet", "slowed")}
    if MPI.COMM_WORLD.rank == 0:
        out["max_difference"] = difference(os.path.join(base, "quiet"), os.path.join(base, "slowed"))
        print(json.dumps(out))


if __name__ == "__main__":
    main()
