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

Where the Jacobian depends on the branches alone (every face stuck or open, no cell on its virgin line), in the
same branches as at the last output time, and the right-hand side is the same to the bit (the same loaded cells, no
face dried since), the system is the one solved then and its rate is taken as it is: no solve (``Response.reused``;
the faulted aquifer's years before its first slip). Every other response is solved from zero: the last rate as a
start converges to the same residual with its error left where that norm, in forces, hardly sees it, face by face
(paper-size Wuxi, the faces' states of the year before: 3 FGMRES iterations instead of 11 but margins 7e-4 relative
off, against 1.5e-5 from zero).
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
    rates (one per term), whether the linear solve converged and its cost; ``system``: the branches (the terms'
    configurations, one array) and the right-hand side's owned entries of the system solved, where its Jacobian
    depends on the branches alone (else None), for the next output time to recognise it (``reused``)."""
    dx: np.ndarray
    rates: tuple
    converged: bool
    cost: SolveCost
    system: tuple | None = None

    def reused(self, comm: Any, varies: bool, configuration: np.ndarray, rhs: np.ndarray) -> bool:
        """Whether the system in ``configuration`` with the right-hand side ``rhs`` (owned entries), whose Jacobian
        depends on the state (``varies``) or on the branches alone, is this response's on every rank. Collective."""
        same = self.system is not None and not varies and _equal(self.system[0], configuration) \
            and _equal(self.system[1], rhs)
        return bool(comm.tompi4py().allreduce(same, op=MPI.LAND))


def _equal(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(np.array_equal(a, b))


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
    virgin line), or ``previous``'s rate where its system is this one (``Response.reused``); ``solve`` False: the
    load rates only, the state's rate zero (no part's margin depends on it). Collective."""
    x_loc = eq.local_array(state.u)
    rhs, rates = drawdown_rhs(eq, x_loc, state.histories, t, cell_rate)
    try:
        if not solve:
            return Response(np.zeros(eq.dofmap.n_local), rates, True, SolveCost())
        config = tuple(term.margin_configuration(x_loc, load, h)
                       for term, load, h in zip(eq.terms, eq.loads.term_loads, state.histories))
        flat = np.concatenate(config) if config else np.zeros(0, np.int64)
        varies = any(term.jacobian_varies(c) for term, c in zip(eq.terms, config))      # collective, same on all
        b = rhs.getArray()
        if previous is not None and previous.reused(eq.comm, varies, flat, b):
            return Response(previous.dx, rates, True, SolveCost(), previous.system)
        system = None if varies else (flat, b.copy())
        du = rhs.duplicate()
        try:
            converged, cost = solver.solve_response(rhs, du, config)
            dx = eq.local_array(du) if converged else np.full(eq.dofmap.n_local, np.nan)
        finally:
            du.destroy()
        return Response(dx, rates, converged, cost, system if converged else None)
    finally:
        rhs.destroy()
