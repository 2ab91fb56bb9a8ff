#!/usr/bin/env python
"""Runs a scene and writes every output step twice: through the run's own output (on more than one rank with
h5py built with MPI, written by every rank: pfault.io.parallel) into -pfault_output_dir, and gathered to rank
0 (pfault.io.steps.StepOutput with parallel=False, the serial writer) into GATHERED_DIR, from the same values.

    mpirun -n 2 python tests/scripts/parallel_output.py SCENE.opts GATHERED_DIR [-option value ...]

Prints JSON {"ranks": N, "parallel": whether the run's output was written in parallel, "h5py_mpi": whether
h5py has MPI, "runs": {series: {center: contiguous runs of rows per rank}}}.
"""
import json
import sys

import petsc4py

from pfault.optionsfile import petsc_arguments

scene, gathered_dir = sys.argv[1], sys.argv[2]
petsc4py.init([sys.argv[0]] + petsc_arguments(scene, sys.argv[3:]))
from petsc4py import PETSc  # noqa: E402

import numpy as np  # noqa: E402

from pfault.errors import run_on_root  # noqa: E402
from pfault.io.observers import Observer  # noqa: E402
from pfault.io.steps import StepOutput  # noqa: E402
from pfault.simulation import Simulation  # noqa: E402


class Mirror(Observer):
    """Every output step written again by a gathering StepOutput into gathered_dir, after the run's own."""

    def __init__(self, output):
        self.output = output
        self.writer = self.fields = None

    def step_done(self, result):
        if not result.output:
            return
        out = self.output
        if self.fields is None:         # (the writer is rank 0's: None on the other ranks)
            m = out.model
            self.writer = run_on_root(out.comm, out.create_writer, gathered_dir)
            sides = out.comm.tompi4py().bcast(m.split.vert_sides if out.comm.rank == 0 and m.split is not None
                                              else None)
            self.fields = StepOutput(out.comm, m.mesh, self.writer, sides, m.dofmap.max_sides, faces=m.faces.face,
                                     fault_id=m.fault_id, parallel=False)
            self.fields.write(0, 0.0, *out.initial)
        out.write_step(result, self.fields)
        run_on_root(out.comm, lambda: self.writer.commit())      # the writer: rank 0 only


class Twice(Simulation):
    """A Simulation whose every output step is also written by a gathering StepOutput into gathered_dir."""
    mirror = None

    def observers(self, output, records):
        own = super().observers(output, records)
        self.mirror = Mirror(output)
        return own[:2] + [self.mirror] + own[2:]


comm = PETSc.COMM_WORLD
sim = Twice(scene, sys.argv)
run_on_root(comm, sim.write_summary, sim.run(), 0.0)
run_on_root(comm, lambda: sim.mirror.writer.close())
out = sim.output.fields
blocks = {}
if out.parallel:
    # per series and kind of row, every rank's (block it writes, rows it holds outside that block)
    from pfault.io.parallel import Block
    rows = {"fields": {"Node": out.vertices, "Cell": out.cells}}
    if out.n_faces:
        rows["fault"] = {"Cell": out.face_rows}
    for name, by_center in rows.items():
        blocks[name] = {}
        for c, r in by_center.items():
            b = Block(comm.tompi4py(), r)
            outside = int(((r.rows < b.start) | (r.rows >= b.stop)).sum())
            blocks[name][c] = comm.tompi4py().allgather((b.stop - b.start, outside))
import h5py  # noqa: E402
info = {"ranks": comm.size, "parallel": out.parallel, "h5py_mpi": bool(h5py.get_config().mpi), "blocks": blocks}
sim.destroy()
if comm.rank == 0:
    print(json.dumps(info))
