#!/usr/bin/env python
"""Mesh convergence of the fault answer on the faulted aquifer, the 3-D block and its plane-strain slab.

    .venv/bin/python benchmarks/fault_convergence.py [--cases NAME,...] [--no-run] [--list] [--step N]

Prints one table (runs/fault_convergence/table.md). A thin wrapper of studies/fault_convergence.py (see its
docstring).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from studies.fault_convergence import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
