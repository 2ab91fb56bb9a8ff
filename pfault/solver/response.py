"""The linear response of a converged state to a further uniform drawdown: the state's rate per metre of head
lowered in the loaded cells, for the margins to failure (pfault.margins).

With the pore-pressure change dp + lam dp_rate (``cell_rate``: Pa per metre of drawdown per local cell) the
equations F(x, lam) = K u - f(lam) + sum of the terms' residuals are affine in the load for fixed configurations;
the rate dx/dlam of a converged state x solves

    J dx/dlam = df/dlam - sum over the terms of d(residual)/dlam

(J: dF/dx at x in the branches the drawdown takes, the terms' ``margin_configuration``: a fault's faces keep their
states, a material with memory's cells on their cap compact on the virgin line).

df/dlam is the Biot load of the rate (and the terms' share: a fault's condensed bubble load), each term's residual
changes with its load (a fault's face pore pressure in its effective tractions, its bubbles' load in its jumps).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..records import SolveCost


@dataclass(frozen=True)
class Response:
    """The state's rate per metre of drawdown (``dx``: local array; NaN where the solve failed), the terms' load
    rates (one per term), whether the linear solve converged and its cost."""
    dx: np.ndarray
    rates: tuple
    converged: bool
    cost: SolveCost


def drawdown_rhs(eq: Any, x_loc: np.ndarray, histories: tuple, t: float, cell_rate: np.ndarray
                 ) -> tuple[Any, tuple]:
    """(-dF/dlam at the state x_loc as a global Vec, zero on constrained rows; the terms' load rates) for the
    pore-pressure rate ``cell_rate`` at time t, under the loads last set (those of t)."""
    loc = np.zeros(eq.dofmap.n_local)
    eq.asm.pore_pressure_load(cell_rate, loc)
    dp = eq.loads.cell_dp(t)
    rates = tuple(term.load_rate(t, dp, cell_rate, eq.asm.alpha, loc) for term in eq.terms)
    for term, load, rate, h in zip(eq.terms, eq.loads.term_loads, rates, histories):
        rows = np.zeros(eq.dofmap.n_local)
        term.residual_rate(x_loc, load, rate, h, rows)
        loc -= rows
    rhs = eq.to_global(loc)
    rhs.getArray()[eq.bc_local_owned] = 0.0
    return rhs, rates


def drawdown_response(eq: Any, solver: Any, state: Any, t: float, cell_rate: np.ndarray, solve: bool = True
                      ) -> Response:
    """The response of the converged state (``state``, at time t) to the pore-pressure rate ``cell_rate``: one
    linear solve with the step solver (pfault.solver.policy.StepSolver.solve_response), its Jacobian in the
    configuration a further drawdown takes (the terms' ``margin_configuration``: a soil's cells on their cap on the
    virgin line); ``solve`` False: the load rates only, the state's rate zero (no part's margin depends on it).
    Collective."""
    x_loc = eq.local_array(state.u)
    rhs, rates = drawdown_rhs(eq, x_loc, state.histories, t, cell_rate)
    du = rhs.duplicate()
    try:
        config = tuple(term.margin_configuration(x_loc, load, h)
                       for term, load, h in zip(eq.terms, eq.loads.term_loads, state.histories)) if solve else ()
        converged, cost = solver.solve_response(rhs, du, config) if solve else (True, SolveCost())
        dx = eq.local_array(du) if converged and solve else np.full(eq.dofmap.n_local, 0.0 if converged else np.nan)
    finally:
        du.destroy()
        rhs.destroy()
    return Response(dx, rates, converged, cost)
