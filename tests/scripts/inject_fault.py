"""Runs pfault's command line with a fault injected on one rank, to test that every rank still ends.

    mpirun -n 2 python tests/scripts/inject_fault.py KIND RANK STEP SCENE.opts [-option value ...]

KIND: ``bug`` (a RuntimeError) or ``memory`` (a MemoryError), raised in time step STEP on rank RANK only;
``bug_at_step_end`` (a RuntimeError) on rank RANK only when time step STEP is solved and its output written,
before its checkpoint and summary are;
``flow`` (the flow solver's FlowNotConverged) raised in time step STEP on every rank (RANK is ignored), as
the flow KSP's collective verdict is; ``disk_full`` (OSError ENOSPC) when rank RANK writes the fields of time
step STEP (on rank 0 when they are gathered there, on that rank when every rank writes its part,
pfault.io.parallel). Exits with pfault's exit code.

The run is pfault's command line (pfault.cli.main) given a Simulation whose observers include the faults. A full
disk is the storage's: HDF5's calls through h5py fail as a full disk makes them fail (the gathered writer's new
step group, or this rank's rows of a step written by every rank); pfault's own code is left as it is.
"""

import errno
import posixpath
import sys

import h5py
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
from pfault.solver.flow import FlowNotConverged  # noqa: E402

here = PETSc.COMM_WORLD.rank == rank
STEP_GROUP = f"steps/{step:06d}"
PARALLEL = parallel.available(PETSc.COMM_WORLD)     # every rank writes its part of the fields (MPI-IO)


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


class FullDisk:
    """h5py's calls that write step STEP of fields.h5, failing as on a full disk: the group of the step when one rank
    writes the file (the others have gathered their values to it), this rank's rows of the step when every rank
    writes its part (MPI-IO)."""

    create_group, setitem = h5py.Group.create_group, h5py.Dataset.__setitem__

    @staticmethod
    def full(file, name):
        return kind == "disk_full" and file.filename.endswith("fields.h5") and name.strip("/") == STEP_GROUP

    def new_group(self, name, *args, **kwargs):
        if not PARALLEL and FullDisk.full(self.file, name):
            raise OSError(errno.ENOSPC, "No space left on device", "fields.h5")
        return FullDisk.create_group(self, name, *args, **kwargs)

    def write(self, key, value):
        # (nothing collective here: the dataset's group from its name, as a rank without rows writes none)
        if PARALLEL and here and FullDisk.full(self.file, posixpath.dirname(self.name)):
            raise OSError(errno.ENOSPC, "No space left on device", "fields.h5")
        return FullDisk.setitem(self, key, value)


class InjectedSimulation(simulation.Simulation):
    """The run with the injected faults observing each step after its fields, before its checkpoint."""

    def observers(self, output, records):
        own = super().observers(output, records)
        return own[:2] + [Faults()] + own[2:]


h5py.Group.create_group, h5py.Dataset.__setitem__ = FullDisk.new_group, FullDisk.write
sys.exit(cli.main(scene, argv, simulation=InjectedSimulation))
