"""Breaking within Newton (pfault.solver.policy.Settling): when an iterate's error is estimated from Newton's last
two steps, and what a cut step reports of the faces broken in its sub-steps; in-process, one rank.

The equations and SNES are stand-ins that give the iterate's configuration and the sizes of Newton's steps, so
that the estimate of every iterate is known in advance.
"""

import numpy as np
import pytest
from petsc4py import PETSc

from pfault.records import Solve, SolveCost
from pfault.solver.policy import VERDICT_CONTRACTION, Settling, cut_step
from pfault.state import State


class FakeEquations:
    """Gives the configuration of the iterate (``configs[its]``) and the size of Newton's last step in what the
    one term reads (``steps[its]``), indexed by the iterate's number, which the fake SNES holds."""
    comm = PETSc.COMM_SELF

    def __init__(self, configs, steps):
        self.configs, self.steps, self.its = configs, steps, 0

    def configuration(self, x, histories):
        return (np.array(self.configs[self.its]),)

    def settle_changes(self, dx):
        return (self.steps[self.its],)


class FakeSnes:
    def __init__(self, eq):
        self.eq = eq

    def getSolution(self):
        return None

    def getSolutionUpdate(self):
        return None


def estimates(configs, steps):
    """The estimates of a SNES solve's iterates 0, 1, ... (one term)."""
    eq = FakeEquations(configs, steps)
    settling = Settling(eq, State(PETSc.Vec().createSeq(1)))
    settling.begin(1.0)
    out = []
    for its in range(len(configs)):
        eq.its = its
        out.append(settling.iterate_errors(FakeSnes(eq), its))
    return out


def test_an_estimate_needs_two_steps_in_one_configuration_contracting_enough():
    same = [[0, 1]] * 4
    theta = 0.01
    e = estimates(same, [None, 1e5, 1e5 * theta, 1e5 * theta ** 3])
    assert e[0] is None and e[1] is None                    # no step yet; one step: no contraction measured
    assert e[2][0] == pytest.approx(1e5 * theta * theta / (1 - theta), rel=1e-14)
    assert e[3][0] == pytest.approx(1e5 * theta ** 3 * theta ** 2 / (1 - theta ** 2), rel=1e-14)
    # a face changed state in the last step: no estimate there, one again at the next step
    e = estimates([[0, 1], [0, 1], [1, 1], [1, 1]], [None, 1e5, 1e3, 1e1])
    assert e[2] is None and e[3][0] == pytest.approx(1e1 * 1e-2 / (1 - 1e-2), rel=1e-14)
    # a step that shrank too little
    slow = 1e5 * VERDICT_CONTRACTION * 1.01
    assert estimates(same[:3], [None, 1e5, slow])[2] is None
    # nothing moved: exact; after a step that did not move, no contraction to measure
    assert estimates(same[:3], [None, 1e5, 0.0])[2] == (0.0,)
    assert estimates(same[:3], [None, 0.0, 1.0])[2] is None


def test_a_new_solve_measures_its_own_steps():
    eq = FakeEquations([[0]] * 3, [None, 1e5, 1e2])
    settling = Settling(eq, State(PETSc.Vec().createSeq(1)))
    for its in range(3):
        eq.its = its
        settling.iterate_errors(FakeSnes(eq), its)
    eq.its = 0
    assert settling.iterate_errors(FakeSnes(eq), 0) is None        # SNES started again: its steps only
    eq.its = 1
    assert settling.iterate_errors(FakeSnes(eq), 1) is None


def test_a_cut_step_reports_the_faces_broken_in_its_sub_steps():
    """The breaking rounds and faces of the sub-steps that made the step, not of the attempt that failed."""
    state = State(PETSc.Vec().createSeq(1))
    calls = []

    def solve_step(t):
        ok = t - (calls[-1][0] if calls and calls[-1][1] else 0.0) <= 0.5 + 1e-12
        calls.append((t, ok))
        return Solve(t, ok, 2 if ok else -5, SolveCost(3, 3), nonlinear=True, breaking=(2, 7) if ok else (1, 4))

    rec = cut_step(solve_step, state, 0.0, 1.0, max_cuts=2)
    assert rec.converged and rec.substeps == 2
    assert rec.breaking == (4, 14)
    assert rec.as_json()["breaking_passes"] == 4 and rec.as_json()["faces_broken_step"] == 14
