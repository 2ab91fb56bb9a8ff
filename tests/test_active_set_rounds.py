"""The active-set rounds of one step (FaultProblem.solve_step, in-process, one rank): how a step ends when faces
are held by the anti-chatter rule or banned after a Newton failure.

The Newton solves and the fault system are replaced by stand-ins that follow a script (the reason of each Newton
solve, the fault area each active-set update changes, and the anti-chatter violation left at the end), so every
round's outcome is known in advance.
"""

import numpy as np
from petsc4py import PETSc

from pfault.solver.problem import FaultProblem

CONVERGED, FAILED = 2, -5          # SNES CONVERGED_FNORM_ABS, DIVERGED_MAX_IT


class ScriptedFaults:
    """Four faces of unit area. update_active_set changes the scripted area; frozen_violations returns the
    scripted (count, largest violation), one entry per release so far."""

    def __init__(self, changes, violations, chatter_tol):
        self.area = np.ones(4)
        self.state = np.zeros(4, int)
        self.c_slip = None
        self.changes = list(changes)
        self.violations = list(violations)
        self.chatter_tol = chatter_tol
        self.released = 0
        self.bans = 0
        self.last_transitions = np.zeros((3, 3), int)

    def begin_step(self, x_loc, carry=None):
        pass

    def save_state(self):
        pass

    def restore_state(self):
        pass

    def ban_last_change(self):
        self.bans += 1
        return 1

    def update_active_set(self, x_loc, traction_tol, opening_tol, slip_tol, fraction=1.0):
        c = self.changes.pop(0)
        self.last_transitions = np.zeros((3, 3), int)
        self.last_transitions[0, 1] = c
        return float(c)

    def counts_by_state(self, x_loc):
        return {"stick": 4, "slip": 0, "open": 0}

    def frozen_count(self):
        return 1

    def frozen_violations(self, *args):
        return self.violations[min(self.released, len(self.violations) - 1)]

    def release_frozen(self, x_loc, traction_tol, opening_tol, slip_tol, chatter_tol):
        n, worst = self.frozen_violations()
        if n and worst > chatter_tol:
            self.released += 1
            return n
        return 0


class ScriptedProblem(FaultProblem):
    def __init__(self, reasons, changes, violations, releases=2, chatter_tol=0.02):
        self.comm = PETSc.COMM_SELF
        self.u = PETSc.Vec().createSeq(3)
        self.u.set(0.0)
        self.faults = ScriptedFaults(changes, violations, chatter_tol)
        self.contact_opts = {"max_active_set_its": 30, "traction_tol": 1.0, "opening_tol": -1.0, "slip_tol": 1e-3,
                             "active_set_tol": 0.0, "bounded_growth": 2.0, "monitor": False,
                             "chatter_tol": chatter_tol, "chatter_releases": releases, "predictor": False,
                             "step_rtol": 0.0}
        self.reasons = list(reasons)
        self.solves = 0
        self._last, self._t_state = None, 0.0
        self.n_factorizations = self.n_reuse_failures = self.n_stalls = 0

    def set_load(self, t):
        pass

    def local_array(self, gvec):
        return gvec.getArray().copy()

    def _snes_solve(self, snes):
        # each solve moves the state: u = the solve's number, converged or not
        self.solves += 1
        self.u.set(float(self.solves))
        return self.reasons.pop(0), 2, 2, [1.0, 0.0]


def test_a_settled_step_releases_violating_frozen_faces_and_goes_on():
    # round 1 changes a face, round 2 settles with 3 frozen faces violating by 0.5 (> 0.02): released; round 3
    # (the released faces change) and round 4 settle with no violation left
    p = ScriptedProblem(reasons=[CONVERGED] * 4, changes=[1, 0, 3, 0], violations=[(3, 0.5), (0, 0.0)])
    rec = p.solve_step(None, 1.0)
    assert rec["converged"] and rec["chatter_releases"] == 1
    assert rec["active_set_its"] == 4 and p.solves == 4 and not p.reasons and not p.faults.changes
    assert rec["frozen_violating"] == 0


def test_releases_are_bounded_and_the_step_then_fails():
    p = ScriptedProblem(reasons=[CONVERGED] * 3, changes=[0, 2, 0] + [0] * 3,
                        violations=[(2, 0.4), (2, 0.3), (2, 0.3)], releases=1)
    rec = p.solve_step(None, 1.0)
    assert not rec["converged"] and rec["chatter_releases"] == 1 and p.solves == 3
    assert "anti-chatter" in rec["reason"] and "0.3" in rec["reason"]


def test_no_release_fails_at_once():
    p = ScriptedProblem(reasons=[CONVERGED], changes=[0], violations=[(2, 0.4)], releases=0)
    rec = p.solve_step(None, 1.0)
    assert not rec["converged"] and rec["chatter_releases"] == 0 and p.solves == 1


def test_violations_within_the_tolerance_are_accepted_without_release():
    p = ScriptedProblem(reasons=[CONVERGED], changes=[0], violations=[(2, 0.01)])
    rec = p.solve_step(None, 1.0)
    assert rec["converged"] and rec["chatter_releases"] == 0 and rec["frozen_violating"] == 2


def test_a_banned_change_ends_the_step_at_the_last_solved_configuration():
    # round 1 solves and changes one face; Newton fails on it (round 2): back to round 1's solution, the change
    # is banned, and no other face asks for one: round 1's configuration is the step's solution
    p = ScriptedProblem(reasons=[CONVERGED, FAILED], changes=[1, 0], violations=[(1, 0.01)])
    rec = p.solve_step(None, 1.0)
    assert rec["converged"] and rec["reason"] == CONVERGED and p.faults.bans == 1
    assert p.u.getArray()[0] == 1.0, "the state is round 1's solution"
    # the same with a banned face that breaks its contact conditions beyond the tolerance: not a solution
    p = ScriptedProblem(reasons=[CONVERGED, FAILED], changes=[1, 0], violations=[(1, 0.5)], releases=0)
    rec = p.solve_step(None, 1.0)
    assert not rec["converged"] and "anti-chatter" in rec["reason"]


def test_a_step_whose_first_newton_solve_fails_with_nothing_to_change_fails():
    p = ScriptedProblem(reasons=[FAILED], changes=[0], violations=[(0, 0.0)])
    rec = p.solve_step(None, 1.0)
    assert not rec["converged"] and rec["reason"] == FAILED
