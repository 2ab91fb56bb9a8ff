#!/usr/bin/env python
"""Hard cases for the contact solver: small scenes run with their defaults, each checked against one invariant.

    .venv/bin/python benchmarks/hard_cases.py [--quick] [--cases NAME,...] [--no-run] [--list]

Writes runs/hard_cases/report.md (one row per case) and runs/hard_cases/newton_per_step.png; exits 1 when a
case does not converge or its invariant fails. A thin wrapper of studies/hard_cases.py (see its docstring).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from studies.hard_cases import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
