#!/usr/bin/env python
"""Runs a scene and writes the checkpoint of every completed step twice, from the same state: through the
run's own writer (on more than one rank with h5py built with MPI, written by every rank: pfault.io.parallel)
into -pfault_output_dir, and gathered to rank 0 (pfault.io.checkpoint.Writer with parallel_io=False) into
GATHERED_DIR/STEP/checkpoint.h5; the run's own checkpoint of each step is copied to OWN_DIR/STEP/ before the
next step replaces it.

    mpirun -n 2 python tests/scripts/parallel_checkpoint.py SCENE.opts GATHERED_DIR OWN_DIR [-option value ...]

Prints JSON {"ranks": N, "parallel": whether the run's checkpoint was written by every rank, "h5py_mpi": whether
h5py has MPI, "steps": the steps written, "blocks": {kind of row: [(rows of the block a rank writes, rows it
holds outside that block) per rank]}}.
"""
import json
import os
import shutil
import sys

import petsc4py

from pfault.optionsfile import petsc_arguments

scene, gathered_dir, own_dir = sys.argv[1:4]
petsc4py.init([sys.argv[0]] + petsc_arguments(scene, sys.argv[4:]))
from petsc4py import PETSc  # noqa: E402

from pfault.errors import run_on_root  # noqa: E402
from pfault.io import checkpoint  # noqa: E402
from pfault.io.observers import Observer  # noqa: E402
from pfault.simulation import Simulation  # noqa: E402


class Gathered(Observer):
    """After the run's own checkpoint of a converged step: a copy of it, and the same state written by a
    gathering writer."""

    def __init__(self, sim, output, records):
        self.sim, self.output, self.records = sim, output, records
        self.steps_written = []

    def step_done(self, result):
        if not result.record.converged:
            return
        out, sim = self.output, self.sim
        gathered = checkpoint.Writer(sim.comm, sim.model.mesh, out.checkpoint.faces, out.checkpoint.n_faces,
                                     parallel_io=False, texts=out.checkpoint.texts)
        mine, theirs = (os.path.join(d, str(result.step)) for d in (own_dir, gathered_dir))

        def copy():
            os.makedirs(theirs)
            shutil.copytree(out.run_path, mine, ignore=lambda d, names: [n for n in names if n != checkpoint.NAME])
        run_on_root(sim.comm, copy)
        gathered.write(theirs, sim.model, sim.state, result.step, result.t, self.records)
        self.steps_written.append(result.step)


class Twice(Simulation):
    """A Simulation whose checkpoint is also written by a gathering writer after every completed step."""
    gathered = None

    def observers(self, output, records):
        self.gathered = Gathered(self, output, records)
        return super().observers(output, records) + [self.gathered]


comm = PETSc.COMM_WORLD
sim = Twice(scene, sys.argv)
run_on_root(comm, sim.write_summary, sim.run(), 0.0)
mpi = comm.tompi4py()
blocks = {}
ck = sim.output.checkpoint
if ck.parallel:
    for kind, rows in ck.rows.items():
        b = ck.blocks[kind]
        outside = int(((rows.rows < b.start) | (rows.rows >= b.stop)).sum())
        blocks[kind] = mpi.allgather((b.stop - b.start, outside))
import h5py  # noqa: E402
info = {"ranks": comm.size, "parallel": ck.parallel, "h5py_mpi": bool(h5py.get_config().mpi),
        "steps": sim.gathered.steps_written, "blocks": blocks}
sim.destroy()
if comm.rank == 0:
    print(json.dumps(info))
