#!/usr/bin/env python
"""Accuracy against cost: error, unknowns, wall time, Newton and Krylov iterations on problems with a known
answer (manufactured solution, oedometer, Theis, penny crack, two blocks) and the two case studies against
their finest mesh, over mesh size, solver, nonlinear tolerance and penalty stiffness.

    .venv/bin/python benchmarks/accuracy_cost.py [--quick] [--problems penny,two_blocks] [--report-only]

Writes runs/accuracy_cost/report.md, error_vs_time.png and results.json. A thin wrapper of
studies/accuracy.py (see its docstring).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from studies.accuracy import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
