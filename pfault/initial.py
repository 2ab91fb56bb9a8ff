"""The geostatic initial state a scene may start from (-pfault_geostatic true): step 0.

An elastic gravity solve with the faults glued (every fault face stuck: no jump while the state forms) gives the
vertical stress (the overburden in flat layers, the arching around stiff bodies), except in the cells of a
material with memory, whose vertical stress is the weight of the column above their centroid (the K0 procedure:
pfault.soils.term.SoilTerm.initial_vertical_stress); the horizontal stresses follow
the K0 rule on effective stresses, sigma'_h = K0 sigma'_v, with hydrostatic pore pressure below the water table
(K0 = -pfault_geostatic_k0, default nu/(1-nu) of each material); no initial shear. That stress is the initial
state: it loads nothing, displacements are those caused by the drawdown, and stresses and fault tractions are the
initial ones plus the changes; the terms' histories start from it (a fault face's initial traction is the
prestress projected on it).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from petsc4py import PETSc

from .errors import StepNotConverged


def k0_stress(sig: np.ndarray, z: np.ndarray, alpha: np.ndarray, lam: np.ndarray, mu: np.ndarray,
              settings: Any) -> np.ndarray:
    """The initial stress (cells x 3 x 3, Pa) from the elastic gravity state's stress ``sig`` per cell: its
    vertical stress, horizontal stresses by the K0 rule on effective stresses with hydrostatic pore pressure below
    the water table at the cells' centroids ``z``; ``alpha``, ``lam``, ``mu`` per cell."""
    s = settings
    p0 = s.water_density * s.gravity * np.maximum(s.water_table - z, 0.0)
    nu = lam / (2 * (lam + mu))
    k0 = np.full(len(z), s.k0) if s.k0 >= 0 else nu / (1 - nu)
    sv = sig[:, 2, 2]
    sh = k0 * (sv + alpha * p0) - alpha * p0
    sigma0 = np.zeros_like(sig)
    sigma0[:, 0, 0] = sigma0[:, 1, 1] = sh
    sigma0[:, 2, 2] = sv
    return sigma0


class GeostaticStart:
    """Computes the geostatic initial state of ``equations`` (pfault.solver.equations.Equations) into a
    state, with the linear solver ``solve_linear(A, b, x) -> KSP reason`` (the step solver's)."""

    def __init__(self, equations: Any, settings: Any) -> None:
        self.eq, self.settings = equations, settings

    def compute(self, state: Any, solve_linear: Any) -> None:
        """The initial stress (``state.sigma0``), the terms' histories from it, and u = u_ref: the initial state,
        in equilibrium with zero displacement."""
        self.start(state, self.initial_stress(state, solve_linear))

    def initial_stress(self, state: Any, solve_linear: Any) -> np.ndarray:
        """The initial stress per local cell (cells x 3 x 3, Pa): the elastic gravity solve's vertical stress and
        the K0 rule (``k0_stress``)."""
        eq = self.eq
        eq.loads.gravity(eq.loads.f)
        ug = state.u.duplicate()
        reason = solve_linear(eq.initial_operator(), eq.loads.f, ug)
        norm = ug.norm()
        if reason <= 0 or not np.isfinite(norm):
            # the initial stress would come from a wrong state: faults open at step 0, every step loaded by it
            ug.destroy()
            why = f"KSP reason {reason}" if reason <= 0 else "a non-finite solution"
            raise StepNotConverged(f"-pfault_geostatic: the elastic gravity solve of the initial stress failed "
                                   f"({why}); check the solver options (-pfault_solver, -ksp_*, -pc_*) or start "
                                   f"without it (-pfault_geostatic false)")
        asm = eq.asm
        sig = eq.effective_stress(eq.local_array(ug), state.histories)
        ug.destroy()
        for term in eq.terms:
            cells, vertical = term.initial_vertical_stress()    # a material with memory's: its overburden
            sig[cells, 2, 2] = vertical
        return k0_stress(sig, asm.centroids[:, 2], asm.alpha, asm.lam, asm.mu, self.settings)

    def start(self, state: Any, sigma0: np.ndarray) -> None:
        """The initial state of the stress ``sigma0`` (per local cell): the terms' histories from it, and
        u = u_ref, in equilibrium with zero displacement."""
        eq = self.eq
        state.sigma0 = sigma0
        eq.loads.set(0.0)       # the terms' loads back from gravity's to those of the start
        state.u.set(0.0)
        loc = eq.local_array(state.u)
        state.histories = tuple(term.prestressed(state.sigma0, loc, load, h)
                                for term, load, h in zip(eq.terms, eq.loads.term_loads, state.histories))
        eq.to_global(loc, PETSc.InsertMode.INSERT_VALUES, out=state.u)
        state.u.copy(state.u_ref)
