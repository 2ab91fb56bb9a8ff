#!/usr/bin/env python
"""Mesh convergence of the fault answer of calibrated Queretaro and its controlled variants.

    .venv/bin/python benchmarks/queretaro_convergence.py [--cases NAME,...] [--no-run] [--list]

Prints one table (runs/queretaro_convergence/table.md). A thin wrapper of studies/queretaro_convergence.py (see its
docstring).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from studies.queretaro_convergence import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
