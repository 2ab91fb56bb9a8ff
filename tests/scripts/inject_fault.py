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

kind, rank, step = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
argv = [sys.argv[0]] + sys.argv[4:]
scene, rest = check_arguments(argv)
petsc4py.init([argv[0], "-options_file", scene] + rest)
from petsc4py import PETSc  # noqa: E402

from pfault import cli  # noqa: E402
from pfault.io.output import RunWriter  # noqa: E402
from pfault.io.parallel import ParallelSeries  # noqa: E402
from pfault.simulation import Simulation  # noqa: E402
from pfault.solver.flow import FlowNotConverged  # noqa: E402

solve, write_step, write_part = Simulation._solve, RunWriter.write_step, ParallelSeries._fill
step_done = Simulation._step_done


def faulty_solve(self, t, t_prev=0.0):
    here = PETSc.COMM_WORLD.rank == rank and abs(t - self.settings.time_end * step / self.settings.time_steps) \
        < 1e-9 * self.settings.time_end
    if here and kind == "bug":
        raise RuntimeError(f"injected fault in step {step}")
    if here and kind == "memory":
        raise MemoryError(f"injected: unable to allocate 8 GiB in step {step}")
    if kind == "flow" and abs(t - self.settings.time_end * step / self.settings.time_steps) < 1e-9 * t:
        raise FlowNotConverged(f"groundwater flow: injected: KSP flow_ did not converge in step {step}")
    return solve(self, t, t_prev)


def faulty_write_step(self, number, t, point_data, cell_data):
    if kind == "disk_full" and number == step:
        raise OSError(errno.ENOSPC, "No space left on device", "fields.h5")
    return write_step(self, number, t, point_data, cell_data)


def faulty_write_part(datasets):
    ds = datasets[0][0]
    if kind == "disk_full" and ds.file.filename.endswith("fields.h5") and ds.parent.name == f"/steps/{step:06d}" and \
            PETSc.COMM_WORLD.rank == rank:
        raise OSError(errno.ENOSPC, "No space left on device", "fields.h5")
    return write_part(datasets)


def faulty_step_done(self, steps, rec, number, t):
    if kind == "bug_at_step_end" and number == step and PETSc.COMM_WORLD.rank == rank:
        raise RuntimeError(f"injected fault at the end of step {step}")
    return step_done(self, steps, rec, number, t)


Simulation._solve = faulty_solve
Simulation._step_done = faulty_step_done
RunWriter.write_step = faulty_write_step
ParallelSeries._fill = staticmethod(faulty_write_part)
sys.exit(cli.main(scene, argv))
