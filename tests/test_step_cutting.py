"""Step retries: a fault step that does not converge is retried from its start, first with the increment slip
direction when it used the augmented one (which then stays), then as 2, 4, ... sub-steps, with a flow model's pore
pressure interpolated linearly in time (FaultProblem.solve_interval, in-process, one rank).

The Newton/active-set solve is replaced by a stand-in that converges only for increments up to a given share of
the step (and, optionally, only with the increment slip direction), so the outcome of every attempt is known in
advance; it records the times, pore pressures and slip laws it is given.
"""

import numpy as np
import pytest
from petsc4py import PETSc

from pfault.solver.problem import FaultProblem


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


class FakeFaults:
    def __init__(self, c_slip=None):
        self.state = np.array([0, 0, 2])
        self.c_slip = c_slip

    def _sync_state(self):
        pass


class FakeProblem(FaultProblem):
    def __init__(self, max_increment, augmented=False, augmented_solves=True):
        self.u = PETSc.Vec().createSeq(3)
        self.u.set(1.0)
        self.faults = FakeFaults(np.ones(3) if augmented else None)
        self.augmented_solves = augmented_solves
        self.drawdown = FakeFlow()
        self.mesh = type("M", (), {"cells": np.zeros((2, 4), int), "cell_material": np.zeros(2, int)})()
        self.asm = type("A", (), {"centroids": np.zeros((2, 3))})()
        self.contact_opts = {"monitor": False}
        self._last, self._t_state = None, 0.0      # predictor history (FaultProblem.create_snes)
        self.max_increment = max_increment
        self.calls = []
        self.laws = []
        self.t_done = 0.0

    def solve_step(self, snes, t):
        dp = self.cell_dp(t)[0]
        start = self.u.getArray()[0]
        ok = t - self.t_done <= self.max_increment + 1e-12
        law = "increment" if self.faults.c_slip is None else "augmented"
        ok = ok and (law == "increment" or self.augmented_solves)
        self.calls.append((t, dp, start, ok))
        self.laws.append(law)
        self.u.set(100.0 + t)                 # a solve changes the state, converged or not
        self.faults.state[:] = 1
        if ok:
            self.t_done = t
        return {"time_s": t, "newton_its": 2, "ksp_its": 2, "wall_s": 0.1, "active_set_its": 1,
                "converged": ok, "residual_history": [[1.0, 0.0]]}


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
    assert rec["newton_its"] == 12 and rec["time_s"] == 2.0
    assert len(rec["residual_history"]) == 6


def test_no_retry_without_cuts_and_failure_after_the_last_cut():
    p = FakeProblem(max_increment=0.1)
    rec = p.solve_interval(None, 0.0, 1.0, max_cuts=0)
    assert not rec["converged"] and len(p.calls) == 1
    p = FakeProblem(max_increment=0.1)
    rec = p.solve_interval(None, 0.0, 1.0, max_cuts=2)
    assert not rec["converged"] and rec["substeps"] == 4
    assert p.u.getArray()[0] != 1.0
    assert p.calls[-1][3] is False


def test_augmented_slip_failure_retries_the_step_with_the_increment_direction_for_good():
    p = FakeProblem(max_increment=1.0, augmented=True, augmented_solves=False)
    rec = p.solve_interval(None, 0.0, 1.0, max_cuts=3)
    # one failed augmented attempt, then the same full step with the increment direction: no sub-steps
    assert rec["converged"] and rec.get("slip_direction_fallback") and rec.get("substeps", 1) == 1
    assert p.laws == ["augmented", "increment"]
    assert [c[2] for c in p.calls] == [1.0, 1.0], "the retry restarts from the step's start"
    assert rec["newton_its"] == 4
    # the increment direction stays for the following steps
    assert p.faults.c_slip is None and p.slip_direction == "increment"
    rec = p.solve_interval(None, 1.0, 2.0, max_cuts=3)
    assert rec["converged"] and not rec.get("slip_direction_fallback") and p.laws[-1] == "increment"


def test_sub_steps_follow_a_failed_slip_direction_fallback():
    p = FakeProblem(max_increment=0.5, augmented=True, augmented_solves=False)
    rec = p.solve_interval(None, 0.0, 1.0, max_cuts=3)
    assert rec["converged"] and rec["substeps"] == 2 and rec.get("slip_direction_fallback")
    assert p.laws == ["augmented", "increment", "increment", "increment"]
    assert [c[0] for c in p.calls] == pytest.approx([1.0, 1.0, 0.5, 1.0])


def test_a_converged_augmented_step_keeps_its_slip_direction():
    p = FakeProblem(max_increment=1.0, augmented=True)
    rec = p.solve_interval(None, 0.0, 1.0, max_cuts=3)
    assert rec["converged"] and not rec.get("slip_direction_fallback")
    assert p.laws == ["augmented"] and p.faults.c_slip is not None and p.slip_direction == "augmented"


# a fault that starts from zero strength: Queretaro (c = 0) without geostatic stress, two one-year steps at mesh
# size factor 2. Every face's Coulomb limit is set by the drawdown alone, and the augmented slip direction (the
# scene's law) chatters in step 1; the increment direction settles it (measured: 7 factorisations for the step,
# both attempts). The converged solution does not depend on the law (measured: maxima agree to 4e-11).
ZERO_STRENGTH = ("-pfault_geostatic", "false", "-pfault_mesh_size_factor", "2",
                 "-pfault_time_end", "2*year", "-pfault_time_steps", "2")


def test_zero_strength_fault_converges_by_the_slip_direction_fallback(tmp_path):
    from conftest import run_scene
    _, fb = run_scene("config/queretaro_calibrated.opts", tmp_path / "fallback", ranks=2, extra=ZERO_STRENGTH)
    _, inc = run_scene("config/queretaro_calibrated.opts", tmp_path / "increment", ranks=2,
                       extra=ZERO_STRENGTH + ("-pfault_contact_slip_direction", "increment"))
    assert fb["converged"] and inc["converged"]
    steps = [s for s in fb["steps"] if s["time_s"] > 0]
    assert steps[0].get("slip_direction_fallback") and steps[0].get("substeps", 1) == 1
    assert not steps[1].get("slip_direction_fallback")
    assert fb["slip_direction"] == "increment" and inc["slip_direction"] == "increment"
    for key in ("max_subsidence_m", "max_fault_opening_m", "max_fault_slip_m", "max_horizontal_displacement_m"):
        assert fb[key] == pytest.approx(inc[key], rel=1e-7), key
    # the fault slides by centimetres and opens by millimetres (1.6 cm and 3.9 mm measured)
    assert fb["max_fault_slip_m"] > 0.01 and fb["max_fault_opening_m"] > 0.001


def test_zero_strength_fault_steps_settle_without_sub_steps(tmp_path):
    """The same scene over 8 one-year steps. In step 8 a face's closing (open -> stick) is a change Newton
    cannot solve: it is banned, and with nothing else asking for a change the last solved configuration stands,
    its banned face within -pfault_contact_chatter_tol (measured: 1 face, 0.012 of the median normal traction).
    Before, the step failed and took 4 sub-steps (63 factorisations instead of 12). Step 1's augmented attempt
    releases faces held by the anti-chatter rule (twice) before the increment direction settles it."""
    from conftest import run_scene
    extra = ("-pfault_geostatic", "false", "-pfault_mesh_size_factor", "2",
             "-pfault_time_end", "8*year", "-pfault_time_steps", "8")
    _, s = run_scene("config/queretaro_calibrated.opts", tmp_path, ranks=2, extra=extra)
    steps = [st for st in s["steps"] if st["time_s"] > 0]
    assert s["converged"] and len(steps) == 8
    assert all(st.get("substeps", 1) == 1 for st in steps), [st.get("substeps", 1) for st in steps]
    assert steps[0]["slip_direction_fallback"] and steps[0]["chatter_releases"] >= 1
    held = [st for st in steps if st["frozen_violating"] > 0]
    assert held, "no step ended with a face held against its contact conditions"
    assert all(st["frozen_max_violation"] <= 0.02 for st in held)
    # the sediments slide down the rock by centimetres (measured 15.9 cm after 8 years)
    assert 0.05 < s["max_fault_slip_m"] < 0.5
