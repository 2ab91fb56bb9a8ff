"""The fault problem's SNES convergence test (FaultProblem._converged, in-process): PETSc's default criteria
(atol, rtol, stol, divergence) and the stall test, which ends a Newton solve whose last STALL_ITS iterations
cut |F| by less than STALL_FACTOR in all (seen on Queretaro with the stated rates, where a face's slip
direction sits at its regularisation kink and the line search takes tiny steps): accepted within STALL_ACCEPT
times atol (there already after one iteration that cuts |F| by less than FLAT_FACTOR), a failure above."""

import types

import pytest
from petsc4py import PETSc

from pfault.solver import problem as pb

R = PETSc.SNES.ConvergedReason


class FakeSnes:
    def __init__(self, rtol=1e-8, atol=1e-3, stol=1e-8):
        self.tol = (rtol, atol, stol, 25)

    def getTolerances(self):
        return self.tol

    def getMaxFunctionEvaluations(self):
        return -1

    def getFunctionEvaluations(self):
        return 0


def run(fnorms, snes=None, ynorm=1.0, xnorm=1.0):
    """Feed the residual norms one iteration at a time; returns (iteration, reason) at the first decision."""
    me = types.SimpleNamespace(_fnorms=[], _divtol=1e4, n_stalls=0)
    snes = snes or FakeSnes()
    for k, f in enumerate(fnorms):
        reason = pb.FaultProblem._converged(me, snes, k, (xnorm, ynorm, f))
        if reason != R.CONVERGED_ITERATING:
            return k, reason, me.n_stalls
    return None, R.CONVERGED_ITERATING, me.n_stalls


def test_a_stalled_newton_solve_stops_after_stall_its_iterations():
    # 0.2 % per iteration, as measured on the stalled Queretaro rounds: stops at iteration STALL_ITS
    fnorms = [876.0 * 0.998 ** k for k in range(25)]
    assert run(fnorms) == (pb.STALL_ITS, R.DIVERGED_MAX_IT, 1)


def test_a_stall_within_stall_accept_atol_counts_as_converged_at_its_first_flat_iteration():
    # the same stall 5x above atol (1e-3): Newton sits on the floor of its nonsmooth residual, the solve is
    # accepted after the first iteration that cuts |F| by less than FLAT_FACTOR
    fnorms = [5e-3 * 0.998 ** k for k in range(25)]
    assert run(fnorms) == (1, R.CONVERGED_ITS, 1)
    assert run([2e-2, 1.5e-2, 5e-3, 4.9e-3]) == (3, R.CONVERGED_ITS, 1)
    # 20x above atol it is a stall only after STALL_ITS iterations, and a failure
    assert run([20.0 / 5.0 * f for f in fnorms]) == (pb.STALL_ITS, R.DIVERGED_MAX_IT, 1)


def test_slow_but_steady_newton_is_not_a_stall():
    # a 1.2x contraction per iteration cuts |F| by 2.5x over 5 iterations: Newton goes on to the tolerance
    fnorms = [1e6 / 1.2 ** k for k in range(120)]
    k, reason, stalls = run(fnorms, FakeSnes(rtol=1e-6, atol=0.0))
    assert reason == R.CONVERGED_FNORM_RELATIVE and stalls == 0
    assert fnorms[k] <= 1e-6 * fnorms[0] < fnorms[k - 1]


def test_a_stall_that_recovers_within_the_window_is_not_cut():
    # four flat iterations, then quadratic convergence: the factor 0.5 over the 5-iteration window is reached
    fnorms = [100.0, 99.0, 98.0, 97.0, 96.0, 40.0, 1.0, 1e-4]
    assert run(fnorms) == (7, R.CONVERGED_FNORM_ABS, 0)


@pytest.mark.parametrize("fnorms,ynorm,expected", [
    ([1e-4], 1.0, (0, R.CONVERGED_FNORM_ABS, 0)),              # atol (1e-3), also at iteration 0
    ([1e6, 5e-3], 1.0, (1, R.CONVERGED_FNORM_RELATIVE, 0)),   # rtol (1e-8), above atol
    ([1.0, 0.9], 1e-9, (1, R.CONVERGED_SNORM_RELATIVE, 0)),    # stol: step below stol |x|
    ([1.0, 2e4], 1.0, (1, R.DIVERGED_DTOL, 0)),                # divergence tolerance 1e4
    ([1.0, float("nan")], 1.0, (1, R.DIVERGED_FNORM_NAN, 0)),
])
def test_petsc_default_criteria_are_kept(fnorms, ynorm, expected):
    assert run(fnorms, FakeSnes(atol=1e-3), ynorm=ynorm) == expected
