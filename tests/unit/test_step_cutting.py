"""Step retries: a fault step whose Newton solve does not converge is retried from its start as 2, 4, ...
sub-steps (pfault.solver.policy.cut_step), with a flow model's pore pressure interpolated linearly in time
within the step (pfault.sources.FlowSource.cell_dp); in-process, one rank.

The Newton solve is replaced by a stand-in that converges only for increments up to a given share of the step,
so the outcome of every attempt is known in advance; it records the times and pore pressures it is given.
"""

import numpy as np
import pytest
from petsc4py import PETSc

from pfault.records import Solve, SolveCost
from pfault.solver.policy import cut_step
from pfault.sources import FlowSource
from pfault.state import State


class FakeFlow:
    """A flow model whose head change is -10 t / (rho_w g) m in both cells, so that dp = -10 t (Pa)."""
    active = True

    def __init__(self):
        self.time = 0.0
        self.advances = []

    def advance_to(self, t):
        assert t >= self.time - 1e-12, "flow cannot go back"
        self.advances.append(t)
        self.time = max(self.time, t)

    def cell_dp(self):
        return np.full(2, -10.0 * self.time)


class FakeStep:
    """solve_step(t): converges for increments up to ``max_increment`` since the last converged time; records
    (t, dp the source gives at t, u at the start, converged)."""

    def __init__(self, source, max_increment, t_done=0.0):
        self.state = State(PETSc.Vec().createSeq(3))
        self.u = self.state.u
        self.u.set(1.0)
        self.source, self.max_increment, self.t_done = source, max_increment, t_done
        self.calls = []

    def __call__(self, t):
        dp = self.source.cell_dp(t)[0]
        start = self.u.getArray()[0]
        ok = t - self.t_done <= self.max_increment + 1e-12
        self.calls.append((t, dp, start, ok))
        self.u.set(100.0 + t)                 # a solve changes the state, converged or not
        if ok:
            self.t_done = t
        return Solve(t, ok, 2 if ok else -5, SolveCost(2, 2, 0.1, 2, 0, (1.0, 0.0)), nonlinear=True)


def test_failed_step_is_retried_as_sub_steps_with_interpolated_pressure():
    flow = FakeFlow()
    source = FlowSource(flow)
    source.advance_to(1.0)
    step = FakeStep(source, max_increment=0.25, t_done=1.0)
    step.u.set(1.0)
    source.advance_to(2.0)                  # the time loop advances the source before the step
    rec = cut_step(step, step.state, 1.0, 2.0, max_cuts=3)
    assert rec.converged and rec.substeps == 4
    times = [c[0] for c in step.calls]
    # full step, then 2 sub-steps (the first fails), then 4 sub-steps
    assert times == pytest.approx([2.0, 1.5, 1.25, 1.5, 1.75, 2.0])
    # every retry restarts from the state at the start of the step
    assert [c[2] for c in step.calls[:3]] == [1.0, 1.0, 1.0]
    # pore pressure: linear in time between the step's ends; the flow was advanced once, to t = 2
    assert [c[1] for c in step.calls] == pytest.approx([-20.0, -15.0, -12.5, -15.0, -17.5, -20.0])
    assert flow.advances == [1.0, 2.0]
    assert rec.cost.newton_its == 12 and rec.cost.factorizations == 12 and rec.time_s == 2.0
    assert len(rec.cost.residual_history) == 12
    assert rec.as_json()["substeps"] == 4 and rec.as_json()["newton_its"] == 12


def test_flow_source_reading_has_no_side_effect():
    """cell_dp reads the source at a time within its last advance; outside it is an error, and it never moves
    the flow model."""
    flow = FakeFlow()
    source = FlowSource(flow)
    source.advance_to(3.0)
    assert source.cell_dp(3.0) == pytest.approx([-30.0, -30.0])
    assert source.cell_dp(1.5) == pytest.approx([-15.0, -15.0])
    with pytest.raises(ValueError, match="not known"):
        source.cell_dp(4.0)
    assert flow.advances == [3.0] and flow.time == 3.0


def test_no_retry_without_cuts_and_failure_after_the_last_cut():
    source = FlowSource(FakeFlow())
    source.advance_to(1.0)
    step = FakeStep(source, max_increment=0.1)
    rec = cut_step(step, step.state, 0.0, 1.0, max_cuts=0)
    assert not rec.converged and len(step.calls) == 1
    step = FakeStep(source, max_increment=0.1)
    rec = cut_step(step, step.state, 0.0, 1.0, max_cuts=2)
    assert not rec.converged and rec.substeps == 4
    assert step.u.getArray()[0] != 1.0
    assert step.calls[-1][3] is False
