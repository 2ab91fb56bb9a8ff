"""Step retries: a fault step whose Newton solve does not converge is retried from its start as 2, 4, ...
sub-steps, with a flow model's pore pressure interpolated linearly in time (Problem.solve_interval, in-process,
one rank).

The Newton solve is replaced by a stand-in that converges only for increments up to a given share of the step,
so the outcome of every attempt is known in advance; it records the times and pore pressures it is given.
"""

import numpy as np
import pytest
from petsc4py import PETSc

from pfault.faults.settings import ContactSettings
from pfault.solver.problem import Problem


class FakeFlow:
    active = True

    def __init__(self):
        self.time = 0.0

    def advance_to(self, t):
        assert t >= self.time - 1e-12, "flow cannot go back"
        self.time = max(self.time, t)

    def cell_values(self, t, *args):
        self.advance_to(t)
        return np.full(2, -10.0 * t)           # dp = -10 t (Pa) in both cells


class FakeProblem(Problem):
    def __init__(self, max_increment):
        self.u = PETSc.Vec().createSeq(3)
        self.u.set(1.0)
        self.faults = object()
        self.contact = ContactSettings()
        self.drawdown = FakeFlow()
        self._dp_interval = None
        self.mesh = type("M", (), {"cells": np.zeros((2, 4), int), "cell_material": np.zeros(2, int)})()
        self.asm = type("A", (), {"centroids": np.zeros((2, 3))})()
        self.max_increment = max_increment
        self.calls = []
        self.t_done = 0.0

    def solve_step(self, snes, t):
        dp = self.cell_dp(t)[0]
        start = self.u.getArray()[0]
        ok = t - self.t_done <= self.max_increment + 1e-12
        self.calls.append((t, dp, start, ok))
        self.u.set(100.0 + t)                 # a solve changes the state, converged or not
        if ok:
            self.t_done = t
        return {"time_s": t, "newton_its": 2, "ksp_its": 2, "wall_s": 0.1, "factorizations": 2,
                "converged": ok, "residual_history": [1.0, 0.0]}


def test_failed_step_is_retried_as_sub_steps_with_interpolated_pressure():
    p = FakeProblem(max_increment=0.25)
    p.t_done = 1.0
    p.drawdown.time = 1.0
    rec = p.solve_interval(None, 1.0, 2.0, max_cuts=3)
    assert rec["converged"] and rec["substeps"] == 4
    times = [c[0] for c in p.calls]
    # full step, then 2 sub-steps (the first fails), then 4 sub-steps
    assert times == pytest.approx([2.0, 1.5, 1.25, 1.5, 1.75, 2.0])
    # every retry restarts from the state at the start of the step
    assert [c[2] for c in p.calls[:3]] == [1.0, 1.0, 1.0]
    # pore pressure: linear in time between the step's ends (the flow has already been advanced to t = 2)
    assert [c[1] for c in p.calls] == pytest.approx([-20.0, -15.0, -12.5, -15.0, -17.5, -20.0])
    assert rec["newton_its"] == 12 and rec["factorizations"] == 12 and rec["time_s"] == 2.0
    assert len(rec["residual_history"]) == 12


def test_no_retry_without_cuts_and_failure_after_the_last_cut():
    p = FakeProblem(max_increment=0.1)
    rec = p.solve_interval(None, 0.0, 1.0, max_cuts=0)
    assert not rec["converged"] and len(p.calls) == 1
    p = FakeProblem(max_increment=0.1)
    rec = p.solve_interval(None, 0.0, 1.0, max_cuts=2)
    assert not rec["converged"] and rec["substeps"] == 4
    assert p.u.getArray()[0] != 1.0
    assert p.calls[-1][3] is False
