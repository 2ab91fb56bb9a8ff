#!/usr/bin/env python
"""Queretaro's fault in plane strain against the element size at the fault.

    .venv/bin/python benchmarks/queretaro_slab.py [--sizes 8,4,2,1,0.5,0.25] [--drawdown 11.3] [--no-run]

Prints one table (runs/queretaro_slab/table.md). A thin wrapper of studies/queretaro_slab.py (see its docstring).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from studies.queretaro_slab import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
