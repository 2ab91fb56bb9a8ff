"""The terms the equations are given besides the elastic skeleton, and the protocol they follow.

The equations (pfault.solver.equations) are the elastic skeleton K u = f(t) plus a list of terms: the fault
interfaces (pfault.faults.term.FaultTerm) and the materials with memory (pfault.soils.term.SoilTerm), in that order.
A scene without either has an empty list: the equations are then linear and nothing else asks what they hold. A
term is configuration only: what it remembers is a history (plain frozen data in the run's state,
pfault.state.State), and what it sees at the time the equations were last set to is its load (Loads.term_loads);
every method takes them and returns values or the next history, in the local numbering of the distributed mesh's
dofs. ``TermDefaults`` gives the answers of a term that adds nothing to a part of the protocol.

The protocol (methods a term has; collective where it says so):

- ``name``: what it is ("faults", "soils"); ``full_newton_steps``: whether Newton takes full steps on its law (False:
  it backtracks on |F|, pfault.solver.setup.apply_solver_defaults); ``moduli_vary_only``: whether, where its Jacobian
  varies within one configuration, only its cells' stiffness moduli change (an iterative solver's preconditioner is
  then kept: pfault.solver.policy.PreconditionerReuse).
- Building: ``add_operator(K, blocked)`` adds its constant part to the operator (before assembly);
  ``pattern()`` the global (rows, cols) of its further Jacobian entries.
- Loads: ``load(t, cell_dp, alpha, out)`` its load at time t (the pore-pressure change per local cell, or None),
  adding its share of f to the local array ``out``; ``gravity_load(body, previous, out)`` that of the initial
  gravity state; ``at_rest(load)`` the load of the initial state itself, which loads nothing.
- The initial state: ``initial_vertical_stress()`` (cells, total vertical stress) of its cells where the geostatic
  start's is not the elastic gravity solve's (a material with memory's: the overburden).
- Histories: ``initial_history()``; ``prestressed(sigma0, x_loc, load, history)`` the history from an initial
  stress (the multipliers it sets in x_loc); ``begin_step(x_loc, load, history)`` at the start of a solve;
  ``commit(x_loc, load, history)`` after a converged step; ``settle(x_loc, load, history, t, error=0.0)`` the
  history at the iterate x_loc of a solve at time t and how many of its parts changed on all ranks (faces that
  broke: Newton goes on from x_loc with the new history until none does), or None where ``error`` (a bound on the
  error of what it reads at x_loc, in ``settle_change``'s norm; 0 at a converged state) leaves a part open;
  ``settle_change(dx_loc)`` (collective) the size of a change of the iterate in what ``settle`` reads (a fault:
  the largest change of a face's traction component).
- The discrete configuration (its active set: a fault face's stick/slip/open): ``configuration(x_loc, load,
  history, exact)`` (exact: the branches the residual takes; else as reported), ``trial_configuration(history)``
  (a step's elastic trial), ``jacobian_varies(configuration)`` (collective: whether the Jacobian depends on more
  than the configuration), ``counts(configuration)`` (collective: the step record's counts of its branches, a
  fault's faces stuck/slipping/open, a soil's cells compacting on the virgin line). The terms' configurations are
  concatenated for the Jacobian cache and the factor reuse.
- Equations: ``residual(x_loc, load, history, out, configuration=None)`` adds its residual to ``out``;
  ``add_jacobian(x_loc, load, history, J, configuration=None)`` its blocks to J;
  ``add_initial_operator(A, n_local)`` its blocks of the initial gravity state's linear operator, returning their
  configuration.
- Stress: ``added_stress(x_loc, load, history)`` (cells, stress) it adds to the cells' mean effective stress (a
  fault's face bubbles: their mean strain in their moduli); ``cell_stress(x_loc, load, history)`` (cells,
  effective stress change) it gives its cells instead of the elastic one (a material with memory).
- What is reported: ``measures(x_loc, x_rel, load, history, mesh)`` the step record's figures (JSON-ready,
  collective); ``fields(x_total, x_rel, load, history)`` the output series' fields ({"fault": per owned face,
  "cells": per local cell}); ``columns(xy, mesh)`` what it measures along vertical columns under the points xy (the
  land surface's, the stations'; pfault.soils.columns.SoilColumns), or None.
- The checkpoint: ``rows`` (what its history's arrays are per: "face" or "cell"), ``history_arrays(history)``
  ({name: array per row}) and ``restored(arrays, x_loc, load)`` the history they hold, started at x_loc.
- Margins to failure (pfault.margins: the further uniform drawdown its parts take before they fail, from the
  linear response of a converged state): ``load_rate(t, cell_dp, cell_rate, alpha, out)`` the rate of its load
  per metre of drawdown (``cell_rate``: Pa/m per local cell), adding the rate of its share of f to ``out``;
  ``residual_rate(x_loc, load, rate, history, out)`` adds d(its residual)/d(drawdown) at the fixed state x_loc;
  ``margin_configuration(x_loc, load, history)`` the configuration the response's Jacobian takes (the branches a
  further drawdown takes from x_loc: a fault's faces keep their states, a soil's cells on their cap compact on
  the virgin line);
  ``margin_parts(x_loc, load, history)`` how many of its parts, on all ranks, have a margin the response decides
  (a fault's faces stuck and not broken; none: the response is not solved); collective;
  ``margins(x_loc, dx_loc, load, rate, history, mesh, settings)`` its margins at x_loc with the state's rate dx_loc
  (None: it has none), an object with ``fields()`` (as ``fields``) and ``as_json()`` (merged into the step's
  record); collective.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np


@dataclass(frozen=True)
class MarginSettings:
    """What the terms' margins are reported in: the pore-pressure change of a metre of drawdown (``rho_g``, Pa/m),
    the drawdowns (m) whose areas within the margin are reported (``thresholds``) and the site coordinates of
    the mesh's origin (``origin``, m)."""
    rho_g: float
    thresholds: tuple
    origin: tuple = (0.0, 0.0, 0.0)


class Term(Protocol):
    """A term of the equations (see the module docstring)."""

    name: str
    full_newton_steps: bool
    moduli_vary_only: bool

    def add_operator(self, K: Any, blocked: bool) -> None: ...

    def pattern(self) -> tuple[np.ndarray, np.ndarray]: ...

    def load(self, t: float, cell_dp: np.ndarray | None, alpha: np.ndarray, out: np.ndarray) -> Any: ...

    def gravity_load(self, body: np.ndarray, previous: Any, out: np.ndarray) -> Any: ...

    def at_rest(self, load: Any) -> Any: ...

    def initial_vertical_stress(self) -> tuple[np.ndarray, np.ndarray]: ...

    def initial_history(self) -> Any: ...

    def prestressed(self, sigma0: np.ndarray, x_loc: np.ndarray, load: Any, history: Any) -> Any: ...

    def begin_step(self, x_loc: np.ndarray, load: Any, history: Any) -> Any: ...

    def commit(self, x_loc: np.ndarray, load: Any, history: Any) -> Any: ...

    def settle(self, x_loc: np.ndarray, load: Any, history: Any, t: float, error: float = 0.0
               ) -> tuple[Any, int | None]: ...

    def settle_change(self, dx_loc: np.ndarray) -> float: ...

    def configuration(self, x_loc: np.ndarray, load: Any, history: Any, exact: bool = True) -> np.ndarray: ...

    def trial_configuration(self, history: Any) -> np.ndarray: ...

    def jacobian_varies(self, configuration: np.ndarray) -> bool: ...

    def residual(self, x_loc: np.ndarray, load: Any, history: Any, out: np.ndarray,
                 configuration: np.ndarray | None = None) -> None: ...

    def add_jacobian(self, x_loc: np.ndarray, load: Any, history: Any, J: Any,
                     configuration: np.ndarray | None = None) -> None: ...

    def add_initial_operator(self, A: Any, n_local: int) -> np.ndarray: ...

    def counts(self, configuration: np.ndarray) -> dict: ...

    def added_stress(self, x_loc: np.ndarray, load: Any, history: Any) -> tuple[np.ndarray, np.ndarray]: ...

    def cell_stress(self, x_loc: np.ndarray, load: Any, history: Any) -> tuple[np.ndarray, np.ndarray]: ...

    def columns(self, xy: np.ndarray, mesh: Any) -> Any: ...

    def measures(self, x_loc: np.ndarray, x_rel: np.ndarray, load: Any, history: Any, mesh: Any) -> dict: ...

    def fields(self, x_total: np.ndarray, x_rel: np.ndarray, load: Any, history: Any) -> dict: ...

    rows: str

    def history_arrays(self, history: Any) -> dict: ...

    def restored(self, arrays: dict, x_loc: np.ndarray, load: Any) -> Any: ...

    def load_rate(self, t: float, cell_dp: np.ndarray | None, cell_rate: np.ndarray, alpha: np.ndarray,
                  out: np.ndarray) -> Any: ...

    def residual_rate(self, x_loc: np.ndarray, load: Any, rate: Any, history: Any, out: np.ndarray) -> None: ...

    def margin_parts(self, x_loc: np.ndarray, load: Any, history: Any) -> int: ...

    def margins(self, x_loc: np.ndarray, dx_loc: np.ndarray, load: Any, rate: Any, history: Any, mesh: Any,
                settings: MarginSettings) -> Any: ...

    def margin_configuration(self, x_loc: np.ndarray, load: Any, history: Any) -> np.ndarray: ...


class TermDefaults:
    """The answers of a term that adds nothing to a part of the protocol (a term class derives from it and
    defines the rest): no Jacobian entries beyond its own blocks' pattern, no initial vertical stress of its own,
    no strain or stress given to cells, nothing to settle, nothing along columns; for the margins to failure a
    residual that does not depend on the load at a fixed state, the response in its current configuration and no
    part with a margin of its own."""

    full_newton_steps = True    # its semismooth Newton takes full steps (pfault.solver.setup.apply_solver_defaults)
    # where its Jacobian varies within one configuration, only stiffness moduli of its cells change (a soil's
    # K = p'/kappa), by the factor the iterate's stress moves: an iterative solver's preconditioner set up for one
    # iterate serves the next of the same configuration (pfault.solver.policy.PreconditionerReuse). False: what
    # varies carries constraints (a slipping face's friction direction), and the preconditioner is set up anew
    moduli_vary_only = False

    def pattern(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)

    def initial_vertical_stress(self) -> tuple[np.ndarray, np.ndarray]:
        """None: its cells take the geostatic start's vertical stress."""
        return np.zeros(0, np.int64), np.zeros(0)

    def settle(self, x_loc: np.ndarray, load: Any, history: Any, t: float, error: float = 0.0) -> tuple[Any, int]:
        return history, 0

    def settle_change(self, dx_loc: np.ndarray) -> float:
        """0: ``settle`` reads nothing of the iterate (the same on every rank, no communication)."""
        return 0.0

    def added_stress(self, x_loc: np.ndarray, load: Any, history: Any) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(0, np.int64), np.zeros((0, 3, 3))

    def cell_stress(self, x_loc: np.ndarray, load: Any, history: Any) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(0, np.int64), np.zeros((0, 3, 3))

    def columns(self, xy: np.ndarray, mesh: Any) -> Any:
        """Nothing measured along columns."""
        return None

    def residual_rate(self, x_loc: np.ndarray, load: Any, rate: Any, history: Any, out: np.ndarray) -> None:
        """Nothing: at a fixed state its residual does not depend on the drawdown."""

    def margin_configuration(self, x_loc: np.ndarray, load: Any, history: Any) -> np.ndarray:
        """Its configuration at x_loc: a further drawdown keeps its branches."""
        return self.configuration(x_loc, load, history)

    def margin_parts(self, x_loc: np.ndarray, load: Any, history: Any) -> int:
        return 0

    def margins(self, x_loc: np.ndarray, dx_loc: np.ndarray, load: Any, rate: Any, history: Any, mesh: Any,
                settings: MarginSettings) -> Any:
        return None
