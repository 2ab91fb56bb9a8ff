#!/usr/bin/env python
"""Wuxi, Queretaro and the calibrated Queretaro at paper size on 2 ranks, against Franceschini et al. (2015).

    .venv/bin/python benchmarks/case_studies.py [--no-run] [--cases wuxi,...] [--solver iterative]
                                                [--size-factor 3] [-- more pfault/PETSc options]

Runs each case under mpirun (one at a time), makes its figures (runs/<run>/*.png) and rewrites
runs/README.md: paper vs pfault, mesh sizes, wall times by stage, per-step Newton/Krylov/active-set figures.
A thin wrapper of studies/casestudies.py (see its docstring).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from studies.casestudies import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
