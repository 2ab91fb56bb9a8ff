"""Command line: ``mpirun -n 2 python -m pfault SCENE.opts [-option value ...]``.

Exit codes: 0 done, 1 bad input, 2 usage, 3 a step did not converge, 4 interrupted (SIGTERM, SIGINT or
SIGUSR1: the run stopped after its current step; summary.json says "interrupted": true).
"""

from __future__ import annotations

import sys
import time

from petsc4py import PETSc

from .errors import InputError

EXIT_OK, EXIT_INPUT, EXIT_USAGE, EXIT_NOT_CONVERGED = 0, 1, 2, 3
EXIT_INTERRUPTED = 4


def main(options_file, argv):
    from .simulation import Simulation
    from .options import help_text
    if PETSc.Options().hasName("help"):
        PETSc.Sys.Print(help_text())
    t0 = time.perf_counter()
    sim = Simulation(options_file, argv)
    try:
        sim.setup()
        summary = sim.run()
        sim.write_summary(time.perf_counter() - t0)
    except InputError as exc:
        PETSc.Sys.syncPrint(f"pfault: error: {exc}", flush=True) if False else None
        if PETSc.COMM_WORLD.rank == 0:
            sys.stderr.write(f"pfault: error: {exc}\n")
            sys.stderr.flush()
        return EXIT_INPUT
    finally:
        sim.destroy()
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
