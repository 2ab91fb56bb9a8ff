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

The Krylov solve starts from the previous output time's rate where the branches and the loaded cells are the same
(``Response.start_for``): the rate then changes only with the slipping faces' directions and the state's own
pore pressure, and where the Jacobian depends on the branches alone (every face stuck or open) and the load rate
is the same it is the previous rate itself. In other branches it starts from zero: the previous rate is wrong
there face by face, where the residual's norm, in forces, hardly sees it (paper-size Wuxi, the faces' states of
the year before: margins 7e-4 relative off at MARGIN_RTOL, against 1.5e-5 from zero).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from mpi4py import MPI

from ..records import SolveCost


@dataclass(frozen=True)
class Response:
    """The state's rate per metre of drawdown (``dx``: local array; NaN where the solve failed), the terms' load
    rates (one per term), whether the linear solve converged and its cost; for the next output time's start, the
    branches the rate was solved in (``configuration``: the terms', one array), the pore-pressure rate
    (``cell_rate``) and the rate's owned entries (``owned``: None when not solved or not converged)."""
    dx: np.ndarray
    rates: tuple
    converged: bool
    cost: SolveCost
    configuration: np.ndarray | None = None
    cell_rate: np.ndarray | None = None
    owned: np.ndarray | None = None

    def start_for(self, comm: Any, configuration: np.ndarray, cell_rate: np.ndarray) -> np.ndarray | None:
        """The owned entries to start the solve of a response in ``configuration`` to ``cell_rate`` from: this
        rate's where both are this response's on every rank, else None. Collective."""
        same = self.owned is not None and _equal(self.configuration, configuration) \
            and _equal(self.cell_rate, cell_rate)
        return self.owned if comm.tompi4py().allreduce(same, op=MPI.LAND) else None


def _equal(a: np.ndarray | None, b: np.ndarray) -> bool:
    return a is not None and a.shape == b.shape and bool(np.array_equal(a, b))


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


def drawdown_response(eq: Any, solver: Any, state: Any, t: float, cell_rate: np.ndarray, solve: bool = True,
                      previous: Response | None = None) -> Response:
    """The response of the converged state (``state``, at time t) to the pore-pressure rate ``cell_rate``: one
    linear solve with the step solver (pfault.solver.policy.StepSolver.solve_response), its Jacobian in the
    configuration a further drawdown takes (the terms' ``margin_configuration``: a soil's cells on their cap on the
    virgin line), started from ``previous`` (the last output time's response) where it is of the same branches and
    load rate; ``solve`` False: the load rates only, the state's rate zero (no part's margin depends on it).
    Collective."""
    x_loc = eq.local_array(state.u)
    rhs, rates = drawdown_rhs(eq, x_loc, state.histories, t, cell_rate)
    if not solve:
        rhs.destroy()
        return Response(np.zeros(eq.dofmap.n_local), rates, True, SolveCost())
    config = tuple(term.margin_configuration(x_loc, load, h)
                   for term, load, h in zip(eq.terms, eq.loads.term_loads, state.histories))
    flat = np.concatenate(config) if config else np.zeros(0, np.int64)
    start = previous.start_for(eq.comm, flat, cell_rate) if previous is not None else None
    du = rhs.duplicate()
    try:
        if start is not None:
            du.getArray()[:] = start
        converged, cost = solver.solve_response(rhs, du, config, guess=start is not None)
        dx = eq.local_array(du) if converged else np.full(eq.dofmap.n_local, np.nan)
        owned = du.getArray().copy() if converged else None
    finally:
        du.destroy()
        rhs.destroy()
    return Response(dx, rates, converged, cost, flat, np.array(cell_rate), owned)
