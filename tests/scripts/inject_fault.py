"""Runs pfault's command line with a fault injected on one rank, to test that every rank still ends.

    mpirun -n 2 python tests/scripts/inject_fault.py KIND RANK STEP SCENE.opts [-option value ...]

KIND: ``bug`` (a RuntimeError) or ``memory`` (a MemoryError), raised in time step STEP on rank RANK only;
``bug_at_step_end`` (a RuntimeError) on rank RANK only when time step STEP is solved and its output written,
before its checkpoint and summary are;
``flow`` (the flow solver's FlowNotConverged) raised in time step STEP on every rank (RANK is ignored), as
the flow KSP's collective verdict is; ``disk_full`` (OSError ENOSPC) when rank RANK writes the fields of time
step STEP (on rank 0 when they are gathered there, on that rank when every rank writes its part,
pfault.io.parallel). Exits with pfault's exit code.
"""

import errno
import sys

import petsc4py

from pfault.__main__ import check_arguments
from pfault.optionsfile import petsc_arguments

kind, rank, step = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
argv = [sys.argv[0]] + sys.argv[4:]
scene, rest = check_arguments(argv)
petsc4py.init([argv[0]] + petsc_arguments(scene, rest))
from petsc4py import PETSc  # noqa: E402

from pfault import cli, simulation  # noqa: E402
from pfault.io import parallel  # noqa: E402
from pfault.io.observers import Observer  # noqa: E402
from pfault.io.output import RunWriter  # noqa: E402
from pfault.solver.flow import FlowNotConverged  # noqa: E402

write_step, write_block = RunWriter.write_step, parallel.write_block
here = PETSc.COMM_WORLD.rank == rank


class Faults(Observer):
    """Raises the injected fault when step ``step`` starts (bug, memory, flow) or once it is done and its fields
    are written, before its checkpoint and summary (bug_at_step_end: given to the run before those observers)."""

    def step_started(self, number, t):
        if number != step:
            return
        if here and kind == "bug":
            raise RuntimeError(f"injected fault in step {step}")
        if here and kind == "memory":
            raise MemoryError(f"injected: unable to allocate 8 GiB in step {step}")
        if kind == "flow":
            raise FlowNotConverged(f"groundwater flow: injected: KSP flow_ did not converge in step {step}")

    def step_done(self, result):
        if kind == "bug_at_step_end" and result.step == step and here:
            raise RuntimeError(f"injected fault at the end of step {step}")


def faulty_write_step(self, number, t, point_data, cell_data):
    if kind == "disk_full" and number == step:
        raise OSError(errno.ENOSPC, "No space left on device", "fields.h5")
    return write_step(self, number, t, point_data, cell_data)


def faulty_write_block(ds, start, value):
    if kind == "disk_full" and ds.file.filename.endswith("fields.h5") and ds.parent.name == f"/steps/{step:06d}" \
            and here:
        raise OSError(errno.ENOSPC, "No space left on device", "fields.h5")
    return write_block(ds, start, value)


class InjectedSimulation(simulation.Simulation):
    """The run with the injected faults observing each step after its fields, before its checkpoint."""

    def observers(self, output, records):
        own = super().observers(output, records)
        return own[:2] + [Faults()] + own[2:]


simulation.Simulation = InjectedSimulation
RunWriter.write_step = faulty_write_step
parallel.write_block = faulty_write_block
sys.exit(cli.main(scene, argv))
