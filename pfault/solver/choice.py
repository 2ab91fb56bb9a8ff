"""Which solver file a run applies when the scene leaves -pfault_solver at auto: the direct solver (MUMPS,
pfault/solver/options/mumps.opts) on small systems, the iterative one (options/iterative.opts) from the size
where it is the faster. Pure functions of what the scene asks for and how many unknowns its mesh gives.

No fault rules out the iterative solver: every Lagrange face has a negative definite 3x3 block from its condensed
bubbles for the Schur fieldsplit to eliminate its multipliers with (pfault.solver.fieldsplit.FieldSplit), and a
penalty face's multipliers are eliminated the same way."""

from __future__ import annotations

AUTO = "auto"
DIRECT = "mumps"
ITERATIVE = "iterative"

# Global unknowns (displacements, both sides of split fault vertices, and Lagrange faces' multipliers: the
# size of the solution vector, summary.json's "dofs") from which the iterative solver is chosen.
# benchmarks/solver_crossover.py, 2 ranks, all steps, end-to-end wall time, the better of two interleaved
# runs of each solver, MUMPS's time over the iterative solver's (benchmarks/README.md, "solver_crossover.py"):
#   calibrated Queretaro 13,692 unknowns 0.81, 35,190 1.02, 82,902 1.90, 212,634 (paper size) 5.06;
#   Wuxi 41,742 1.00, 84,411 (paper size) 1.18, 136,935 1.41; demo box (no fault) 24,375 0.81, 78,033 1.45.
# The two cross between 42,000 (Wuxi, as fast) and 78,000 unknowns (the box, the iterative solver 1.45 times
# faster), and are within 20 % of each other from 14,000 to 42,000 on every scene, where MUMPS, which needs
# no Krylov convergence, is kept. The CPU times give the same order. Measured on 2 ranks of one 2-core
# machine; on more ranks the crossover may move (the factorisation and the AMG scale apart).
ITERATIVE_FROM_DOFS = 50_000


def choose_solver(n_dofs: int) -> str:
    """DIRECT below ITERATIVE_FROM_DOFS global unknowns, ITERATIVE from there."""
    return DIRECT if n_dofs < ITERATIVE_FROM_DOFS else ITERATIVE


def solver_file_name(requested: str, n_dofs: int, pc_type_given: bool = False) -> str:
    """The -pfault_solver value a run applies (a name for pfault.solver.setup.apply_solver_file): the one the
    user or the scene named, as it is; for ``auto`` the choice of ``choose_solver``, or none ("") when the user
    chose the preconditioner with -pc_type and named no solver file (PETSc's options then steer the solver
    alone, on the code defaults of pfault.solver.setup.apply_solver_defaults)."""
    if requested != AUTO:
        return requested
    if pc_type_given:
        return ""
    return choose_solver(n_dofs)
