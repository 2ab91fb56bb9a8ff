#!/usr/bin/env python
"""Runs a scene and writes every output step twice: through the run's own output (on more than one rank with
h5py built with MPI, written by every rank: pfault.io.parallel) into -pfault_output_dir, and gathered to rank
0 (pfault.io.steps.StepOutput with parallel=False, the serial writer) into GATHERED_DIR, from the same values.

    mpirun -n 2 python tests/scripts/parallel_output.py SCENE.opts GATHERED_DIR [-option value ...]

Prints JSON {"ranks": N, "parallel": whether the run's output was written in parallel, "h5py_mpi": whether
h5py has MPI, "runs": {series: {center: contiguous runs of rows per rank}}}.
"""
import dataclasses
import json
import sys

import petsc4py

scene, gathered_dir = sys.argv[1], sys.argv[2]
petsc4py.init([sys.argv[0], "-options_file", scene] + sys.argv[3:])
from petsc4py import PETSc  # noqa: E402

from pfault.errors import run_on_root  # noqa: E402
from pfault.simulation import Simulation  # noqa: E402


class Twice(Simulation):
    """A Simulation whose every output step is also written by a gathering StepOutput into gathered_dir."""
    mirror = None

    def _output(self, step, t, u_rel_local, initial=False):
        if self.mirror is None:
            own = self.settings
            self.settings = dataclasses.replace(own, output_dir=gathered_dir)
            writer = run_on_root(self.comm, self._create_writer)
            self.settings = own
            self.mirror = writer, self._step_output(writer, parallel=False)
        maxima = super()._output(step, t, u_rel_local, initial)
        own, self.output = self.output, self.mirror[1]
        try:
            again = super()._output(step, t, u_rel_local, initial)
        finally:
            self.output = own
        assert again == maxima
        run_on_root(self.comm, lambda: self.mirror[0].commit())      # the writer: rank 0 only
        return maxima


comm = PETSc.COMM_WORLD
sim = Twice(scene, sys.argv)
sim.setup()
sim.run()
run_on_root(comm, sim.write_summary, 0.0)
run_on_root(comm, lambda: sim.mirror[0].close())
out = sim.output
blocks = {}
if out.parallel:
    # per series and kind of row, every rank's (block it writes, rows it holds outside that block)
    from pfault.io.parallel import Block
    rows = {"fields": {"Node": out.vertices, "Cell": out.cells}}
    if out.faces is not None:
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
