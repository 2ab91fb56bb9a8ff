"""-pfault_solver auto: the direct solver below ITERATIVE_FROM_DOFS global unknowns or where the faults need it,
the iterative one from there; a named solver is kept as named (pfault.solver.choice)."""

import dataclasses

import pytest

from pfault.faults.settings import FaultSettings
from pfault.solver.choice import (ITERATIVE_FROM_DOFS, choose_solver, faults_need_direct, solver_file_name)

LAGRANGE = FaultSettings("f", cohesion=0.0, friction_angle=30.0, method="lagrange", penalty_normal=0.0,
                         penalty_tangential=0.0)
PENALTY = dataclasses.replace(LAGRANGE, name="p", method="penalty")


def test_threshold_splits_the_sizes():
    assert choose_solver(ITERATIVE_FROM_DOFS - 1) == "mumps"
    assert choose_solver(ITERATIVE_FROM_DOFS) == "iterative"
    assert choose_solver(10 * ITERATIVE_FROM_DOFS) == "iterative"
    assert choose_solver(10 * ITERATIVE_FROM_DOFS, need_direct=True) == "mumps"


def test_threshold_sits_in_the_measured_crossover():
    # benchmarks/solver_crossover.py: MUMPS the faster or as fast up to Wuxi's 41,742 unknowns, the iterative
    # solver from the box's 78,033 on, and at both case studies' paper sizes (Wuxi 84,411, calibrated
    # Queretaro 212,634), which auto gives it
    assert 41_742 < ITERATIVE_FROM_DOFS <= 78_033
    assert choose_solver(84_411) == choose_solver(212_634) == "iterative"


@pytest.mark.parametrize("faults, direct", [((), False), ((LAGRANGE,), False), ((PENALTY,), False),
                                            ((LAGRANGE, PENALTY), False)])
def test_no_fault_needs_the_direct_solver(faults, direct):
    assert faults_need_direct(faults) is direct
    assert solver_file_name("auto", 10 * ITERATIVE_FROM_DOFS, faults) == ("mumps" if direct else "iterative")


def test_a_named_solver_is_kept():
    for name in ("mumps", "iterative", "gamg", "config/solver/mumps.opts", ""):
        assert solver_file_name(name, 10 * ITERATIVE_FROM_DOFS, (LAGRANGE,)) == name
        assert solver_file_name(name, 10, (), pc_type_given=True) == name


def test_auto_with_a_preconditioner_given_applies_no_file():
    assert solver_file_name("auto", 10 * ITERATIVE_FROM_DOFS, (), pc_type_given=True) == ""
    assert solver_file_name("auto", 10, (), pc_type_given=True) == ""
