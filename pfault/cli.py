"""Command line: ``mpirun -n 2 python -m pfault SCENE.opts [-option value ...]``.

Exit codes (the same on every rank; mpirun returns them):

    0  done
    1  bad input: an option, the scene file or a mesh file (one line on stderr naming it and the fix)
    2  usage: no scene file, a scene file that does not exist, stray arguments
    3  a step did not converge (summary.json says which), the groundwater-flow solve or the geostatic
       gravity solve failed
    4  the output cannot be written: -pfault_output_dir not writable, a file in the way, the disk full
       (checked before the first solve against an estimate of the output size, and on every write)
    5  out of memory (a box too large for this machine is found before it is built)
    6  internal error: a bug; the traceback is printed before the line
    7  interrupted: SIGTERM, SIGINT or SIGUSR1 stopped the run after its current step (summary.json says
       "interrupted": true; -pfault_restart continues it)

Every error is one line starting with ``pfault: error:`` (``pfault: internal error:`` for a bug), printed
once. An error on some ranks only ends the whole job within seconds (pfault.errors.RunGuard).
"""

from __future__ import annotations

import time

from petsc4py import PETSc

from .errors import (EXIT_INPUT, EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_MEMORY, EXIT_NOT_CONVERGED,  # noqa: F401
                     EXIT_OK, EXIT_OUTPUT, EXIT_USAGE, RunGuard, StepNotConverged, as_pfault_error,
                     run_on_root)
from .options import help_text
from .simulation import Simulation
from .solver.flow import FlowNotConverged


def _flow_failure(exc):
    return StepNotConverged(f"{exc}; the flow solver is set with -flow_ksp_* and -flow_pc_* (e.g. raise "
                            "-flow_ksp_max_it or choose -flow_pc_type lu)")


def _destroy(sim):
    if sim is not None:
        sim.destroy()


def _last_words(sim, line, code):
    """A rank failing alone, before the job is aborted: it records the failure in the summary.json of a run in
    place, or removes the staging directory of one that has not completed a step (Simulation.last_words)."""
    if sim is not None:
        sim.last_words(line, code)


def main(options_file: str, argv: list[str], simulation: type | None = None) -> int:
    """Run the scene ``options_file`` with the command line ``argv``; returns the exit code. ``simulation``: the
    class of the run (default pfault.simulation.Simulation; a test gives one whose observers inject faults)."""
    comm = PETSc.COMM_WORLD
    guard = RunGuard(comm)
    sim = None
    t0 = time.perf_counter()
    try:
        if PETSc.Options().hasName("help"):
            PETSc.Sys.Print(help_text())
        sim = (simulation or Simulation)(options_file, argv)
        summary = sim.run()
        run_on_root(comm, sim.write_summary, summary, time.perf_counter() - t0)
    except (Exception, KeyboardInterrupt) as exc:  # noqa: BLE001  (every failure ends the run through the guard)
        err = as_pfault_error(_flow_failure(exc) if isinstance(exc, FlowNotConverged) else exc)
        code = guard.settle(err, last_words=lambda line, code: _last_words(sim, line, code))
        # reached only when every rank failed together
        if sim is not None and guard.comm.rank == 0:
            sim.record_failure(err.line(), code)
        guard.comm.Barrier()   # no rank ends (mpirun then stops the others) while rank 0 writes
        _destroy(sim)
        guard.free()
        return code
    _destroy(sim)
    guard.free()
    PETSc.Sys.Print(f"pfault: {summary['scene']}: max subsidence {summary['max_subsidence_m']:.6g} m, "
                    f"max horizontal displacement {summary['max_horizontal_displacement_m']:.6g} m, "
                    f"wall {time.perf_counter() - t0:.2f} s -> {sim.settings.output_dir}")
    if not summary["converged"]:
        PETSc.Sys.Print("pfault: a step did not converge; see summary.json")
        return EXIT_NOT_CONVERGED
    if summary.get("interrupted"):
        PETSc.Sys.Print(f"pfault: interrupted after step {summary['completed_steps'][-1]}; continue it with "
                        f"-pfault_restart {sim.settings.output_dir}")
        return EXIT_INTERRUPTED
    return EXIT_OK
