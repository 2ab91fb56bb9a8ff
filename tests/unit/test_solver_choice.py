"""-pfault_solver auto: the direct solver below ITERATIVE_FROM_DOFS global unknowns, the iterative one from there;
a named solver is kept as named (pfault.solver.choice)."""

from pfault.solver.choice import ITERATIVE_FROM_DOFS, choose_solver, solver_file_name


def test_threshold_splits_the_sizes():
    assert choose_solver(ITERATIVE_FROM_DOFS - 1) == "mumps"
    assert choose_solver(ITERATIVE_FROM_DOFS) == "iterative"
    assert choose_solver(10 * ITERATIVE_FROM_DOFS) == "iterative"


def test_threshold_sits_in_the_measured_crossover():
    # benchmarks/solver_crossover.py: MUMPS the faster or as fast up to Wuxi's 41,742 unknowns, the iterative
    # solver from the box's 78,033 on, and at both case studies' paper sizes (Wuxi 84,411, calibrated
    # Queretaro 212,634), which auto gives it
    assert 41_742 < ITERATIVE_FROM_DOFS <= 78_033
    assert choose_solver(84_411) == choose_solver(212_634) == "iterative"


def test_auto_follows_the_size():
    assert solver_file_name("auto", 10 * ITERATIVE_FROM_DOFS) == "iterative"
    assert solver_file_name("auto", ITERATIVE_FROM_DOFS - 1) == "mumps"


def test_a_named_solver_is_kept():
    for name in ("mumps", "iterative", "gamg", "config/solver/mumps.opts", ""):
        assert solver_file_name(name, 10 * ITERATIVE_FROM_DOFS) == name
        assert solver_file_name(name, 10, pc_type_given=True) == name


def test_auto_with_a_preconditioner_given_applies_no_file():
    assert solver_file_name("auto", 10 * ITERATIVE_FROM_DOFS, pc_type_given=True) == ""
    assert solver_file_name("auto", 10, pc_type_given=True) == ""
